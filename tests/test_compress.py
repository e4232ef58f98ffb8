"""The compress stage (issue 24): material textures block-compressed by class (BC7 colour and
data, BC5 normal maps, BC4 occlusion), their quality measured here against the uncompressed cook
of the same source (levels decoded by pack::bc, an independent decoder), the quality bar, the
per-texture overrides and --no-compress."""

from __future__ import annotations

import json

import numpy as np
import pytest

from asset_pipeline import _core
from asset_pipeline.cook import cook_detailed
from asset_pipeline.pipeline import CookSettings
from test_mips import foliage_rgba, material_gltf, png_bytes

# The acceptance's bars.
MIN_PSNR_DB = 38.0
MAX_MEAN_ANGLE_DEG = 1.5

FAST = dict(lods=False, lightmap_uvs=False, baking=False, report=False)


def linear(srgb8: np.ndarray) -> np.ndarray:
    c = srgb8.astype(np.float64) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def psnr(mse: float) -> float:
    return 10.0 * np.log10(1.0 / max(mse, 1e-12))


def colour_psnr(a: list[np.ndarray], b: list[np.ndarray]) -> float:
    """Linear-light RGB premultiplied by alpha, and alpha, over every level (texel-weighted)."""
    se, n = 0.0, 0
    for x, y in zip(a, b):
        ax, ay = x[..., 3:4] / 255.0, y[..., 3:4] / 255.0
        se += float(((linear(x[..., :3]) * ax - linear(y[..., :3]) * ay) ** 2).sum() + ((ax - ay) ** 2).sum())
        n += x.shape[0] * x.shape[1] * 4
    return psnr(se / n)


def normal_angles(plain: list[np.ndarray], bc5: list[np.ndarray]) -> np.ndarray:
    """Degrees between the uncompressed 16-bit normals and the BC5 ones with z rebuilt, every level."""
    out = []
    for p, c in zip(plain, bc5):
        v = p[..., :3].astype(np.float64) / 65535.0 * 2.0 - 1.0
        xy = c.astype(np.float64) / 255.0 * 2.0 - 1.0
        w = np.concatenate([xy, np.sqrt(np.maximum(1.0 - (xy ** 2).sum(-1, keepdims=True), 0.0))], axis=-1)
        cos = (v * w).sum(-1) / (np.linalg.norm(v, axis=-1) * np.linalg.norm(w, axis=-1))
        out.append(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))).ravel())
    return np.concatenate(out)


def rolling_normals(n: int) -> np.ndarray:
    """An 8-bit tangent-space normal map of gently rolling ground (slopes up to ~30°, a bump
    every 30 texels: what stone or terrain maps look like; test_mips' bumpy map, a 55° bump
    every 9 texels, is beyond BC5's 8 steps a block: 3.2° mean, which the bar keeps out)."""
    y, x = np.mgrid[0:n, 0:n].astype(np.float64)
    dx, dy = 0.5 * np.cos(x * 0.21) * np.cos(y * 0.17), -0.4 * np.sin(x * 0.21) * np.sin(y * 0.17)
    v = np.stack([-dx, -dy, np.ones_like(dx)], axis=-1)
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    out = np.full((n, n, 4), 255, np.uint8)
    out[..., :3] = np.rint((v * 0.5 + 0.5) * 255)
    return out


def levels_of(pack, index: int) -> tuple[str, list[np.ndarray]]:
    return _core.read_pack_texture(str(pack), index)


@pytest.fixture(scope="module")
def material(tmp_path_factory):
    """A material with a colour texture (with alpha), a normal map, metallic-roughness and a
    separate occlusion texture, cooked compressed and uncompressed."""
    tmp = tmp_path_factory.mktemp("compress")
    colour = foliage_rgba(64)
    y, x = np.mgrid[0:64, 0:64]
    mr = np.stack([np.full_like(x, 255), 40 + 3 * x, 255 - 3 * y, np.full_like(x, 255)], -1).astype(np.uint8)
    ao = np.stack([128 + (60 * np.sin(x * 0.2) * np.cos(y * 0.15)).astype(int)] * 3 + [np.full_like(x, 255)], -1).astype(np.uint8)
    doc = material_gltf([png_bytes(colour), png_bytes(rolling_normals(64)), png_bytes(mr), png_bytes(ao)], {
        "name": "rock",
        "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}, "metallicRoughnessTexture": {"index": 2}},
        "normalTexture": {"index": 1},
        "occlusionTexture": {"index": 3},
        "alphaMode": "BLEND",
    })
    src = tmp / "rock.gltf"
    src.write_text(json.dumps(doc))
    packed, plain = tmp / "bc.pack", tmp / "plain.pack"
    result = cook_detailed(src, packed, settings=CookSettings(**FAST, cache_dir=tmp / "cache"))
    cook_detailed(src, plain, settings=CookSettings(**FAST, compress=False, cache_dir=tmp / "cache"))
    return src, packed, plain, result


