"""The bake stage end to end: a small level cooked with lightmaps and probes, the files it writes,
determinism across thread counts, Ctrl-C, and bad arguments."""

from __future__ import annotations

import json
import subprocess
import textwrap
from pathlib import Path

import numpy as np
import pytest

import asset_pipeline
from asset_pipeline import _core, bake, ir
from asset_pipeline.lightmap_post import read_exr
from asset_pipeline.pipeline import CookSettings, cook

COOK = Path(__file__).resolve().parent.parent / ".venv" / "bin" / "cook"

# A closed room (walls, floor, roof) with a doorway and a skylight, on a ground slab, under sun
# and sky, with a point light inside: light enters and bounces; the room's far corner is in shadow.
ROOM = """
[level]
name = "room"
texels_per_metre = 4
sky = { color = [0.5, 0.6, 1.0], intensity = 5000 }

[[materials]]
name = "stone"
base_color = [0.7, 0.65, 0.6]

[[brushes]]
name = "slab"
kind = "box"
size = [16, 1, 16]
translation = [0, -0.5, 0]
material = "stone"

[[brushes]]
name = "shell"
kind = "box"
size = [6, 4, 6]
translation = [0, 2, 0]
material = "stone"

[[brushes]]
name = "inside"
kind = "box"
size = [5.4, 3.4, 5.4]
translation = [0, 2, 0]
material = "stone"

[[brushes]]
name = "door"
kind = "box"
size = [1.2, 2.2, 1]
translation = [0, 1.4, 2.9]
material = "stone"

[[brushes]]
name = "skylight"
kind = "box"
size = [1, 1, 1]
translation = [1.5, 3.8, -1.5]
material = "stone"

[[objects]]
name = "ground"
op = "union"
operands = ["slab"]

[[objects]]
name = "room"
op = "difference"
operands = ["shell", "inside", "door", "skylight"]

[[lights]]
name = "sun"
kind = "sun"
direction = [-0.3, -0.8, -0.5]
intensity = 80000

[[lights]]
name = "lamp"
kind = "point"
position = [-1.5, 2.5, -1.5]
intensity = 100
range = 8
"""

# Irradiance lightmaps (not the default, directional): these tests check B = H/pi with the sun in it
# per texel, which only an irradiance page holds (a directional page's RGB is b0, without the sun);
# the directional bake has tests of its own below.
QUICK = bake.BakeSettings(preset="draft", samples=8, probe_samples=16, lightmap_mode="irradiance")


