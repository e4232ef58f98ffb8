"""The compress stage's rules (pipeline._compress_stage runs them): which block format every
material texture is stored in, the quality each must keep, and the user's per-texture overrides.

Formats by what the material slots read (cook_core::compress does the work, in Rust):
  base colour, emissive          -> BC7 sRGB   (quality: PSNR in linear light, premultiplied)
  metallic-roughness (and ORM)   -> BC7 linear (PSNR of R, G, B)
  occlusion alone                -> BC4        (PSNR of R)
  normal map                     -> BC5        (x, y; the shader rebuilds z; mean angular error)
Every mip level is compressed after it was filtered (the textures stage, in linear light).
Lightmaps and reflection probes stay half float for now.

A texture that misses its bar at BC7's fast effort is tried at basic; one that still misses it
stays uncompressed (the report says so), unless an override forces it. Overrides map glob
patterns of texture names to "auto" (the default), "none" (keep uncompressed) or "force"
(compress whatever the quality)."""

from __future__ import annotations

import dataclasses
import fnmatch

import numpy as np

from asset_pipeline import ir

# The bar each class must clear (the acceptance; the report prints what each got).
MIN_PSNR_DB = 38.0
MAX_MEAN_ANGLE_DEG = 1.5

MODES = ("auto", "none", "force")


def parse_overrides(items: list[str] | None) -> dict[str, str]:
    """CLI `--texture-compression PATTERN=MODE` items -> {pattern: mode}; ValueError names a bad one."""
    out: dict[str, str] = {}
    for item in items or []:
        pattern, sep, mode = item.rpartition("=")
        if not sep or not pattern or mode not in MODES:
            raise ValueError(f"--texture-compression '{item}': expected PATTERN=MODE, MODE one of {', '.join(MODES)}")
        out[pattern] = mode
    return out


def texture_classes(scene: ir.Scene) -> dict[int, str]:
    """Texture index -> class (colour, data, occlusion, normal) for every texture the stage
    compresses: those the materials read (a texture only the occlusion slot reads is occlusion),
    and unreferenced ones by their usage. Lightmap pages, their direction textures and HDR
    textures are left out."""
    skip = scene.baked_textures()
    slots: dict[int, set[str]] = {}
    for m in scene.materials:
        for slot, t in (("colour", m.base_color_texture), ("colour", m.emissive_texture), ("normal", m.normal_texture),
                        ("data", m.metallic_roughness_texture), ("occlusion", m.occlusion_texture)):
            if t is not None:
                slots.setdefault(t, set()).add(slot)
    out: dict[int, str] = {}
    for i, t in enumerate(scene.textures):
        if i in skip or t.usage == "hdr":
            continue
        by_usage = {"color": "colour", "data": "data", "normal": "normal"}[t.usage]
        used = slots.get(i, set())
        out[i] = "occlusion" if used == {"occlusion"} and t.usage == "data" else by_usage
    return out


def mode_of(name: str, overrides: dict[str, str]) -> str:
    """The override whose pattern matches `name` (the last one given wins), else auto."""
    mode = "auto"
    for pattern, m in overrides.items():
        if fnmatch.fnmatchcase(name, pattern):
            mode = m
    return mode


def unmatched(scene: ir.Scene, overrides: dict[str, str]) -> list[str]:
    """Override patterns no texture of the scene matches (a typo the user should hear about)."""
    return [p for p in overrides if not any(fnmatch.fnmatchcase(t.name, p) for t in scene.textures)]


def meets_bar(cls: str, quality: dict) -> bool:
    if cls == "normal":
        return quality["mean_deg"] <= MAX_MEAN_ANGLE_DEG
    return quality["psnr_db"] >= MIN_PSNR_DB


def compress_texture(t: ir.Texture, cls: str, mode: str) -> tuple[ir.Texture, dict]:
    """One texture through the rules above -> (the texture as it will be stored, its record:
    class, format, effort, quality, bytes before and after, and why it was kept if it was)."""
    from asset_pipeline._core import compress_texture as encode

    before = int(sum(m.nbytes for m in t.mips))
    record = {"name": t.name, "class": cls, "size": [t.width, t.height], "levels": len(t.mips), "bytes_before": before}
    if mode == "none":
        return t, {**record, "format": t.format, "bytes_after": before, "kept": "override none"}
    levels = [np.ascontiguousarray(m) for m in t.mips]
    fmt, blocks, quality = encode(levels, cls, "fast")
    effort = "fast"
    if not meets_bar(cls, quality) and cls in ("colour", "data"):
        fmt2, blocks2, quality2 = encode(levels, cls, "basic")
        if _better(cls, quality2, quality):
            fmt, blocks, quality, effort = fmt2, blocks2, quality2, "basic"
    record.update(quality=quality, effort=effort)
    if mode == "auto" and not meets_bar(cls, quality):
        return t, {**record, "format": t.format, "bytes_after": before, "kept": "below the quality bar"}
    after = int(sum(b.nbytes for b in blocks))
    return dataclasses.replace(t, format=fmt, mips=list(blocks)), {**record, "format": fmt, "bytes_after": after}


def _better(cls: str, a: dict, b: dict) -> bool:
    return a["mean_deg"] < b["mean_deg"] if cls == "normal" else a["psnr_db"] > b["psnr_db"]


def summarise(records: list[dict]) -> dict:
    """The stage's statistics for the report and CookResult.compress."""
    return {
        "textures": len(records),
        "compressed": sum(1 for r in records if "kept" not in r),
        "kept": sum(1 for r in records if "kept" in r),
        "bytes_before": sum(r["bytes_before"] for r in records),
        "bytes_after": sum(r["bytes_after"] for r in records),
        "per_texture": records,
    }
