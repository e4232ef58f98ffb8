#!/usr/bin/env python3
"""The mesh optimisation stage's numbers (issue 24) for the demo level and every shared glTF
sample: vertex cache ACMR (16-entry FIFO) before and after over every LOD and LOD 0 alone,
the bound no order can beat (each vertex transformed once: vertices / triangles), vertex
counts before and after the stage, and vertex bytes: before (the stage's input in the 80-byte
f32 layout packs used up to format 9) and after (its output in the 36-byte quantised layout,
engine/pack/src/vertex.rs).

    .venv/bin/python tools/mesh_stats.py [--samples DIR]

Each source is cooked without baking (the stage's input does not depend on the bake) into a
temporary directory.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

from content_sources import display_name, samples_dir, sources

F32_VERTEX_BYTES = 80  # pack::Vertex, stored as it was up to pack format 9


def main() -> int:
    from asset_pipeline import _core
    from asset_pipeline.pipeline import CookSettings, CookError, cook

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--samples", type=Path, default=samples_dir())
    args = ap.parse_args()
    print("| source | triangles (all LODs) | ACMR before | ACMR after | ACMR bound | LOD 0 ACMR before | after | vertices before | after | vertex bytes before | after |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    with tempfile.TemporaryDirectory() as tmp:
        for src in sources(args.samples, "mesh_stats"):
            name = display_name(src, args.samples)
            try:
                r = cook(src, Path(tmp) / "out.pack", CookSettings(baking=False, report=False, force=True, cache_dir=Path(tmp) / "cache"))
            except CookError as e:
                print(f"| {name} | cook failed: {e} |")
                continue
            s = r.mesh_opt
            if not s:
                print(f"| {name} | no meshes |")
                continue
            print(f"| {name} | {s['triangles']} | {s['acmr_before']:.3f} | {s['acmr_after']:.3f} | {s['vertices_after'] / max(s['triangles'], 1):.3f} | {s['lod0_acmr_before']:.3f} | {s['lod0_acmr_after']:.3f} "
                  f"| {s['vertices_before']} | {s['vertices_after']} | {s['vertices_before'] * F32_VERTEX_BYTES} | {s['vertices_after'] * _core.VERTEX_STRIDE} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