@pytest.fixture(scope="module")
def room(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("room")
    p = d / "room.toml"
    p.write_text(textwrap.dedent(ROOM))
    return p


@pytest.fixture(scope="module")
def cooked(room, tmp_path_factory):
    out = tmp_path_factory.mktemp("out") / "room.pack"
    result = cook(room, out, CookSettings(bake=QUICK, lods=False))
    return out, result


def test_bake_writes_exr_pages_and_puts_lightmaps_and_probes_in_the_pack(cooked):
    out, result = cooked
    assert [s.name for s in result.stages] == ["level", "uv2", "bake", "chunks", "mesh_opt", "textures", "compress", "write"]
    exr = out.with_name("room.lightmap0.exr")
    img = read_exr(exr)
    # Readable by the OpenEXR package as well, as half floats.
    import OpenEXR

    with OpenEXR.File(str(exr)) as f:
        parts = f.parts[0]
        rgb = parts.channels["RGB"].pixels if "RGB" in parts.channels else np.stack([parts.channels[c].pixels for c in "RGB"], -1)
    assert rgb.dtype == np.float16 and rgb.shape == img.shape
    np.testing.assert_array_equal(rgb.astype(np.float32), img)

    summary = asset_pipeline.read_pack_summary(out)
    assert summary["lightmap_pages"] == 1 and summary["lightmaps_baked"] == 1, summary
    assert summary["probes"] > 0, summary
    # Material textures get their mip chains; the lightmap page (the last texture) keeps one level.
    assert summary["texture_mips"][-1] == 1 and all(m > 1 for m in summary["texture_mips"][:-1]), summary

    # HDR kept (sunlit ground is thousands of nits, no clamp at 1), nothing negative or NaN.
    assert np.isfinite(img).all() and img.min() >= 0.0
    assert img.max() > 1000.0, img.max()
    report = out.with_suffix(".report.md").read_text()
    assert "## Bake" in report and "room.lightmap0.exr" in report and "Probes:" in report


def test_probes_see_the_room_dark_and_the_yard_bright(room, tmp_path):
    scene = _scene(room)
    baked = bake.bake_level(scene, QUICK)
    g = baked.probes
    nx, ny, nz = g.counts
    pos = np.array(g.origin) + np.stack(np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij"), -1).transpose(2, 1, 0, 3).reshape(-1, 3) * np.array(g.spacing)
    inside = (np.abs(pos[:, 0]) < 2.4) & (np.abs(pos[:, 2]) < 2.4) & (pos[:, 1] > 0.5) & (pos[:, 1] < 3.5)
    outside = (np.abs(pos[:, 0]) > 4.0) & (pos[:, 1] > 0.5) & (pos[:, 1] < 3.5)
    assert inside.any() and outside.any()
    # DC term: the mean of B over directions.
    dc = g.sh[:, 0, 1] * 0.2820948
    assert np.median(dc[outside]) > 3 * np.median(dc[inside]), (np.median(dc[outside]), np.median(dc[inside]))
    assert g.sun_visibility[outside].mean() > 0.9 and g.sun_visibility[inside].mean() < 0.5


def _scene(room: Path) -> ir.Scene:
    """The room level built, with lightmap UVs and a region per static instance (what the cook's
    level and uv2 stages make)."""
    import dataclasses

    from asset_pipeline.csg import build_level
    from asset_pipeline.level import load_level
    from asset_pipeline.uv2 import Instance, Uv2Settings, lightmap_uvs

    scene = build_level(load_level(room))
    static_meshes, static_nodes = scene.static_meshes(), scene.static_nodes()
    local = {m: k for k, m in enumerate(static_meshes)}
    r = lightmap_uvs([scene.meshes[m].base for m in static_meshes], Uv2Settings(texels_per_metre=4.0),
                     instances=[Instance(local[scene.nodes[n].mesh]) for n in static_nodes])
    meshes, nodes = list(scene.meshes), list(scene.nodes)
    for m, lod in zip(static_meshes, r.lods):
        meshes[m] = dataclasses.replace(meshes[m], lods=[lod])
    for n, region in zip(static_nodes, r.regions):
        nodes[n] = dataclasses.replace(nodes[n], lightmap=region)
    return dataclasses.replace(scene, meshes=meshes, nodes=nodes, lightmap=r.layout)


def _quad_lod(size: float, y: float, up: bool) -> ir.Lod:
    """A size x size quad at height y facing up (or down), its own lightmap UVs in [0.1, 0.9]."""
    h = size / 2
    pos = np.array([[-h, y, -h], [h, y, -h], [h, y, h], [-h, y, h]], np.float32)
    tris = np.array([[0, 2, 1], [0, 3, 2]] if up else [[0, 1, 2], [0, 2, 3]], np.uint32)
    uv1 = (0.5 + 0.4 * pos[:, [0, 2]] / h).astype(np.float32)
    nrm = np.tile(np.array([[0.0, 1.0 if up else -1.0, 0.0]], np.float32), (4, 1))
    return ir.Lod(attributes={"position": pos, "normal": nrm, "uv1": uv1}, triangles=tris, materials=np.zeros(2, np.uint32),
                  lightmap_blocks=np.zeros(2, np.uint32))


def _translate(x: float, y: float, z: float) -> tuple:
    return (1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, x, y, z, 1)


def _two_tiles() -> ir.Scene:
    """One mesh (a 2 x 2 m floor tile) placed twice: in the open at x = -5 and at x = 5 under a
    4 x 4 m roof 1 m up; each placement (and the roof) its own quarter of a 32 x 32 page."""
    tile, roof = _quad_lod(2.0, 0.0, up=True), _quad_lod(4.0, 0.0, up=False)
    region = lambda ou, ov: {"page": 0, "scale": [0.5, 0.5], "offset": [ou, ov]}
    return ir.Scene(
        name="tiles", source="test",
        meshes=[ir.Mesh("tile", [tile]), ir.Mesh("roof", [roof])],
        materials=[ir.Material(name="stone", base_color=(0.6, 0.6, 0.6, 1.0))],
        nodes=[ir.Node("sunny", local=_translate(-5, 0, 0), mesh=0, static=True, lightmap=region(0.0, 0.0)),
               ir.Node("shaded", local=_translate(5, 0, 0), mesh=0, static=True, lightmap=region(0.5, 0.0)),
               ir.Node("roof", local=_translate(5, 1, 0), mesh=1, static=True, lightmap=region(0.0, 0.5))],
        lights=[ir.Light("sun", "sun", intensity=50000.0, direction=(-0.1, -1.0, 0.05))],
        sky=ir.Sky(color=(0.5, 0.6, 1.0), intensity=2000.0),
        lightmap=ir.LightmapLayout(texels_per_metre=6.0, pages=[(32, 32)], padding=2),
    )


def test_every_static_instance_gets_its_own_lightmap():
    # The tile in the sun and its copy under the roof share one mesh (one set of lightmap UVs)
    # but not their light: each region is baked at its own instance's world positions.
    scene = _two_tiles()
    baked = bake.bake_level(scene, QUICK)
    page = baked.pages[0]
    sunny, shaded = page[4:12, 4:12], page[4:12, 20:28]  # inside each region's chart
    assert np.isfinite(page).all() and shaded.min() > 0.0, "the shaded tile is baked (sky light from the sides)"
    e = 50000.0 / np.pi  # the sunny tile's direct light alone, 0.99 of it at the sun's angle
    assert sunny.mean() > 0.9 * e and shaded.mean() < 0.1 * e, (sunny.mean(), shaded.mean())
    stats = baked.stats
    assert stats["static_instances"] == 3
    assert [(i["node"], i["mesh"]) for i in stats["instances"]] == [("sunny", "tile"), ("shaded", "tile"), ("roof", "roof")]
    texels = [i["texels"] for i in stats["instances"]]
    assert texels[0] == texels[1] > 100 and texels[2] > 100 and sum(texels) == stats["texels"], texels
    lines = bake.describe(stats)
    assert any("Static instances: 3" in l for l in lines) and any("instance 'shaded' (mesh 'tile')" in l for l in lines), lines


def test_same_seed_one_and_two_threads_give_identical_exr_bytes(room, tmp_path):
    outs = []
    for threads in (1, 2):
        out = tmp_path / f"t{threads}" / "room.pack"
        out.parent.mkdir()
        cook(room, out, CookSettings(bake=bake.BakeSettings(preset="draft", samples=4, probe_samples=8, seed=3, threads=threads), lods=False, report=False))
        outs.append(out)
    a, b = (o.with_name("room.lightmap0.exr").read_bytes() for o in outs)
    assert a == b
    assert outs[0].read_bytes() == outs[1].read_bytes()


def test_interrupting_the_bake_leaves_the_previous_outputs(room, tmp_path):
    out = tmp_path / "room.pack"
    cook(room, out, CookSettings(bake=QUICK, lods=False, report=False))
    exr = out.with_name("room.lightmap0.exr")
    before = (out.read_bytes(), exr.read_bytes())

    def interrupt(stage, done, total):
        if stage.startswith("bake") and done > 0:
            raise KeyboardInterrupt

    from asset_pipeline.progress import Progress

    with pytest.raises(KeyboardInterrupt):
        cook(room, out, CookSettings(bake=bake.BakeSettings(preset="draft", samples=2, probe_samples=4, seed=9), lods=False, report=False),
             progress=Progress(callback=interrupt))
    assert (out.read_bytes(), exr.read_bytes()) == before
    assert sorted(p.name for p in tmp_path.iterdir() if not p.name.startswith(".")) == ["room.lightmap0.exr", "room.pack"]


@pytest.mark.parametrize("args, message", [
    (("--samples", "0"), "argument --samples: 0 is not 1 or more"),
    (("--quality", "ultra"), "argument --quality: invalid choice: 'ultra'"),
    (("--bounces", "x"), "argument --bounces: 'x' is not a whole number"),
])
def test_bad_bake_arguments_are_one_line_errors(room, tmp_path, args, message):
    r = subprocess.run([str(COOK), str(room), "-o", str(tmp_path / "x.pack"), *args], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and message in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert not (tmp_path / "x.pack").exists()


def test_directional_texels_hold_the_sky_in_l1_and_the_suns_visibility():
    # bake_points(directional=True) (issue 22): the sunny tile sees the sky over its hemisphere,
    # b0 = L/2 and b1 = (0, L/2, 0) per channel (shading.md section 4.1, less the sliver of
    # sky the roof 10 m away hides), and the whole sun; the tile under the roof none of it.
    st = bake.static_scene(_two_tiles())
    baker = bake._core.Baker(*st.baker_args)
    points = np.array([[-5.0, 0.0, 0.0]] * 32 + [[5.0, 0.0, 0.0]] * 32, np.float32)
    normals = np.tile(np.array([[0.0, 1.0, 0.0]], np.float32), (64, 1))
    out, rays = baker.bake_points(points, normals, samples=64, bounces=1, directional=True)
    assert out.shape == (64, 13) and out.dtype == np.float32 and rays > 64 * 64
    sunny, shaded = out[:32].mean(axis=0), out[32:].mean(axis=0)
    sky = 2000.0 * np.array([0.5, 0.6, 1.0])
    np.testing.assert_allclose(sunny[0:3], sky / 2, rtol=0.03)
    b1 = sunny[3:12].reshape(3, 3)  # per channel (x, y, z)
    np.testing.assert_allclose(b1[:, 1], sky / 2, rtol=0.03)
    assert np.abs(b1[:, [0, 2]]).max() < 0.03 * sky.max()
    assert (out[:32, 12] == 1.0).all() and (out[32:, 12] == 0.0).all(), out[:, 12]
    # Under the roof: 59% of the upper hemisphere's solid angle is the roof's grey underside
    # (lit by the open sky below it, there being no ground), so less light, less from above.
    assert shaded[0] < 0.8 * sunny[0] and shaded[4] < 0.5 * sunny[4], (shaded, sunny)


def test_a_directional_bake_puts_b0_the_sun_and_the_direction_in_the_pack_and_the_exr(room, tmp_path):
    # --lightmap-mode directional (issue 22): per page b0 (Rgba16Float, BC6H once compressed)
    # and the luminance's direction with the sun's visibility as alpha (Rgba8Unorm, BC7), in the
    # pack and in the page's EXR (b0 as its RGB, "sun.Y", "direction.X/Y/Z", written from the
    # uncompressed pages); the sun is not in b0.
    out = tmp_path / "room.pack"
    r = subprocess.run([str(COOK), str(room), "-o", str(out), "-q", "--no-lods", "--quality", "draft", "--samples", "8",
                        "--probe-samples", "16", "--lightmap-mode", "directional",
                        # At draft samples the direction is noisy enough to land under BC7's bar
                        # (kept RGBA8 by default): forced here so both formats are checked.
                        "--texture-compression", "lightmap0 direction=force"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    summary = asset_pipeline.read_pack_summary(out)
    assert summary["lightmap_pages"] == 1 and summary["lightmaps_baked"] == 1, summary
    import OpenEXR

    with OpenEXR.File(str(out.with_name("room.lightmap0.exr"))) as f:
        ch = f.parts[0].channels
        names = set(ch)
        get = lambda n: np.asarray(ch[n].pixels, np.float32)
        b0 = np.stack([get(c) for c in "RGB"], -1) if "RGB" not in ch else np.asarray(ch["RGB"].pixels, np.float32)
        sun = get("sun.Y")
        direction = np.stack([get(f"direction.{a}") for a in "XYZ"], -1)
    assert {"sun.Y", "direction.X", "direction.Y", "direction.Z"} <= names, names
    assert np.isfinite(b0).all() and b0.min() >= 0.0 and sun.min() >= 0.0 and sun.max() <= 1.0
    # Sunlit texels (the yard) see the whole sun, the room's far corner none of it; b0 holds the
    # sky and bounces only: the sun's direct light alone would add 80 000 lux / 4 pi = 6366 nits.
    assert (sun == 1.0).mean() > 0.2 and (sun == 0.0).mean() > 0.05, ((sun == 1.0).mean(), (sun == 0.0).mean())
    assert np.median(b0[sun == 1.0][:, 1]) < 5000.0
    # The direction is a unit-bounded vector, mostly up in the yard (the sky above it).
    t = (255.0 * direction - 128.0) / 127.0
    assert np.linalg.norm(t, axis=-1).max() <= 1.0 + 1.5 / 127.0
    assert np.median(t[sun == 1.0][:, 1]) > 0.2
    assert "Preset draft, directional lightmaps;" in out.with_suffix(".report.md").read_text()
    # In the pack, compressed (issue 24): b0 as BC6H within 3 % (median relative error, the
    # texels not black in both) of the uncompressed page the EXR holds; the direction and the
    # sun's visibility as BC7 within 3 / 255 (median) of its bytes.
    formats = {}
    for i in range(summary["textures"]):
        fmt, levels = _core.read_pack_texture(out, i)
        formats[fmt] = np.asarray(levels[0], np.float32)
    assert set(formats) == {"Bc6hUfloat", "Bc7Unorm"}, set(formats)
    packed_b0 = formats["Bc6hUfloat"][..., :3]
    exact = b0.astype(np.float16).astype(np.float32)
    norm, err = np.linalg.norm(exact, axis=-1), np.linalg.norm(packed_b0 - exact, axis=-1)
    seen = (norm > 0) | (err > 0)
    relative = np.where(norm > 0, err / np.maximum(norm, 1e-30), np.inf)[seen]
    assert np.median(relative) <= 0.03, np.median(relative)
    packed_dir = formats["Bc7Unorm"]
    exact_dir = np.concatenate([direction, sun[..., None]], axis=-1) * 255.0
    assert np.median(np.abs(packed_dir - exact_dir)) <= 3.0
    print(f"BC6H lightmap: median relative error {100 * np.median(relative):.2f}%, p95 {100 * np.percentile(relative, 95):.2f}%")
    # The exposure's log-average (textures.md eq. 21.1) was taken from the pages as baked, not
    # from the compressed ones: recomputed here in numpy from the EXR's uncompressed channels
    # (pack::exposure's estimate: b0 (1 + 2 |t|) + the visible sun's E cos / pi toward t).
    manifest = json.loads(_core.read_pack_manifest(out))
    sun_light = next(l for l in manifest["lights"] if l["kind"] == "sun")
    toward = -np.asarray(sun_light["direction"], np.float64) / np.linalg.norm(sun_light["direction"])
    lux = np.asarray(sun_light["color"], np.float64) * sun_light["intensity"]
    y = np.array([0.2126, 0.7152, 0.0722])
    b0_half = b0.astype(np.float16).astype(np.float64)
    t = (np.rint(255.0 * direction) - 128.0) / 127.0
    length = np.linalg.norm(t, axis=-1)
    cos = np.where(length > 0, (t @ toward) / np.maximum(length, 1e-30), 0.0)
    lum = (b0_half @ y) * (1 + 2 * np.minimum(length, 1.0)) + np.rint(255.0 * sun) / 255.0 * (lux @ y) * np.maximum(cos, 0.0) / np.pi
    expected = np.exp(np.mean(np.log(1e-4 + 0.5 * lum[lum > 0])))
    assert manifest["lightmap"]["log_average"] == pytest.approx(expected, rel=1e-4), (manifest["lightmap"]["log_average"], expected)


def test_mono_sh_is_the_luminance_direction_over_twice_b0():
    # shading::sh::MonoSh::from_rgb in numpy: t = b1_Y / (2 b0_Y), clamped to |t| <= 1, as
    # bytes 128 + 127 t; b0 passes through, the sun's visibility becomes the direction's alpha
    # byte (255 v) and the page's alpha is 1.
    page = np.zeros((1, 3, 13), np.float32)
    page[0, :, 0:3] = [2.0, 2.0, 2.0]
    page[0, 0, 3:12] = [0.0, 1.0, 0.0] * 3  # b1 = (0, 1, 0) per channel: t = (0, 0.25, 0)
    page[0, 1, 3:12] = [0.0, 0.0, -8.0] * 3  # noisy: |t| = 2 -> clamped to (0, 0, -1)
    page[0, 2, 3:12] = [4.0, 0, 0, 0, 0, 0, 0, 0, 0]  # red only: t_x = 0.2126 * 4 / 4
    page[0, :, 12] = [1.0, 0.5, 0.0]
    rgba, direction = bake.mono_sh(page)
    np.testing.assert_array_equal(rgba[0, :, :3], page[0, :, :3])
    np.testing.assert_array_equal(rgba[0, :, 3], [1.0, 1.0, 1.0])
    np.testing.assert_array_equal(direction[0, 0], [128, 160, 128, 255])
    np.testing.assert_array_equal(direction[0, 1], [128, 128, 1, 128])
    np.testing.assert_array_equal(direction[0, 2], [128 + np.rint(127 * 0.2126), 128, 128, 0])
