"""What the content tools (mesh_stats.py, pack_sizes.py) cook: the demo level, the golem and
every glTF of the shared samples."""

from __future__ import annotations

import os
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def samples_dir() -> Path:
    """$GLTF_SAMPLES_DIR, else ../shared/gltf-samples beside the repository (as the tests)."""
    return Path(os.environ.get("GLTF_SAMPLES_DIR") or REPO.parent / "shared" / "gltf-samples")


def sources(samples: Path, tool: str) -> list[Path]:
    found = [REPO / "content" / "levels" / "temple.toml", REPO / "content" / "levels" / "characters" / "golem.gltf"]
    if samples.is_dir():
        found += sorted(p for p in samples.rglob("*") if p.suffix.lower() in (".gltf", ".glb"))
    else:
        print(f"{tool}: no glTF samples at {samples} (set GLTF_SAMPLES_DIR); the level and golem only", file=sys.stderr)
    return found


def display_name(src: Path, samples: Path) -> Path:
    return src.relative_to(samples) if src.is_relative_to(samples) else src.relative_to(REPO)
