"""The compress stage's rules (pipeline._compress_stage runs them): which block format every
material texture is stored in, the quality each must keep, and the user's per-texture overrides.

Formats by what the material slots read (cook_core::compress does the work, in Rust):
  base colour, emissive          -> BC7 sRGB   (quality: PSNR in linear light, premultiplied)
  metallic-roughness (and ORM)   -> BC7 linear (PSNR of R, G, B)
  occlusion alone                -> BC4        (PSNR of R)
  normal map                     -> BC5        (x, y; the shader rebuilds z; mean angular error)
  lightmap page (half float)     -> BC6H       (median relative error)
  lightmap direction + sun       -> BC7 linear (PSNR of R, G, B, A)
  reflection probe cube          -> BC6H       (each face's chain; the worst face's median)
Every mip level is compressed after it was filtered (the textures stage, in linear light; the
bake prefilters a cube's levels).

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
MAX_MEDIAN_RELATIVE = 0.03

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
    """Texture index -> class (colour, data, occlusion, normal, hdr, direction) for every texture
    the stage compresses: those the materials read (a texture only the occlusion slot reads is
    occlusion), unreferenced ones by their usage, the lightmap pages (hdr) and their direction
    textures (direction). Other HDR textures are left out."""
    skip = scene.baked_textures()
    lm = scene.lightmap
    slots: dict[int, set[str]] = {}
    for m in scene.materials:
        for slot, t in (("colour", m.base_color_texture), ("colour", m.emissive_texture), ("normal", m.normal_texture),
                        ("data", m.metallic_roughness_texture), ("occlusion", m.occlusion_texture)):
            if t is not None:
                slots.setdefault(t, set()).add(slot)
    out: dict[int, str] = {}
    if lm is not None:
        out.update({i: "hdr" for i in lm.textures})
        out.update({i: "direction" for i in lm.directions})
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


# Names the bake gives the textures it makes (bake.attach): page N's lightmap and direction.
# Overrides are checked before the bake, against these for the pages a cook can have.
BAKED_NAMES = [f"lightmap{p}{suffix}" for p in range(256) for suffix in ("", " direction")]


def cube_name(probe: ir.ReflectionProbe) -> str:
    """What overrides and the report call a reflection probe's cube."""
    return f"reflection {probe.name}"


def unmatched(scene: ir.Scene, overrides: dict[str, str], baking: bool = False) -> list[str]:
    """Override patterns no texture of the scene (nor, when `baking`, one the bake will make, or a
    reflection probe's cube) matches: a typo the user should hear about."""
    names = [t.name for t in scene.textures] + (BAKED_NAMES + [cube_name(p) for p in scene.reflection_probes] if baking else [])
    return [p for p in overrides if not any(fnmatch.fnmatchcase(n, p) for n in names)]


def meets_bar(cls: str, quality: dict) -> bool:
    if cls == "normal":
        return quality["mean_deg"] <= MAX_MEAN_ANGLE_DEG
    if cls == "hdr":
        return quality["median_rel"] <= MAX_MEDIAN_RELATIVE
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
    if not meets_bar(cls, quality) and cls in ("colour", "data", "direction", "hdr"):
        fmt2, blocks2, quality2 = encode(levels, cls, "basic")
        if _better(cls, quality2, quality):
            fmt, blocks, quality, effort = fmt2, blocks2, quality2, "basic"
    record.update(quality=quality, effort=effort)
    if mode == "auto" and not meets_bar(cls, quality):
        return t, {**record, "format": t.format, "bytes_after": before, "kept": "below the quality bar"}
    after = int(sum(b.nbytes for b in blocks))
    return dataclasses.replace(t, format=fmt, mips=list(blocks)), {**record, "format": fmt, "bytes_after": after}


def compress_cube(rc: ir.ReflectionCubes, cube: np.ndarray, name: str, mode: str) -> tuple[np.ndarray | None, dict]:
    """One reflection probe's half-float cube ([level][face] rows, ir.ReflectionCubes) as BC6H:
    (its blocks in the same order, or None when kept; its record). Each face's levels are one
    chain to the encoder; the cube's quality is its worst face's."""
    from asset_pipeline._core import compress_texture as encode

    s, levels = rc.face_size, rc.levels
    before = int(cube.nbytes)
    record = {"name": name, "class": "hdr", "size": [s, s], "levels": levels, "bytes_before": before}
    if mode == "none":
        return None, {**record, "format": rc.format, "bytes_after": before, "kept": "override none"}
    offsets = np.cumsum([0] + [6 * max(1, s >> k) ** 2 for k in range(levels)])
    faces = []  # faces[f][k]: the blocks of face f, level k
    worst = None
    effort = "fast"
    for f in range(6):
        chain = []
        for k in range(levels):
            n = max(1, s >> k)
            chain.append(np.ascontiguousarray(cube[offsets[k] + f * n * n: offsets[k] + (f + 1) * n * n].reshape(n, n, 4)))
        fmt, blocks, quality = encode(chain, "hdr", "fast")
        if not meets_bar("hdr", quality):
            _, blocks2, quality2 = encode(chain, "hdr", "basic")
            if _better("hdr", quality2, quality):
                blocks, quality, effort = blocks2, quality2, "basic"
        faces.append(blocks)
        if worst is None or quality["median_rel"] > worst["median_rel"]:
            worst = quality
    record.update(quality=worst, effort=effort)
    if mode == "auto" and not meets_bar("hdr", worst):
        return None, {**record, "format": rc.format, "bytes_after": before, "kept": "below the quality bar"}
    data = np.concatenate([faces[f][k] for k in range(levels) for f in range(6)])
    return data, {**record, "format": "Bc6hUfloat", "bytes_after": int(data.nbytes)}


def keep_set_whole(records: list[dict], formats: list[str]) -> list[int]:
    """A set the runtime holds as one array (the lightmap pages, their direction textures, the
    reflection cubes) is stored in one format. Where some of its members were kept uncompressed
    (below the bar, or an override), the others are marked kept too: their records (in place)
    get their uncompressed `formats` and sizes and say which member kept them. Returns the
    positions of the members the caller must put back uncompressed (none when nothing changes)."""
    kept = [r for r in records if "kept" in r]
    if not kept or len(kept) == len(records):
        return []
    why = f"'{kept[0]['name']}' of its set was kept ({kept[0]['kept']})"
    back = [k for k, r in enumerate(records) if "kept" not in r]
    for k in back:
        records[k].update(format=formats[k], bytes_after=records[k]["bytes_before"], kept=why)
    return back


def keep_sets_whole(scene: ir.Scene, textures: list[ir.Texture], records: list[dict], record_of: dict[int, int]) -> None:
    """`keep_set_whole` for the lightmap pages and for their direction textures: a member put
    back gets the uncompressed texture again (in `textures`)."""
    lm = scene.lightmap
    for ids in ([] if lm is None else [lm.textures, lm.directions]):
        for k in keep_set_whole([records[record_of[i]] for i in ids], [scene.textures[i].format for i in ids]):
            textures[ids[k]] = scene.textures[ids[k]]


def _better(cls: str, a: dict, b: dict) -> bool:
    if cls == "normal":
        return a["mean_deg"] < b["mean_deg"]
    if cls == "hdr":
        return a["median_rel"] < b["median_rel"]
    return a["psnr_db"] > b["psnr_db"]


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
