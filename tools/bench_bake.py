"""Benchmark of the bake stage (not a test): the demo level baked at a preset, timed by phase.

    .venv/bin/python tools/bench_bake.py [--preset medium] [--threads 2] [--level content/levels/temple.toml]

Builds the level and its lightmap UVs (not timed), then runs ``bake.bake_level`` (timed): BVH
build, every atlas page (texels, rays, seconds, Mrays/s), clean-up (denoise, dilate, stitch),
probes, reflection probes. The issue's goal for the demo level at ``medium`` on 2 cores: under 60 s
in all.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

from asset_pipeline import bake
from asset_pipeline.csg import build_level
from asset_pipeline.level import load_level
from asset_pipeline.pipeline import with_lightmap_uvs

ROOT = Path(__file__).resolve().parent.parent


def level_with_uv2(path: Path):
    return with_lightmap_uvs(build_level(load_level(path)))[0]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--level", type=Path, default=ROOT / "content/levels/temple.toml")
    ap.add_argument("--preset", default="medium", choices=bake.PRESETS)
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args()

    scene = level_with_uv2(args.level)
    w, h = scene.lightmap.pages[0]
    print(f"level {args.level.name}: {len(scene.lightmap.pages)} page(s), first {w}x{h} at {scene.lightmap.texels_per_metre:g} texels/m; "
          f"preset {args.preset}, {args.threads} threads; machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.2f}")
    t = time.perf_counter()
    baked = bake.bake_level(scene, bake.BakeSettings(preset=args.preset, threads=args.threads))
    total = time.perf_counter() - t
    s = baked.stats
    for line in bake.describe(s):
        print(line)
    post = sum(p["post_seconds"] for p in s["pages"])
    refl = s.get("reflections")
    print(f"BVH build {s['bvh_seconds']:.2f} s; lightmaps {s['lightmap_seconds']:.1f} s; clean-up {post:.1f} s; probes {s['probe_seconds']:.1f} s"
          + (f"; reflection probes {refl['seconds']:.1f} s ({refl['count']})" if refl else ""))
    print(f"bake time at {args.preset} on {args.threads} threads: {total:.1f} s (goal for medium on 2 cores: < 60 s); "
          f"load average at the end {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
