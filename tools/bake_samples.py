"""Cook and bake every glTF model under the samples folder directly (`cook model.glb`), as a user
would, and report per model: static instances, lightmap texels, bake seconds and the whole cook.

    .venv/bin/python tools/bake_samples.py [--quality medium] [--samples-dir DIR] [--out DIR]

The samples folder is $GLTF_SAMPLES_DIR, else ../shared/gltf-samples. Each model is cooked with
--force into its own folder under --out (default: a temporary folder), so nothing is cached.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

from asset_pipeline import CookError
from asset_pipeline.bake import PRESETS, BakeSettings
from asset_pipeline.cook import cook_detailed
from asset_pipeline.pipeline import CookSettings

REPO = Path(__file__).resolve().parent.parent


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quality", choices=PRESETS, default="medium")
    parser.add_argument("--samples-dir", type=Path, default=Path(os.environ.get("GLTF_SAMPLES_DIR") or REPO.parent / "shared" / "gltf-samples"))
    parser.add_argument("--out", type=Path, help="where the packs go (default: a temporary folder)")
    args = parser.parse_args()
    models = sorted(args.samples_dir.glob("*/*.gl[tb]*"))
    if not models:
        print(f"bake_samples: no .gltf/.glb models under {args.samples_dir}", file=sys.stderr)
        return 2
    out_root = args.out or Path(tempfile.mkdtemp(prefix="bake-samples-"))
    settings = CookSettings(force=True, bake=BakeSettings(preset=args.quality))
    print(f"quality {args.quality}, {os.cpu_count()} cores; packs in {out_root}")
    print("| model | static instances | lightmap texels | pages | bake s | cook s |")
    print("|---|---:|---:|---:|---:|---:|")
    failed = 0
    for model in models:
        out = out_root / model.parent.name / f"{model.stem}.pack"
        out.parent.mkdir(parents=True, exist_ok=True)
        t0 = time.perf_counter()
        try:
            r = cook_detailed(model, out, progress=False, settings=settings)
        except CookError as e:
            print(f"| {model.parent.name}/{model.name} | failed: {e} | | | | |")
            failed += 1
            continue
        bake = next((s.seconds for s in r.stages if s.name == "bake"), 0.0)
        instances = len(r.uv2.get("instances", []))
        print(f"| {model.parent.name}/{model.name} | {instances} | {r.bake.get('texels', 0)} | {r.summary['lightmap_pages']} | "
              f"{bake:.1f} | {time.perf_counter() - t0:.1f} |")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