def test_each_class_gets_its_format_and_clears_its_bar(material):
    _, packed, plain, result = material
    m = json.loads(_core.read_pack_manifest(str(packed)))
    [mat] = m["materials"]
    formats = [t["format"] for t in m["textures"]]
    assert formats[mat["base_color_texture"]] == "Bc7Srgb"
    assert formats[mat["normal_texture"]] == "Bc5Unorm"
    assert formats[mat["metallic_roughness_texture"]] == "Bc7Unorm"
    assert formats[mat["occlusion_texture"]] == "Bc4Unorm"
    pm = json.loads(_core.read_pack_manifest(str(plain)))
    assert pm["materials"] == m["materials"]
    plain_formats = [t["format"] for t in pm["textures"]]
    slots = ("base_color_texture", "normal_texture", "metallic_roughness_texture", "occlusion_texture")
    assert [plain_formats[mat[s]] for s in slots] == ["Rgba8Srgb", "Rgba16Unorm", "Rgba8Unorm", "Rgba8Unorm"]

    # Colour: PSNR in linear light measured here, from the pack's decoded levels.
    _, a = levels_of(plain, mat["base_color_texture"])
    _, b = levels_of(packed, mat["base_color_texture"])
    assert len(a) == len(b) == 7
    colour = colour_psnr(a, b)
    assert colour >= MIN_PSNR_DB
    # Normal map: angular error with z rebuilt.
    _, a = levels_of(plain, mat["normal_texture"])
    _, b = levels_of(packed, mat["normal_texture"])
    assert b[0].shape == (64, 64, 2)
    angles = normal_angles(a, b)
    assert angles.mean() <= MAX_MEAN_ANGLE_DEG
    # Data (R, G, B) and occlusion (R).
    _, a = levels_of(plain, mat["metallic_roughness_texture"])
    _, b = levels_of(packed, mat["metallic_roughness_texture"])
    data = psnr(np.mean([((x[..., :3] / 255.0 - y[..., :3] / 255.0) ** 2).mean() for x, y in zip(a[:1], b[:1])]))
    assert data >= MIN_PSNR_DB
    _, a = levels_of(plain, mat["occlusion_texture"])
    _, b = levels_of(packed, mat["occlusion_texture"])
    assert b[0].shape == (64, 64, 1)
    occlusion = psnr(float(((a[0][..., 0] / 255.0 - b[0][..., 0] / 255.0) ** 2).mean()))
    assert occlusion >= MIN_PSNR_DB

    # The stage's own record agrees with what was measured here.
    records = {r["class"]: r for r in result.compress["per_texture"]}
    assert records["colour"]["quality"]["psnr_db"] == pytest.approx(colour, abs=0.05)
    assert records["normal"]["quality"]["mean_deg"] == pytest.approx(angles.mean(), rel=0.02)
    assert result.compress["compressed"] == 4 and result.compress["kept"] == 0
    assert result.compress["bytes_after"] * 3 < result.compress["bytes_before"]


