"""The cook report: a Markdown file beside the pack (`<name>.report.md`) with what each stage
made and what it cost, and PNG previews of the lightmap atlas pages."""

from __future__ import annotations

import os
from pathlib import Path

from asset_pipeline import ir
from asset_pipeline.cache import write_atomic


def _row(*cells) -> str:
    return "| " + " | ".join(str(c) for c in cells) + " |"


def write_report(out: Path, scene: ir.Scene, summary: dict, stages, uv2_stats: dict, bake_stats: dict | None = None, exrs=(),
                 chunk_stats: dict | None = None, atlas_scene: ir.Scene | None = None, mesh_opt_stats: dict | None = None,
                 compress_stats: dict | None = None) -> Path:
    """`atlas_scene`: the scene as its lightmap atlas was laid out (before the chunk stage: a
    chart a chunk border cuts is drawn as one chart), for the atlas previews; default `scene`."""
    path = out.with_suffix(".report.md")
    lines = [f"# Cook report: {out.name}", "", f"Source: `{scene.source}`", ""]
    lines += [
        f"{summary['meshes']} meshes, {summary['triangles']} triangles at LOD 0, {summary['materials']} materials, "
        f"{summary['textures']} textures, {len(scene.lights)} lights, {len(scene.spawns)} spawn points; "
        f"pack {summary['bytes']} bytes.",
        "",
        "## Stages",
        "",
        _row("stage", "items", "from cache", "seconds"),
        _row("---", "---:", "---:", "---:"),
    ]
    lines += [_row(s.name, s.items, s.cached, f"{s.seconds:.3f}") for s in stages]
    lines += ["", "## Meshes and LODs", "", "Error: upper bound of the two-sided Hausdorff distance to LOD 0, metres, object space.", ""]
    lines += [_row("mesh", "static", "LOD", "triangles", "vertices", "error (m)"), _row("---", "---", "---:", "---:", "---:", "---:")]
    static = set(scene.static_meshes())
    for k, m in enumerate(scene.meshes):
        for i, lod in enumerate(m.lods):
            lines.append(_row(m.name if i == 0 else "", "yes" if k in static and i == 0 else "", i, lod.triangle_count, lod.vertex_count, f"{lod.error:.4f}"))
    if mesh_opt_stats:
        m = mesh_opt_stats
        lines += ["", "## Mesh optimisation", "",
                  f"Vertex cache (FIFO of {m['cache_size']}), vertices transformed per triangle (ACMR): every LOD "
                  f"{m['acmr_before']:.3f} -> {m['acmr_after']:.3f} over {m['triangles']} triangles; LOD 0 "
                  f"{m['lod0_acmr_before']:.3f} -> {m['lod0_acmr_after']:.3f}. Vertices {m['vertices_before']} -> {m['vertices_after']} "
                  "(unused ones dropped)."]
    if compress_stats:
        lines += _compress_section(compress_stats)
    if chunk_stats:
        from asset_pipeline.chunks import describe

        lines += ["", "## Level chunks", "", *describe(chunk_stats)]
    if scene.skins or scene.clips:
        lines += ["", "## Animation", "", f"{len(scene.skins)} skin(s): " + ", ".join(f"{s.name} ({len(s.joints)} joints)" for s in scene.skins), ""]
        lines += [_row("clip", "channels", "seconds"), _row("---", "---:", "---:")]
        lines += [_row(c.name, len(c.channels), f"{max((float(ch.times[-1]) for ch in c.channels), default=0.0):.3f}") for c in scene.clips]
    if scene.warnings:
        lines += ["", "## Warnings", "", *(f"- {w}" for w in scene.warnings)]
    if scene.lightmap is not None:
        lm = scene.lightmap
        lines += ["", "## Lightmap atlas", "", f"Requested density {lm.texels_per_metre:g} texels/m, padding {lm.padding} texels, {len(lm.pages)} page(s).", ""]
        for k, v in sorted(uv2_stats.items()):
            if not isinstance(v, (list, dict)):
                lines.append(f"- {k}: {v:.4g}" if isinstance(v, float) else f"- {k}: {v}")
        instances = uv2_stats.get("instances", [])
        if instances:
            lines += ["", f"{len(instances)} static instance(s), each with texels of its own:", "",
                      _row("instance", "mesh", "page", "texels baked", "texels/m"), _row("---", "---", "---:", "---:", "---:")]
            lines += [_row(i["name"], i["mesh"], ", ".join(map(str, i["pages"])), i.get("texels", ""), f"{i['measured_texels_per_metre']:.3g}")
                      for i in instances]
        previews = _previews(out, atlas_scene or scene)
        for i, (w, h) in enumerate(lm.pages):
            lines += ["", f"Page {i}: {w} x {h}"]
            if i < len(previews):
                lines.append(f"![UV2 page {i}]({os.path.relpath(previews[i], path.parent)})")
    if bake_stats:
        from asset_pipeline.bake import describe

        lines += ["", "## Bake", "", *describe(bake_stats)]
        lines += [f"- `{os.path.relpath(e, path.parent)}`" for e in exrs]
    text = ("\n".join(lines) + "\n").encode()
    write_atomic(path, lambda f: f.write(text))
    return path


def _previews(out: Path, scene: ir.Scene) -> list[Path]:
    """PNG per atlas page showing every chart, drawn by the uv2 stage's rasteriser."""
    from asset_pipeline import uv2

    render = getattr(uv2, "write_previews", None)
    if render is None:
        return []
    folder = out.with_suffix(".report")
    folder.mkdir(exist_ok=True)
    return list(render(scene, folder))


def _quality(q: dict) -> str:
    if "mean_deg" in q:
        return f"{q['mean_deg']:.2f}° / {q['p99_deg']:.2f}°"
    if "median_rel" in q:
        return f"{100 * q['median_rel']:.2f}% / {100 * q['p95_rel']:.2f}%"
    return f"{q['psnr_db']:.1f} dB"


def _compress_section(c: dict) -> list[str]:
    """Every material texture's stored format, its quality against the uncompressed levels (all
    levels, texel-weighted) and bytes; why a texture was kept uncompressed."""
    mb = lambda b: f"{b / 1e6:.2f}"
    lines = ["", "## Texture compression", "",
             f"{c['compressed']} of {c['textures']} textures block-compressed, {c['kept']} kept uncompressed; "
             f"{mb(c['bytes_before'])} MB -> {mb(c['bytes_after'])} MB. Quality: PSNR (colour in linear light) "
             "or mean / 99th-percentile angular error (normal maps, z rebuilt), or median / 95th-percentile "
             "relative error (lightmaps), all levels.", "",
             _row("texture", "class", "size", "format", "effort", "quality", "MB before", "MB after", "note"),
             _row("---", "---", "---", "---", "---", "---:", "---:", "---:", "---")]
    for r in c["per_texture"]:
        q = r.get("quality")
        quality = "" if q is None else _quality(q)
        lines.append(_row(r["name"], r["class"], f"{r['size'][0]}x{r['size'][1]}", r["format"], r.get("effort", ""), quality,
                          mb(r["bytes_before"]), mb(r["bytes_after"]), r.get("kept", "")))
    return lines
