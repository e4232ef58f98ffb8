"""Mip chains: `_core.mip_chain` (cook_core::mips) and the cooker's textures stage end to end.
The filter's own tests, with the notes' thresholds, are Rust unit tests in
asset_pipeline/core/src/mips/tests.rs; these check the crossing, the stage and the pack."""

import base64
import io
import json
import struct
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
    buf = io.BytesIO()
    Image.fromarray(rgba, "RGBA").save(buf, "PNG")
    return buf.getvalue()


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
    result = cook(src, out, CookSettings(lods=False, lightmap_uvs=False, baking=False))
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
    cook(src2, tmp_path / "blend.pack", CookSettings(lods=False, lightmap_uvs=False, baking=False))
    _, plain = _core.read_pack_texture(tmp_path / "blend.pack", 0)
    assert abs(coverage(plain[3], 0.5) - c0) > 0.02
    # A re-cook to another path takes the chain from the stage cache.
    again = cook(src, tmp_path / "again.pack", CookSettings(lods=False, lightmap_uvs=False, baking=False))
    stage = next(s for s in again.stages if s.name == "textures")
    assert (stage.items, stage.cached) == (1, 1)
    assert _core.read_pack_texture(tmp_path / "again.pack", 0)[1][3].tobytes() == levels[3].tobytes()


def test_no_mips_keeps_one_level(run_cook, tmp_path):
    src = tmp_path / "q.gltf"
    src.write_text(json.dumps(quad_gltf(png_bytes(foliage_rgba(32)))))
    out = tmp_path / "q.pack"
    r = run_cook(src, "-o", out, "--no-mips")
    assert r.returncode == 0, r.stderr
    assert asset_pipeline.read_pack_summary(out)["texture_mips"] == [1]
    r = run_cook(src, "-o", out, "--mip-filter", "box")
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
    for level in out.textures[0].mips[1:]:
        v = level[..., :3].astype(np.float64) / 127.5 - 1.0
        assert np.all(np.abs(np.linalg.norm(v, axis=-1) - 1.0) <= np.sqrt(3) / 255), "normals are renormalised"
    assert (np.abs(out.textures[0].mips[1][..., 0].astype(int) - 128) <= 1).all(), "opposite tilts average to flat"
    for level in out.textures[1].mips[1:]:
        assert level.dtype == np.float16 and float(level.min()) >= 0.0
    # Usage survives the crossing to Rust and back.
    text, arrays = ir.to_wire(out)
    assert [t.usage for t in ir.from_wire(text, arrays).textures] == ["normal", "hdr", "hdr"]