def test_noise_misses_the_bar_and_stays_uncompressed_unless_forced(tmp_path):
    # Independent random colours in every texel: no 4x4 block lies near a line in colour space,
    # so BC7 cannot reach 38 dB; the stage keeps the texture as it was and says why.
    rng = np.random.default_rng(5)
    noise = rng.integers(0, 256, (32, 32, 4), dtype=np.uint8)
    src = tmp_path / "noise.gltf"
    src.write_text(json.dumps(material_gltf([png_bytes(noise)], {"name": "n", "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}, "alphaMode": "BLEND"})))
    r = cook_detailed(src, tmp_path / "a.pack", settings=CookSettings(**FAST))
    [rec] = r.compress["per_texture"]
    assert rec["kept"] == "below the quality bar"
    assert rec["quality"]["psnr_db"] < MIN_PSNR_DB
    assert levels_of(tmp_path / "a.pack", 0)[0] == "Rgba8Srgb"
    r = cook_detailed(src, tmp_path / "b.pack", settings=CookSettings(**FAST, texture_compression={"img*": "force"}))
    assert levels_of(tmp_path / "b.pack", 0)[0] == "Bc7Srgb"
    assert r.compress["per_texture"][0]["quality"]["psnr_db"] == pytest.approx(rec["quality"]["psnr_db"])


def test_overrides_and_no_compress_from_the_command_line(material, run_cook, tmp_path):
    src = material[0]
    out = tmp_path / "o.pack"
    p = run_cook(str(src), "-o", str(out), "--no-lods", "--no-bake", "--texture-compression", "img1=none", "--texture-compression", "img3=auto")
    assert p.returncode == 0, p.stderr
    formats = [t["format"] for t in json.loads(_core.read_pack_manifest(str(out)))["textures"]]
    names = [t["name"] for t in json.loads(_core.read_pack_manifest(str(out)))["textures"]]
    assert dict(zip(names, formats)) == {"img0": "Bc7Srgb", "img1": "Rgba16Unorm", "img2": "Bc7Unorm", "img3": "Bc4Unorm"}
    report = out.with_suffix(".report.md").read_text()
    assert "## Texture compression" in report and "override none" in report

    p = run_cook(str(src), "-o", str(out), "--no-lods", "--no-bake", "--no-compress")
    assert p.returncode == 0, p.stderr
    assert not any(t["format"].startswith("Bc") for t in json.loads(_core.read_pack_manifest(str(out)))["textures"])

    # A pattern that matches nothing is a typo: one line naming it, nothing written.
    bad = tmp_path / "bad.pack"
    p = run_cook(str(src), "-o", str(bad), "-q", "--no-bake", "--texture-compression", "rocks*=none")
    assert p.returncode == 2 and "override 'rocks*' matches no texture" in p.stderr and "Traceback" not in p.stderr
    assert p.stderr.count("\n") == 1 and not bad.exists()
    p = run_cook(str(src), "-o", str(bad), "--no-bake", "--texture-compression", "img1=bc9")
    assert p.returncode == 2 and "expected PATTERN=MODE" in p.stderr and not bad.exists()
    p = run_cook(str(src), "-o", str(bad), "--no-bake", "--no-compress", "--texture-compression", "img1=none")
    assert p.returncode == 2 and "needs compression" in p.stderr


def test_a_second_cook_takes_every_texture_from_the_cache(material, tmp_path):
    src = material[0]
    cache = tmp_path / "cache"
    cook_detailed(src, tmp_path / "a.pack", settings=CookSettings(**FAST, cache_dir=cache))
    r = cook_detailed(src, tmp_path / "b.pack", settings=CookSettings(**FAST, cache_dir=cache, force=False))
    [stage] = [s for s in r.stages if s.name == "compress"] or [None]
    if stage is None:  # the whole cook was up to date: nothing ran at all
        assert r.up_to_date
    else:
        assert stage.cached == stage.items == 4
    assert (tmp_path / "a.pack").read_bytes() == (tmp_path / "b.pack").read_bytes()


def test_shared_samples_textures_clear_the_bars(gltf_samples, tmp_path):
    # Every material texture of GolfBall (a 1024² normal map) and BoxTextured (a colour map):
    # the stage's measured quality, against the bars.
    for name in ("GolfBall/GolfBall.glb", "BoxTextured/BoxTextured.gltf"):
        r = cook_detailed(gltf_samples / name, tmp_path / "s.pack", settings=CookSettings(**FAST))
        assert r.compress["kept"] == 0 and r.compress["compressed"] >= 1, name
        for rec in r.compress["per_texture"]:
            q = rec["quality"]
            assert (q["mean_deg"] <= MAX_MEAN_ANGLE_DEG) if "mean_deg" in q else (q["psnr_db"] >= MIN_PSNR_DB), (name, rec)
