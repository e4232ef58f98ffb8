#!/usr/bin/env python3
"""Pack size against source size (issue 24) for the demo level and every shared glTF sample:
the source's bytes (the glTF or level file and every file its cook read: buffers, images,
props), the pack's bytes split by what they hold (vertices, indices, textures by format,
lightmaps, probes, animation, other), and the ratio.

    .venv/bin/python tools/pack_sizes.py [--samples DIR] [--quality draft|medium|high]

Each source is cooked with the default settings (the bake at --quality, default draft to keep
the run short; the bake's settings change the lightmaps' texels, not their size) into a
temporary directory.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from collections import Counter
from pathlib import Path

from content_sources import display_name, samples_dir, sources


def breakdown(manifest: dict) -> Counter:
    """Bytes of the pack's data by what they hold."""
    parts: Counter = Counter()
    lm = manifest.get("lightmap") or {}
    baked = set(lm.get("textures", [])) | set(lm.get("directions", []))
    for m in manifest["meshes"]:
        for lod in m["lods"]:
            parts["vertices"] += lod["vertices"]["len"]
            parts["indices"] += lod["indices"]["len"]
    for i, t in enumerate(manifest["textures"]):
        key = "lightmaps" if i in baked else f"textures {t['format']}"
        parts[key] += sum(r["len"] for r in t["mips"])
    for p in (manifest.get("reflection_probes") or {}).get("probes", []):
        parts["reflection probes"] += p["data"]["len"]
    return parts


def main() -> int:
    from asset_pipeline import _core
    from asset_pipeline.bake import BakeSettings
    from asset_pipeline.pipeline import CookError, CookSettings, cook

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--samples", type=Path, default=samples_dir())
    ap.add_argument("--quality", choices=["draft", "medium", "high"], default="draft")
    args = ap.parse_args()
    print("| source | source bytes | pack bytes | pack / source | vertices | indices | textures | lightmaps | reflection probes | other |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    with tempfile.TemporaryDirectory() as tmp:
        for src in sources(args.samples, "pack_sizes"):
            name = display_name(src, args.samples)
            out = Path(tmp) / "out.pack"
            try:
                r = cook(src, out, CookSettings(report=False, force=True, cache_dir=Path(tmp) / "cache", bake=BakeSettings(preset=args.quality)))
            except CookError as e:
                print(f"| {name} | cook failed: {e} |")
                continue
            source_bytes = sum(Path(f).stat().st_size for f in {os.fspath(f) for f in (r.scene.files or [src])})
            pack_bytes = out.stat().st_size
            parts = breakdown(json.loads(_core.read_pack_manifest(out)))
            textures = sum(v for k, v in parts.items() if k.startswith("textures"))
            other = pack_bytes - sum(parts.values())
            print(f"| {name} | {source_bytes} | {pack_bytes} | {pack_bytes / source_bytes:.2f}x | {parts['vertices']} | {parts['indices']} | {textures} "
                  f"| {parts['lightmaps']} | {parts['reflection probes']} | {other} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
