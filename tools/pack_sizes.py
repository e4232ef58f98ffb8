#!/usr/bin/env python3
"""Pack size against source size (issue 24) for the demo level and every shared glTF sample:
the source's bytes (the glTF or level file and every file its cook read: buffers, images,
props), the pack file's bytes and the ratio, and what its data blob holds once decoded (the
pack stores it zstd-compressed): vertices, indices, textures, lightmaps, reflection probes and
the rest (animation, probe grids, the manifest); then the compress stage's quality for the
baked light (lightmap pages: median / 95th-percentile relative error against the uncompressed
page; direction textures: PSNR; reflection cubes: the worst face's median).

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
    print("| source | source bytes | pack bytes | pack / source | decoded | vertices | indices | textures | lightmaps | reflection probes | other |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    baked_light = []
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
            doc, data = _core.read_pack(out)
            parts = breakdown(json.loads(doc))
            textures = sum(v for k, v in parts.items() if k.startswith("textures"))
            decoded = len(data) + len(doc)
            other = decoded - sum(parts.values())
            print(f"| {name} | {source_bytes} | {pack_bytes} | {pack_bytes / source_bytes:.2f}x | {decoded} | {parts['vertices']} | {parts['indices']} | {textures} "
                  f"| {parts['lightmaps']} | {parts['reflection probes']} | {other} |")
            for rec in (r.compress or {}).get("per_texture", []):
                if rec["class"] in ("hdr", "direction"):
                    baked_light.append((name, rec))
    print()
    print("| source | baked texture | size | stored as | quality | bytes before | after | note |")
    print("|---|---|---|---|---:|---:|---:|---|")
    for name, rec in baked_light:
        q = rec.get("quality") or {}
        quality = (f"{100 * q['median_rel']:.2f}% / {100 * q['p95_rel']:.2f}%" if "median_rel" in q
                   else f"{q['psnr_db']:.1f} dB" if "psnr_db" in q else "")
        print(f"| {name} | {rec['name']} | {rec['size'][0]}x{rec['size'][1]} | {rec['format']} | {quality} | {rec['bytes_before']} "
              f"| {rec['bytes_after']} | {rec.get('kept', '')} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
