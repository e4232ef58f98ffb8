"""Mip chains: `_core.mip_chain` (cook_core::mips) and the cooker's textures stage end to end.
The filter's own tests, with the notes' thresholds, are Rust unit tests in
asset_pipeline/core/src/mips/tests.rs; these check the crossing, the stage and the pack."""

import base64
import io
import json
import struct
import zlib
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import asset_pipeline
from asset_pipeline import _core, ir
from asset_pipeline.cache import StageCache
from asset_pipeline.pipeline import CookSettings, _textures_stage, cook
from asset_pipeline.progress import Progress


def foliage_rgba(n: int, seed: int = 3) -> np.ndarray:
    """Thin antialiased leaves (2-4 texels wide) on transparency, green on 'garbage' magenta."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:n, 0:n].astype(np.float64) + 0.5
    alpha = np.zeros((n, n))
    for _ in range(n * n // 120):
        cx, cy, ang = rng.uniform(0, n), rng.uniform(0, n), rng.uniform(0, np.pi)
        length, width = rng.uniform(5, 12), rng.uniform(1.0, 2.0)
        dx, dy = (x - cx + n / 2) % n - n / 2, (y - cy + n / 2) % n - n / 2
        u, v = dx * np.cos(ang) + dy * np.sin(ang), -dx * np.sin(ang) + dy * np.cos(ang)
        d = np.sqrt((u / length) ** 2 + (v / width) ** 2)
        alpha = np.maximum(alpha, np.clip((1 - d) * 3 * width + 0.5, 0, 1))
    rgba = np.zeros((n, n, 4), np.uint8)
    rgba[...] = (255, 0, 255, 0)
    leaf = alpha > 0
    rgba[leaf, :3] = (40, 140, 30)
    rgba[..., 3] = np.round(alpha * 255).astype(np.uint8)
    return rgba


def coverage(level: np.ndarray, cutoff: float) -> float:
    return float(np.mean(level[..., 3].astype(np.float64) / 255.0 >= cutoff))


def png_bytes(rgba: np.ndarray) -> bytes:
    if rgba.dtype == np.uint16:
        return png16_bytes(rgba)
    buf = io.BytesIO()
    Image.fromarray(rgba, "RGBA").save(buf, "PNG")
    return buf.getvalue()


def png16_bytes(rgba: np.ndarray) -> bytes:
    """A 16-bit RGBA PNG (Pillow writes no 16-bit RGBA), straight from the PNG spec."""
    h, w, _ = rgba.shape

    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    rows = b"".join(b"\0" + rgba[y].astype(">u2").tobytes() for y in range(h))
    ihdr = struct.pack(">IIBBBBB", w, h, 16, 6, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(rows)) + chunk(b"IEND", b"")


def quad_gltf(png: bytes, alpha_mode: str = "MASK", cutoff: float = 0.5) -> dict:
    """A textured unit quad (positions, uv, u16 indices) whose material uses `png` as base colour."""
    idx = struct.pack("<6H", 0, 1, 2, 0, 2, 3) + b"\0" * 4
    pos = struct.pack("<12f", 0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0)
    uv = struct.pack("<8f", 0, 1, 1, 1, 1, 0, 0, 0)
    buf = idx + pos + uv
    material = {"name": "leaves", "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}, "alphaMode": alpha_mode, "doubleSided": True}
    if alpha_mode == "MASK":
        material["alphaCutoff"] = cutoff
    return {
        "asset": {"version": "2.0"},
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"name": "Quad", "primitives": [{"attributes": {"POSITION": 1, "TEXCOORD_0": 2}, "indices": 0, "material": 0}]}],
        "materials": [material],
        "textures": [{"source": 0}],
        "images": [{"name": "leaves", "uri": "data:image/png;base64," + base64.b64encode(png).decode()}],
        "accessors": [
            {"bufferView": 0, "componentType": 5123, "count": 6, "type": "SCALAR"},
            {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]},
            {"bufferView": 2, "componentType": 5126, "count": 4, "type": "VEC2"},
        ],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 12},
            {"buffer": 0, "byteOffset": 16, "byteLength": 48},
            {"buffer": 0, "byteOffset": 64, "byteLength": 32},
        ],
        "buffers": [{"byteLength": len(buf), "uri": "data:application/octet-stream;base64," + base64.b64encode(buf).decode()}],
    }


# --- the binding -----------------------------------------------------------------------------


def test_chain_levels_halve_down_to_one_texel_in_the_input_dtype():
    levels = _core.mip_chain(np.zeros((5, 3, 4), np.uint8), "color")
    assert [l.shape for l in levels] == [(2, 1, 4), (1, 1, 4)] and all(l.dtype == np.uint8 for l in levels)
    hdr = np.zeros((8, 4, 4), np.float16)
    hdr[2, 1] = 1e4
    levels = [l.view(np.float16) for l in _core.mip_chain(hdr.view(np.uint16), "hdr")]
    assert [l.shape for l in levels] == [(4, 2, 4), (2, 1, 4), (1, 1, 4)]
    assert min(float(l.min()) for l in levels) >= 0.0 and float(levels[0].max()) > 1.0


def test_srgb_checker_filters_to_188_not_128():
    checker = np.where((np.add.outer(np.arange(8), np.arange(8)) % 2 == 0)[..., None], 0, 255).astype(np.uint8).repeat(4, axis=2)
    checker[..., 3] = 255
    for level in _core.mip_chain(checker, "color"):
        assert (level[..., :3] == 188).all(), level[..., 0]
    # The same bytes as linear data average to the code-value mean.
    assert (_core.mip_chain(checker, "data")[0][..., :3] == 128).all()


def zone_plate_alias_rms(level1: np.ndarray, n: int) -> float:
    i, j = np.mgrid[0:n // 2, 0:n // 2].astype(np.float64)
    x, y = 2 * j + 0.5, 2 * i + 0.5
    freq = np.sqrt(x * x + y * y) / (2 * n)
    band = (freq >= 0.3) & (freq <= 0.5)
    return float(np.sqrt(np.mean((level1[..., 0][band] / 255.0 - 0.5) ** 2)))


def test_zone_plate_default_filter_is_under_the_alias_gate_and_box_is_not():
    n = 256
    y, x = np.mgrid[0:n, 0:n].astype(np.float64)
    v = np.round((0.5 + 0.5 * np.cos(np.pi * (x * x + y * y) / (2 * n))) * 255).astype(np.uint8)
    zp = np.ascontiguousarray(np.stack([v, v, v, np.full_like(v, 255)], -1))
    default = zone_plate_alias_rms(_core.mip_chain(zp, "data", edge="clamp")[0], n)
    box = zone_plate_alias_rms(_core.mip_chain(zp, "data", filter="box", edge="clamp")[0], n)
    assert default <= 0.05 < box, (default, box)


@pytest.mark.parametrize("call, message", [
    (lambda: _core.mip_chain(np.zeros((4, 4, 4), np.uint8), "albedo"), "unknown texture usage 'albedo'"),
    (lambda: _core.mip_chain(np.zeros((4, 4, 4), np.uint8), "color", filter="cubic"), "unknown filter 'cubic'"),
    (lambda: _core.mip_chain(np.zeros((4, 4, 4), np.uint16), "hdr", filter="lanczos3"), "negative lobes"),
    (lambda: _core.mip_chain(np.zeros((4, 4, 3), np.uint8), "data"), "expected (h, w, 4)"),
    (lambda: _core.mip_chain(np.full((2, 2, 4), np.nan, np.float16).view(np.uint16), "hdr"), "texel (0, 0) is not finite"),
])
def test_bad_arguments_are_one_line_value_errors(call, message):
    with pytest.raises(ValueError) as e:
        call()
    assert message in str(e.value) and "\n" not in str(e.value)


# --- the textures stage and the pack ---------------------------------------------------------


def test_cooked_alpha_tested_texture_has_a_full_chain_that_keeps_its_coverage(tmp_path):
    rgba = foliage_rgba(128)
    src = tmp_path / "leaves.gltf"
    src.write_text(json.dumps(quad_gltf(png_bytes(rgba), "MASK", 0.5)))
    out = tmp_path / "leaves.pack"
    result = cook(src, out, CookSettings(lods=False, lightmap_uvs=False, baking=False, compress=False))
    assert result.summary["texture_mips"] == [8]
    fmt, levels = _core.read_pack_texture(out, 0)
    assert fmt == "Rgba8Srgb" and [l.shape[:2] for l in levels] == [(128 >> k, 128 >> k) for k in range(8)]
    assert (levels[0] == rgba).all()
    c0 = coverage(levels[0], 0.5)
    assert 0.15 < c0 < 0.6, c0
    for k, level in enumerate(levels[1:], start=1):
        texels = level.shape[0] * level.shape[1]
        bound = max(0.02, 0.5 / texels)
        assert abs(coverage(level, 0.5) - c0) <= bound, (k, coverage(level, 0.5), c0)
        # Premultiplied filtering: the transparent texels' magenta never bleeds into a leaf.
        visible = level[..., 3] > 0
        assert (level[visible][:, 0] <= 40).all() and (level[visible][:, 2] <= 30).all(), k
    # The same texture on a blended material is not rescaled: its coverage thins out.
    src2 = tmp_path / "blend.gltf"
    src2.write_text(json.dumps(quad_gltf(png_bytes(rgba), "BLEND")))
    cook(src2, tmp_path / "blend.pack", CookSettings(lods=False, lightmap_uvs=False, baking=False, compress=False))
    _, plain = _core.read_pack_texture(tmp_path / "blend.pack", 0)
    assert abs(coverage(plain[3], 0.5) - c0) > 0.02
    # A re-cook to another path takes the chain from the stage cache.
    again = cook(src, tmp_path / "again.pack", CookSettings(lods=False, lightmap_uvs=False, baking=False, compress=False))
    stage = next(s for s in again.stages if s.name == "textures")
    assert (stage.items, stage.cached) == (1, 1)
    assert _core.read_pack_texture(tmp_path / "again.pack", 0)[1][3].tobytes() == levels[3].tobytes()


def test_no_mips_keeps_one_level(run_cook, tmp_path):
    src = tmp_path / "q.gltf"
    src.write_text(json.dumps(quad_gltf(png_bytes(foliage_rgba(32)))))
    out = tmp_path / "q.pack"
    r = run_cook(src, "-o", out, "--no-mips", "--no-bake")
    assert r.returncode == 0, r.stderr
    assert asset_pipeline.read_pack_summary(out)["texture_mips"] == [1]
    r = run_cook(src, "-o", out, "--mip-filter", "box", "--no-bake")
    assert r.returncode == 0, r.stderr
    assert asset_pipeline.read_pack_summary(out)["texture_mips"] == [6]


def test_bad_filter_from_the_api_names_the_file_and_texture(tmp_path):
    src = tmp_path / "q.gltf"
    src.write_text(json.dumps(quad_gltf(png_bytes(foliage_rgba(16)))))
    with pytest.raises(asset_pipeline.CookError) as e:
        cook(src, tmp_path / "q.pack", CookSettings(lods=False, lightmap_uvs=False, baking=False, mip_filter="nope"))
    assert str(e.value).startswith(f"{src}: texture 0 'leaves': unknown filter 'nope'")
    assert not (tmp_path / "q.pack").exists()


def test_stage_follows_usage_and_leaves_lightmaps_at_one_level(tmp_path):
    n = 32
    y, x = np.mgrid[0:n, 0:n]
    # A normal map of opposite tilts in alternate columns, and an HDR texture with one hot texel.
    tilt = np.where((x % 2 == 0)[..., None], [218, 128, 218, 255], [37, 128, 218, 255]).astype(np.uint8)
    hot = np.zeros((n, n, 4), np.float16)
    hot[5, 7] = 1e4
    textures = [
        ir.Texture("normals", n, n, "Rgba8Unorm", [np.ascontiguousarray(tilt)], usage="normal"),
        ir.Texture("emission", n, n, "Rgba16Float", [hot]),
        ir.Texture("lightmap0", n, n, "Rgba16Float", [hot.copy()]),
    ]
    assert textures[1].usage == "hdr"
    scene = ir.Scene("s", "s.gltf", textures=textures, lightmap=ir.LightmapLayout(5.0, [(n, n)], textures=[2]))
    out, rec = _textures_stage(scene, CookSettings(), StageCache(tmp_path / "cache", enabled=False), Progress(enabled=False))
    assert rec.items == 2 and [len(t.mips) for t in out.textures] == [6, 6, 1]
    # Normal maps leave 16-bit at every level, level 0 included, each texel unit length (1e-3).
    assert out.textures[0].format == "Rgba16Unorm"
    for level in out.textures[0].mips:
        assert level.dtype == np.uint16
        v = level[..., :3].astype(np.float64) / 65535.0 * 2.0 - 1.0
        assert np.abs(np.linalg.norm(v, axis=-1) - 1.0).max() <= 1e-3, "normals are renormalised"
    assert (np.abs(out.textures[0].mips[1][..., 0].astype(int) - 32768) <= 300).all(), "opposite tilts average to flat"
    for level in out.textures[1].mips[1:]:
        assert level.dtype == np.float16 and float(level.min()) >= 0.0
    # Usage survives the crossing to Rust and back.
    text, arrays = ir.to_wire(out)
    assert [t.usage for t in ir.from_wire(text, arrays).textures] == ["normal", "hdr", "hdr"]


def material_gltf(images: list[bytes], material: dict) -> dict:
    """The textured quad of `quad_gltf` with several images (texture i = image i) and `material`."""
    doc = quad_gltf(images[0])
    doc["materials"] = [material]
    doc["textures"] = [{"source": i} for i in range(len(images))]
    doc["images"] = [{"name": f"img{i}", "uri": "data:image/png;base64," + base64.b64encode(png).decode()} for i, png in enumerate(images)]
    return doc


def bumpy_normals(n: int, bits: int) -> np.ndarray:
    """A tangent-space normal map of a bumpy height field, UNORM with `bits` per channel."""
    y, x = np.mgrid[0:n, 0:n].astype(np.float64)
    dx, dy = 1.4 * np.cos(x * 0.7) * np.cos(y * 0.45), -0.9 * np.sin(x * 0.7) * np.sin(y * 0.45)
    v = np.stack([-dx, -dy, np.ones_like(dx)], axis=-1)
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    top = (1 << bits) - 1
    out = np.full((n, n, 4), top, np.uint16 if bits == 16 else np.uint8)
    out[..., :3] = np.rint((v * 0.5 + 0.5) * top)
    return out


def test_gltf_material_textures_are_imported_by_what_they_hold(tmp_path):
    # One image as base colour and emission (colour, sRGB), one as normal map (vectors, 16-bit
    # out), one as metallic-roughness and occlusion (linear data): each slot gets the texture its
    # usage makes, an image read two ways becomes two textures, one read twice the same way one.
    colour = foliage_rgba(32)
    colour[..., 3] = 255
    data = np.zeros((32, 32, 4), np.uint8)
    data[..., 0] = np.arange(32)[None, :] * 8  # occlusion ramp
    data[..., 1] = 200  # roughness
    data[..., 2] = np.arange(32)[:, None] * 8  # metalness ramp
    data[..., 3] = 255
    material = {
        "name": "rock",
        "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}, "metallicRoughnessTexture": {"index": 2}},
        "normalTexture": {"index": 1, "scale": 0.8},
        "occlusionTexture": {"index": 2, "strength": 0.5},
        "emissiveTexture": {"index": 0},
        "emissiveFactor": [1, 1, 1],
    }
    src = tmp_path / "rock.gltf"
    src.write_text(json.dumps(material_gltf([png_bytes(colour), png_bytes(bumpy_normals(32, 8)), png_bytes(data)], material)))
    out = tmp_path / "rock.pack"
    cook(src, out, CookSettings(lods=False, lightmap_uvs=False, baking=False, compress=False))
    manifest = json.loads(_core.read_pack_manifest(str(out)))
    [m] = manifest["materials"]
    assert m["base_color_texture"] == m["emissive_texture"], "one image read as colour twice is one texture"
    assert m["metallic_roughness_texture"] == m["occlusion_texture"]
    assert len({m["base_color_texture"], m["normal_texture"], m["occlusion_texture"]}) == 3
    assert (m["normal_scale"], m["occlusion_strength"]) == (pytest.approx(0.8), pytest.approx(0.5))
    formats = [t["format"] for t in manifest["textures"]]
    assert formats[m["base_color_texture"]] == "Rgba8Srgb"
    assert formats[m["normal_texture"]] == "Rgba16Unorm"
    assert formats[m["occlusion_texture"]] == "Rgba8Unorm"
    # Every level of the cooked normal map holds unit vectors (1e-3); the data texture is
    # filtered per channel in linear space (the ramp's mean is kept, not pulled toward sRGB).
    fmt, levels = _core.read_pack_texture(str(out), m["normal_texture"])
    assert fmt == "Rgba16Unorm" and len(levels) == 6
    for level in levels:
        v = level[..., :3].astype(np.float64) / 65535.0 * 2.0 - 1.0
        assert np.abs(np.linalg.norm(v, axis=-1) - 1.0).max() <= 1e-3
    _, data_levels = _core.read_pack_texture(str(out), m["occlusion_texture"])
    assert abs(float(data_levels[1][..., 0].mean()) - float(data[..., 0].mean())) <= 1.0
    assert np.all(data_levels[2][..., 1] == 200)


def test_a_16_bit_normal_map_keeps_its_bits(tmp_path):
    normals16 = bumpy_normals(16, 16)
    src = tmp_path / "n.gltf"
    material = {"name": "m", "normalTexture": {"index": 0}}
    src.write_text(json.dumps(material_gltf([png_bytes(normals16)], material)))
    out = tmp_path / "n.pack"
    cook(src, out, CookSettings(lods=False, lightmap_uvs=False, baking=False, compress=False))
    fmt, levels = _core.read_pack_texture(str(out), 0)
    # Level 0 is only renormalised: within a few 16-bit steps of the authored texels, which
    # an 8-bit detour would have moved by ~128 steps.
    assert fmt == "Rgba16Unorm"
    assert np.abs(levels[0].astype(np.int64) - normals16.astype(np.int64)).max() <= 4
