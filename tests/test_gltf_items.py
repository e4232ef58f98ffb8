"""glTF scenes cooked as levels, feature by feature (README, "glTF scenes are levels"): what is
static, one lightmap region per placement, KHR_lights_punctual, KHR_texture_transform and
texCoord in the baker, samplers in the mip stage, emissive textures, alpha cut-outs, double-sided
surfaces, cameras, refused extensions, and the runtime reading what the cooker writes.

Light is checked against closed forms where physics gives one (a sun, a spot, a windowed point
light, an emitting polygon over a plane, a square over a sky-lit plane), and against the same
scene without the feature where it does not. Bakes are raw (no denoiser, no stitching: see
lightmap_samples.RAW) and small. Each test says in its docstring why it fails without the
feature it covers.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from asset_pipeline import _core
from asset_pipeline.bake import BakeSettings
from asset_pipeline.lightmap_post import read_exr
from asset_pipeline.pipeline import CookSettings, cook, lightmap_paths
from conftest import cook_ok, run_demo
from gltf_scenes import FLOAT, Scene, quaternion
from lightmap_samples import RAW, polygon_irradiance, surface_samples

UP = np.array([0.0, 1.0, 0.0])
DOWN = np.array([0.0, -1.0, 0.0])
# These tests read B = H/pi from the pages' EXRs and hold it to closed forms: irradiance lightmaps,
# not the default directional ones (whose RGB is b0, without the sun, and whose L1 reconstruction
# is not exact for a concentrated light; see lightmap_samples.baked).
IRRADIANCE = {"lightmap_mode": "irradiance"}


# ---- helpers ------------------------------------------------------------------------------------


def bake_scene(s: Scene, folder: Path, name: str, *, samples: int = 32, bounces: int = 2, texels_per_metre: float = 16.0,
               sky_nits: float = 0.0):
    """Write `s` as `<name>.gltf` in `folder`, cook it (no LODs, no mips; raw baker output at
    `samples` paths per texel; no sky unless asked) and read its lightmap pages back from their
    EXR files: (CookResult, pages). Irradiance lightmaps (IRRADIANCE), whose pages hold B."""
    src = s.write(folder / f"{name}.gltf")
    out = folder / f"{name}.pack"
    settings = CookSettings(bake=BakeSettings(preset="draft", samples=samples, bounces=bounces, probe_samples=16, post=RAW, **IRRADIANCE), lods=False,
                            mips=False, texels_per_metre=texels_per_metre, sky_nits=sky_nits, force=True)
    result = cook(src, out, settings)
    return result, [read_exr(p) for p in lightmap_paths(out, len(result.scene.lightmap.pages))]


def manifest(pack: Path) -> dict:
    return json.loads(_core.read_pack_manifest(pack))


def node_named(doc: dict, name: str) -> dict:
    """The pack manifest's node called `name`."""
    return next(n for n in doc["nodes"] if n["name"] == name)


def rgba(h: int, w: int, left, right) -> np.ndarray:
    """An (h, w, 4) uint8 image: columns u < 0.5 `left`, the rest `right` (RGBA 0..255)."""
    img = np.empty((h, w, 4), np.uint8)
    img[:, : w // 2] = left
    img[:, w // 2:] = right
    return img


# ---- 1. glTF scenes are levels: what is static ----------------------------------------------------


def skinned_quad(s: Scene, name: str, material: int, translation) -> int:
    """A quad mesh skinned to one joint node (identity bind): a skinned mesh node."""
    mesh = s.quad_mesh(f"{name}-mesh", (1, 1), material)
    attrs = s.doc["meshes"][mesh]["primitives"][0]["attributes"]
    attrs["JOINTS_0"] = s.accessor(np.zeros((4, 4), np.uint16), "VEC4", 5123, 34962)
    attrs["WEIGHTS_0"] = s.accessor(np.tile(np.array([1, 0, 0, 0], np.float32), (4, 1)), "VEC4", FLOAT, 34962)
    joint = s.node(f"{name}-joint", translation=translation)
    s.doc.setdefault("skins", []).append({"joints": [joint], "inverseBindMatrices": s.accessor(np.eye(4, dtype=np.float32).reshape(1, 16), "MAT4", FLOAT)})
    n = s.node(name, mesh=mesh, translation=translation)
    s.doc["nodes"][n]["skin"] = len(s.doc["skins"]) - 1
    return n


def morphed_quad(s: Scene, name: str, material: int, translation) -> int:
    """A quad whose mesh has one morph target (lifting it 0.2 m)."""
    mesh = s.quad_mesh(f"{name}-mesh", (1, 1), material)
    delta = np.tile(np.array([0, 0.2, 0], np.float32), (4, 1))
    s.doc["meshes"][mesh]["primitives"][0]["targets"] = [{"POSITION": s.accessor(delta, "VEC3", FLOAT, minmax=True)}]
    s.doc["meshes"][mesh]["weights"] = [0.0]
    return s.node(name, mesh=mesh, translation=translation)


def quad_under_animated_parent(s: Scene, name: str, parent: str, material: int, translation) -> int:
    """A quad node (not animated itself) whose parent's translation is animated."""
    child = s.node(name, mesh=s.quad_mesh(f"{name}-mesh", (1, 1), material), root=False)
    p = s.node(parent, translation=translation, children=[child])
    times = s.accessor(np.array([0, 1], np.float32), "SCALAR", FLOAT, minmax=True)
    values = s.accessor(np.array([translation, np.add(translation, [1, 0, 0])], np.float32), "VEC3", FLOAT)
    s.doc.setdefault("animations", []).append({"name": f"{parent}-slide", "samplers": [{"input": times, "output": values}],
                                               "channels": [{"sampler": 0, "target": {"node": p, "path": "translation"}}]})
    return child


def what_is_static_scene() -> Scene:
    s = Scene()
    grey = s.material("grey", color=(0.5, 0.5, 0.5, 1))
    s.node("plain", mesh=s.quad_mesh("plain-mesh", (2, 2), grey))
    skinned_quad(s, "skinned", grey, [3, 0, 0])
    morphed_quad(s, "morphed", grey, [-3, 0, 0])
    quad_under_animated_parent(s, "carried", "mover", grey, [0, 0, 3])
    door = s.node("door", mesh=s.quad_mesh("door-mesh", (1, 1), grey), translation=[0, 0, -3])
    s.doc["nodes"][door]["extras"] = {"static": False}
    return s


def test_only_the_plain_mesh_node_is_static_gets_a_region_and_bakes(tmp_path):
    """A plain mesh node, a skinned one, one whose mesh has morph targets, one under an animated
    parent and one whose extras say {"static": false}: only the plain one is static, has a
    lightmap region (in the IR and in the pack) and is baked (under the default 1000-nit sky an
    open plane's B is 1000). Fails if any of the four rules is missing (that node would be static
    with a region) or if a static glTF node were not baked."""
    s = what_is_static_scene()
    src = s.write(tmp_path / "level.gltf")
    out = tmp_path / "level.pack"
    result = cook(src, out, CookSettings(bake=BakeSettings(preset="draft", samples=16, probe_samples=16, post=RAW, **IRRADIANCE), lods=False, mips=False))
    mesh_nodes = [n for n in result.scene.nodes if n.mesh is not None]
    assert sorted(n.name for n in mesh_nodes) == ["carried", "door", "morphed", "plain", "skinned"]
    assert {n.name: n.static for n in mesh_nodes} == {"plain": True, "skinned": False, "morphed": False, "carried": False, "door": False}
    assert [n.name for n in result.scene.nodes if n.lightmap is not None] == ["plain"]
    doc = manifest(out)
    packed = {n["name"]: n for n in doc["nodes"] if n["mesh"] is not None}
    assert {k: (n["is_static"], n["lightmap"] is not None) for k, n in packed.items()} == {
        "plain": (True, True), "skinned": (False, False), "morphed": (False, False), "carried": (False, False), "door": (False, False)}
    # Baked: one page, its texture in the pack and its EXR beside it; the plain quad under the sky.
    assert len(doc["lightmap"]["pages"]) == 1 and len(doc["lightmap"]["textures"]) == 1
    assert [i["node"] for i in result.bake["instances"]] == ["plain"]
    pages = [read_exr(p) for p in lightmap_paths(out, 1)]
    _, b = surface_samples(result.scene, pages, "plain", count=1024)
    np.testing.assert_allclose(b.mean(0), 1000.0, rtol=0.01)


def test_no_bake_gives_regions_but_no_baked_pages(tmp_path, run_cook):
    """`--no-bake`: the static node still gets its lightmap region and the atlas its page, but no
    page is baked (no lightmap texture in the pack, no EXR beside it). Fails if --no-bake also
    dropped the UV stage (no region) or still baked."""
    src = what_is_static_scene().write(tmp_path / "level.gltf")
    out = tmp_path / "level.pack"
    r = run_cook(src, "-o", out, "--no-bake", "--no-lods", "-q")
    assert r.returncode == 0, r.stderr
    doc = manifest(out)
    assert len(doc["lightmap"]["pages"]) == 1 and doc["lightmap"]["textures"] == [] and doc["probes"] is None
    assert [n["name"] for n in doc["nodes"] if n["lightmap"] is not None] == ["plain"]
    assert node_named(doc, "plain")["is_static"]
    assert not lightmap_paths(out, 1)[0].exists()


def test_a_level_of_props_alone_cooks_and_bakes_its_static_props(tmp_path):
    """A level TOML with [[props]] only (no [[objects]]): it cooks and bakes; the prop placed
    with `static = true` is static with a region and baked texels, the one placed with
    `static = false` (the same glTF) is neither. Fails if a level needed
    objects, or if the props' switch did not decide."""
    s = Scene()
    s.node("slab", mesh=s.quad_mesh("slab", (2, 2), s.material("grey", color=(0.5, 0.5, 0.5, 1))))
    s.write(tmp_path / "props" / "slab.gltf")
    level = tmp_path / "props.toml"
    level.write_text("""
[level]
name = "props"
texels_per_metre = 8
sky = { color = [1, 1, 1], intensity = 1000 }

[[props]]
name = "fixed"
gltf = "props/slab.gltf"
translation = [0, 0, 0]
static = true

[[props]]
name = "loose"
gltf = "props/slab.gltf"
translation = [4, 0, 0]
static = false
""")
    out = tmp_path / "props.pack"
    result = cook(level, out, CookSettings(bake=BakeSettings(preset="draft", samples=16, probe_samples=16, post=RAW, **IRRADIANCE), lods=False, mips=False))
    assert [s.name for s in result.stages] == ["level", "uv2", "bake", "chunks", "mesh_opt", "compress", "write"]
    doc = manifest(out)
    packed = {n["name"]: n for n in doc["nodes"] if n["mesh"] is not None}
    assert {k: (n["is_static"], n["lightmap"] is not None) for k, n in packed.items()} == {"fixed/slab": (True, True), "loose/slab": (False, False)}
    assert [(i["node"], i["texels"] > 0) for i in result.bake["instances"]] == [("fixed/slab", True)]
    pages = [read_exr(p) for p in lightmap_paths(out, len(doc["lightmap"]["pages"]))]
    _, b = surface_samples(result.scene, pages, "fixed/slab", count=512)
    np.testing.assert_allclose(b.mean(0), 1000.0, rtol=0.01)


# ---- 2. one lightmap region per placement ---------------------------------------------------------


def test_each_placement_of_a_mesh_has_its_own_region_light_and_texels(tmp_path):
    """One 2 m tile mesh placed three times: under a low roof, in the open, and in the open at
    scale 2. Each placement has a region of its own (same mesh, different regions), is baked
    where it stands (the open tile sees the whole 1000-nit sky, B = 1000; the covered one a
    sliver of it), the scale-2 one gets about 4x the texels, and the report lists all three.
    Fails if placements shared one region (the covered and open tiles would read the same
    texels), if texels ignored the world scale, or if the report left instances out."""
    s = Scene()
    white = s.material("white", color=(0.8, 0.8, 0.8, 1))
    tile = s.quad_mesh("tile", (2, 2), white)
    s.node("covered", mesh=tile)
    s.node("open", mesh=tile, translation=[10, 0, 0])
    s.node("big", mesh=tile, translation=[-10, 0, 0], scale=[2, 2, 2])
    # A 5 x 5 m roof 0.3 m above the covered tile, facing up (its back face, black, is above the tile).
    s.node("roof", mesh=s.quad_mesh("roof", (5, 5), white), translation=[0, 0.3, 0])
    result, pages = bake_scene(s, tmp_path, "tiles", samples=64, sky_nits=1000.0)
    scene = result.scene
    nodes = {n.name: n for n in scene.nodes}
    assert nodes["covered"].mesh == nodes["open"].mesh == nodes["big"].mesh
    regions = [nodes[k].lightmap for k in ("covered", "open", "big")]
    assert len({(r["page"], *r["offset"]) for r in regions}) == 3, regions
    np.testing.assert_allclose(np.divide(regions[2]["scale"], regions[0]["scale"]), 2.0, rtol=1e-6)
    doc = manifest(tmp_path / "tiles.pack")
    assert [m["name"] for m in doc["meshes"]].count("tile") == 1
    assert len({json.dumps(node_named(doc, k)["lightmap"]) for k in ("covered", "open", "big")}) == 3

    _, covered = surface_samples(scene, pages, "covered", count=1024)
    _, open_ = surface_samples(scene, pages, "open", count=1024)
    assert abs(open_.mean() / 1000.0 - 1) < 0.01, open_.mean(0)
    assert covered.mean() < 0.25 * open_.mean(), (covered.mean(0), open_.mean(0))

    texels = {i["name"]: i["texels"] for i in result.uv2["instances"]}
    assert 3.6 < texels["big"] / texels["open"] < 4.4 and texels["covered"] == texels["open"], texels
    report = (tmp_path / "tiles.report.md").read_text()
    for name in ("covered", "open", "big", "roof"):
        assert any(line.startswith(f"| {name} | ") for line in report.splitlines()), f"instance {name} not in the report"


# ---- 3. KHR_lights_punctual: closed forms over a plane ---------------------------------------------


def quaternion_from_to(a, b) -> list[float]:
    """Unit quaternion (x, y, z, w) turning unit vector `a` onto unit vector `b` (not opposite)."""
    a, b = (np.asarray(v, np.float64) / np.linalg.norm(v) for v in (a, b))
    axis = np.cross(a, b)
    if np.linalg.norm(axis) < 1e-12:
        return [0.0, 0.0, 0.0, 1.0]
    return quaternion(axis, math.degrees(math.acos(np.clip(a @ b, -1, 1))))


def lit_floor(s: Scene, size=(4, 4)) -> None:
    s.node("floor", mesh=s.quad_mesh("floor", size, s.material("floor", color=(0.8, 0.8, 0.8, 1))))


def test_khr_spot_light_follows_the_recommended_cone_falloff(tmp_path):
    """A spot light (cones 0.25 and 0.55 rad, 150 cd, tinted) 1.2 m above a floor, shining down
    along its node's -Z: B = I falloff(theta) cos / r^2 / pi with glTF's recommended falloff
    clamp((cos theta - cos outer) / (cos inner - cos outer), 0, 1)^2, within 1% over the lit
    area and over the ramp between the cones, 3% per point, and exactly 0 outside the outer cone (no sky, nothing to bounce
    off). Fails with no cone (a point light: the outside would be lit), with another falloff
    shape (linear, smoothstep, hard edge: off by far more than 1% between the cones) or with the
    direction taken from another axis."""
    pos, intensity, tint = np.array([0.2, 1.2, -0.1]), 150.0, np.array([1.0, 0.9, 0.7])
    inner, outer = 0.25, 0.55
    s = Scene()
    lit_floor(s)
    s.light("spot", "spot", intensity=intensity, color=tuple(tint), node={"translation": pos.tolist(), "rotation": quaternion_from_to([0, 0, -1], DOWN)},
            spot={"innerConeAngle": inner, "outerConeAngle": outer})
    result, pages = bake_scene(s, tmp_path, "spot", samples=4, bounces=1, texels_per_metre=32.0)
    (light,) = result.scene.lights
    assert light.kind == "spot" and np.allclose(light.direction, DOWN, atol=1e-6) and (light.inner_cone, light.outer_cone) == pytest.approx((inner, outer))
    p, b = surface_samples(result.scene, pages, "floor", count=8192)
    d = p - pos
    r = np.linalg.norm(d, axis=1)
    cos_axis = (d / r[:, None]) @ DOWN
    falloff = np.clip((cos_axis - math.cos(outer)) / (math.cos(inner) - math.cos(outer)), 0, 1) ** 2
    want = (intensity * falloff * (-d[:, 1] / r) / r ** 2 / math.pi)[:, None] * tint
    for name, region in (("the lit area", falloff > 0), ("between the cones", (falloff > 0.2) & (falloff < 1))):
        ratio = b[region].sum(0) / want[region].sum(0)
        np.testing.assert_allclose(ratio, 1.0, atol=0.01, err_msg=f"baked / analytic B over {name}: {ratio}")
    # Per point, where the falloff is at least 0.2: bilinear filtering between texel centres
    # across the kink at the inner cone is all the difference (a spot's light sample is exact).
    bright = falloff >= 0.2
    per_point = b[bright, 0] / want[bright, 0]
    assert np.abs(per_point - 1).max() < 0.03, np.abs(per_point - 1).max()
    # Outside the outer cone by more than two texels (what bilinear filtering reaches): dark.
    footprint = pos[1] * math.tan(outer)
    outside = np.linalg.norm((p - pos)[:, [0, 2]], axis=1) > footprint + 2.5 / 32
    assert outside.sum() > 1000 and b[outside].max() == 0.0, b[outside].max()


def test_khr_directional_light_in_lux_gives_e_cos_over_pi(tmp_path):
    """A directional light of 2000 lux travelling along (0.3, -1, 0.2) (its node's -Z) over a
    floor, no sky: B = E cos(incidence) / pi everywhere, within 0.5% per point (the sun's tiny
    disk is the only spread). Fails if the intensity were taken as anything but lux at normal
    incidence, if the cosine were missing, or the direction came from another axis."""
    travel = np.array([0.3, -1.0, 0.2]) / np.linalg.norm([0.3, -1.0, 0.2])
    s = Scene()
    lit_floor(s)
    s.light("sun", "directional", intensity=2000.0, color=(1.0, 0.95, 0.9), node={"rotation": quaternion_from_to([0, 0, -1], travel)})
    result, pages = bake_scene(s, tmp_path, "sun", samples=8, bounces=1)
    (light,) = result.scene.lights
    assert light.kind == "sun" and np.allclose(light.direction, travel, atol=1e-6)
    _, b = surface_samples(result.scene, pages, "floor", count=4096)
    want = 2000.0 * -travel[1] / math.pi * np.array([1.0, 0.95, 0.9])
    np.testing.assert_allclose(b, np.broadcast_to(want, b.shape), rtol=0.005)


def test_khr_point_light_range_windows_its_falloff(tmp_path):
    """A 80 cd point light 1 m above a floor with `range` 2 m: B = I cos / r^2 window(r) / pi
    with glTF's recommended window clamp(1 - (r / range)^4, 0, 1)^2, within 1% over the lit
    area and 2% per point, and exactly 0 beyond the range. Fails if range were ignored (at
    r = 1.5 m the window is 0.47; beyond 2 m the floor would be lit) or windowed otherwise."""
    pos, intensity, reach = np.array([0.0, 1.0, 0.0]), 80.0, 2.0
    s = Scene()
    lit_floor(s)
    s.light("bulb", "point", intensity=intensity, node={"translation": pos.tolist()}, range=reach)
    result, pages = bake_scene(s, tmp_path, "range", samples=8, bounces=1)
    assert result.scene.lights[0].range == pytest.approx(reach)
    p, b = surface_samples(result.scene, pages, "floor", count=8192)
    d = pos - p
    r = np.linalg.norm(d, axis=1)
    window = np.clip(1 - (r / reach) ** 4, 0, 1) ** 2
    want = intensity * (d[:, 1] / r) / r ** 2 * window / math.pi
    lit = window > 0
    ratio = b[lit, 0].sum() / want[lit].sum()
    assert abs(ratio - 1) < 0.01, ratio
    bright = want > 0.1 * want.max()
    assert np.abs(b[bright, 0] / want[bright] - 1).max() < 0.02
    beyond = r > reach + 2.5 / 16
    assert beyond.sum() > 1000 and b[beyond].max() == 0.0, b[beyond].max()


# ---- 4. KHR_texture_transform and texCoord in the baker -------------------------------------------

# Sensors: small white quads facing down 0.25 m above a floor, at these offsets from its centre.
SENSORS = {"west": (-1.0, 0.0), "east": (1.0, 0.0), "north": (0.0, -1.0), "south": (0.0, 1.0)}


def sensor_colour(scene, pages, name: str) -> np.ndarray:
    """Mean B (RGB) over a sensor: the light its floor sends up, in the floor's colour there."""
    return surface_samples(scene, pages, name, count=512)[1].mean(0)


def test_base_colour_transform_and_texcoord_move_the_red_bounce(tmp_path):
    """Six 4 m floors under the sky, each with a texture red for u < 0.5 and white beyond, read
    through a different slot setup; white sensors 0.25 m above each floor show the colour of
    the floor beneath them (B of a downward face is the floor's bounce). The floor's uv0 runs
    u = 0 at x = -2 to 1 at x = 2, v likewise along z; its TEXCOORD_1 is (1 - u, v).

    - identity: red under the west sensor (u = 0.25), white under the east one (u = 0.75);
    - offset (0.5, 0): u' = u + 0.5 puts red under the east sensor;
    - rotation pi/2: u' = v (KHR_texture_transform's T R S with R = [[c, s], [-s, c]], as the
      corrected spec, three.js, Babylon and the TextureTransformTest sample have it,
      KhronosGroup/glTF#1563): red under the north sensor (z < 0), white under the south one;
      with the opposite sign (the spec's literal GLSL) u' = -v would put red south;
    - texCoord 1: the mirrored set puts red east;
    - texCoord 0 overridden by the extension's own texCoord 1: red east;
    - texCoord 1 with offset (0.5, 0): the offset applies to the set chosen, red back west.

    Fails if the baker ignored the transform or the texCoord (those floors would be red where
    the identity one is), applied rotation the other way, or applied the transform to the wrong
    set."""
    half_red = rgba(8, 64, (255, 0, 0, 255), (255, 255, 255, 255))
    transform = lambda **t: {"extensions": {"KHR_texture_transform": t}}  # noqa: E731
    cases = {
        "identity": ({}, ("west", "east")),
        "offset": (transform(offset=[0.5, 0.0]), ("east", "west")),
        "rotation": (transform(rotation=math.pi / 2), ("north", "south")),
        "texcoord1": ({"texCoord": 1}, ("east", "west")),
        "override": ({"texCoord": 0, **transform(texCoord=1)}, ("east", "west")),
        "texcoord1_offset": ({"texCoord": 1, **transform(offset=[0.5, 0.0])}, ("west", "east")),
    }
    s = Scene()
    texture = s.image_texture("half-red", half_red)
    white = s.material("sensor", color=(0.8, 0.8, 0.8, 1))
    sensor = s.quad_mesh("sensor", (0.5, 0.5), white, facing_down=True)
    for k, (case, (slot, _)) in enumerate(cases.items()):
        x0 = 12.0 * k
        floor = s.quad_mesh(f"{case}-floor", (4, 4), s.material(case, texture=texture, base_uv=slot), uv1=True)
        s.node(f"{case}-floor", mesh=floor, translation=[x0, 0, 0])
        for where, (dx, dz) in SENSORS.items():
            s.node(f"{case}-{where}", mesh=sensor, translation=[x0 + dx, 0.25, dz])
    result, pages = bake_scene(s, tmp_path, "transforms", samples=64, bounces=1, texels_per_metre=8.0, sky_nits=1000.0)
    uvs = {m.name: m.uv("base_color") for m in result.scene.materials}
    assert uvs["override"]["tex_coord"] == 1 and uvs["rotation"]["rotation"] == pytest.approx(math.pi / 2)
    seen = {}
    for case, (_, (red, white)) in cases.items():
        r, w = sensor_colour(result.scene, pages, f"{case}-{red}"), sensor_colour(result.scene, pages, f"{case}-{white}")
        seen[case] = (red, (r[1] / r[0]).round(3), white, (w[1] / w[0]).round(3))
        assert r[1] / r[0] < 0.2 and w[1] / w[0] > 0.9 and r[0] > 300, seen[case]


# ---- 5. samplers in the mip stage ------------------------------------------------------------------

REPEAT, CLAMP, MIRROR = 10497, 33071, 33648
WRAP_NAMES = {REPEAT: "wrap", CLAMP: "clamp", MIRROR: "mirror"}


def edge_image(axis: int) -> np.ndarray:
    """16 x 16 sRGB grey (128) with the last column (axis 1) or row (axis 0) black."""
    img = np.full((16, 16, 4), 128, np.uint8)
    img[..., 3] = 255
    img[(slice(None), 15) if axis == 1 else (15, slice(None))] = (0, 0, 0, 255)
    return img


def test_mip_levels_filter_across_edges_as_the_sampler_wraps_and_no_mipmaps_keeps_one_level(tmp_path):
    """Textures whose last column is black, sampled with wrapS repeat, clamp and mirror (wrapT
    repeat), one whose last row is black with wrapT clamp (wrapS repeat), and three whose
    minFilter reads no mipmaps (LINEAR, NEAREST) or does (LINEAR_MIPMAP_LINEAR):

    - level 1's first column: only a repeating texture reaches the black column across the
      left edge (darker than 128); clamp and mirror read grey there (exactly 128);
    - level 1's last column differs between all three modes, repeat the lightest (the black
      column is not extended past the edge);
    - every level equals cook_core's chain for the sampler's edge mode per axis (wrapT clamp
      spares the first row, as wrapS clamp spares the first column);
    - minFilter LINEAR or NEAREST: one level; LINEAR_MIPMAP_LINEAR: all five.

    Fails if the stage filtered every texture as repeating (the README's level default), mixed
    up the axes, or built mip chains for textures sampled without mipmaps."""
    s = Scene()
    cases = {
        "repeat": (edge_image(1), {"wrapS": REPEAT, "wrapT": REPEAT}),
        "clamp": (edge_image(1), {"wrapS": CLAMP, "wrapT": REPEAT}),
        "mirror": (edge_image(1), {"wrapS": MIRROR, "wrapT": REPEAT}),
        "clamp_t": (edge_image(0), {"wrapS": REPEAT, "wrapT": CLAMP}),
        "linear": (edge_image(1), {"magFilter": 9729, "minFilter": 9729}),
        "nearest": (edge_image(1), {"magFilter": 9728, "minFilter": 9728}),
        "trilinear": (edge_image(1), {"magFilter": 9729, "minFilter": 9987}),
    }
    for k, (name, (img, sampler)) in enumerate(cases.items()):
        t = s.image_texture(name, img, sampler)
        s.node(name, mesh=s.quad_mesh(name, (1, 1), s.material(name, texture=t)), translation=[2.0 * k, 0, 0])
    src = s.write(tmp_path / "samplers.gltf")
    out = tmp_path / "samplers.pack"
    result = cook(src, out, CookSettings(lods=False, baking=False, force=True, compress=False))
    index = {t.name: i for i, t in enumerate(result.scene.textures)}
    assert set(cases) <= set(index), index
    doc = manifest(out)
    levels = {}
    for name, (img, sampler) in cases.items():
        fmt, levels[name] = _core.read_pack_texture(out, index[name])
        assert fmt == "Rgba8Srgb" and (levels[name][0] == img).all(), name
    assert {n: len(levels[n]) for n in ("linear", "nearest", "trilinear", "repeat")} == {"linear": 1, "nearest": 1, "trilinear": 5, "repeat": 5}
    assert doc["textures"][index["linear"]]["sampler"]["mipmap_filter"] is None
    assert [doc["textures"][index[n]]["sampler"]["wrap_s"] for n in ("repeat", "clamp", "mirror")] == ["repeat", "clamp", "mirror"]

    first = {n: levels[n][1][:, 0, :3].astype(int) for n in ("repeat", "clamp", "mirror")}
    last = {n: levels[n][1][:, -1, :3].astype(int) for n in ("repeat", "clamp", "mirror")}
    assert (first["clamp"] == 128).all() and (first["mirror"] == 128).all() and (first["repeat"] < 126).all(), first
    assert len({last[n].tobytes() for n in last}) == 3 and (last["repeat"] > last["clamp"]).all() and (last["repeat"] > last["mirror"]).all(), last
    assert (levels["clamp_t"][1][0, :, :3] == 128).all() and not (levels["clamp_t"][1][-1, :, :3] == 128).any()
    for name in ("repeat", "clamp", "mirror", "clamp_t"):
        img, sampler = cases[name]
        edge = f"{WRAP_NAMES[sampler['wrapS']]},{WRAP_NAMES[sampler['wrapT']]}"
        want = _core.mip_chain(img, "color", edge=edge)
        assert [l.tobytes() for l in levels[name][1:]] == [np.asarray(l).tobytes() for l in want], name


# ---- 6. emissive textures -------------------------------------------------------------------------


def test_emissive_texture_black_on_one_half_lights_like_the_white_half_alone(tmp_path):
    """A 1 m quad 1 m above a floor, facing down, black itself, emitting (1, 0.8, 0.6) x
    KHR_materials_emissive_strength 250 through an emissive texture black for u < 0.5 (x < 0)
    and white beyond (clamped at the edges): the floor's B is the white half's alone, Lambert's
    polygon formula for the rectangle x in [0, 0.5] times 250 (1, 0.8, 0.6) / pi, within 1%
    over the central floor and 2% over each side of it. Fails without the emissive texture (the
    floor would get about twice the light, evenly), with it read mirrored (the sides would
    swap) or without the emissive strength (1/250 of the light)."""
    strength, tint = 250.0, np.array([1.0, 0.8, 0.6])
    s = Scene()
    lit_floor(s)
    mask = s.image_texture("half-white", rgba(8, 64, (0, 0, 0, 255), (255, 255, 255, 255)), {"wrapS": CLAMP, "wrapT": CLAMP})
    lamp = s.material("lamp", color=(0, 0, 0, 1), emissive=tuple(tint), emissive_strength=strength, emissive_texture=mask)
    s.node("lamp", mesh=s.quad_mesh("lamp", (1, 1), lamp, facing_down=True), translation=[0, 1, 0])
    result, pages = bake_scene(s, tmp_path, "emissive", samples=128, bounces=1)
    p, b = surface_samples(result.scene, pages, "floor", count=8192)
    white_half = np.array([[0, 1, -0.5], [0.5, 1, -0.5], [0.5, 1, 0.5], [0, 1, 0.5]], np.float64)
    want = polygon_irradiance(p, UP, white_half)[:, None] / math.pi * strength * tint
    central = (np.abs(p[:, 0]) < 1.5) & (np.abs(p[:, 2]) < 1.5)
    for name, region, tol in (("central floor", central, 0.01), ("x > 0.25", central & (p[:, 0] > 0.25), 0.02),
                              ("x < -0.25", central & (p[:, 0] < -0.25), 0.02)):
        ratio = b[region].sum(0) / want[region].sum(0)
        np.testing.assert_allclose(ratio, 1.0, atol=tol, err_msg=f"baked / analytic B over the {name}: {ratio}")


# ---- 7. alpha cut-outs ---------------------------------------------------------------------------


def test_alpha_mask_and_blend_let_the_sun_through_where_they_should(tmp_path):
    """Two 2 m quads 0.5 m above a floor under a 3000-lux sun straight down (no sky): one Mask
    (cutoff 0.5) whose texture's alpha is 0 for x < 0 and 1 beyond, one Blend with alpha 0.3.
    Under the mask's transparent half the floor is sunlit, B = E / pi (within 0.5% per point);
    under its opaque half it is in full shadow (B = 0: the quad's underside is a single-sided
    back face, black, and there is nothing else to bounce off); under the blended quad the
    hashed alpha test passes 70% of the light (within 2 points). Fails if the baker ignored
    alpha (both dark), used the mask the other way round, or treated Blend as Mask (alpha 0.3
    is below the cutoff: all of the light) or as Opaque (none)."""
    e = 3000.0
    s = Scene()
    s.node("floor", mesh=s.quad_mesh("floor", (8, 4), s.material("floor", color=(0.8, 0.8, 0.8, 1))))
    cutout = s.image_texture("cutout", rgba(8, 64, (255, 255, 255, 0), (255, 255, 255, 255)), {"wrapS": CLAMP, "wrapT": CLAMP})
    masked = s.material("masked", texture=cutout, alpha_mode="MASK", alpha_cutoff=0.5)
    blended = s.material("blended", color=(1, 1, 1, 0.3), alpha_mode="BLEND")
    s.node("mask", mesh=s.quad_mesh("mask", (2, 2), masked), translation=[-2, 0.5, 0])
    s.node("blend", mesh=s.quad_mesh("blend", (2, 2), blended), translation=[2, 0.5, 0])
    s.light("sun", "directional", intensity=e, node={"rotation": quaternion_from_to([0, 0, -1], DOWN)})
    result, pages = bake_scene(s, tmp_path, "alpha", samples=32, bounces=2)
    p, b = surface_samples(result.scene, pages, "floor", count=16384)
    x, z = p[:, 0], np.abs(p[:, 2])
    through = (x > -2.9) & (x < -2.1) & (z < 0.9)
    shadow = (x > -1.9) & (x < -1.1) & (z < 0.9)
    blend = (x > 1.1) & (x < 2.9) & (z < 0.9)
    open_ = (np.abs(x) < 0.9) | (np.abs(x) > 3.1)
    assert min(through.sum(), shadow.sum(), blend.sum()) > 500
    np.testing.assert_allclose(b[through | open_], e / math.pi, rtol=0.005)
    assert b[shadow].max() < 1e-3 * e / math.pi, b[shadow].max()
    passed = b[blend, 0].mean() / (e / math.pi)
    assert abs(passed - 0.7) < 0.02, passed


# ---- 8. double-sided surfaces ---------------------------------------------------------------------


def test_a_double_sided_roof_reflects_the_floors_light_back_a_single_sided_one_does_not(tmp_path):
    """A 2 m white roof 0.3 m above a white 6 m floor under the 1000-nit sky, in three versions:
    single-sided facing up, double-sided facing up, single-sided facing down. What the baker
    does (README): a single-sided surface seen from behind is opaque and black, a double-sided
    one is the same surface from both sides. So under the single-sided roof facing up the floor
    sees only the sky around the roof, B = 1000 (1 - F) with F the roof's view factor (Lambert's
    polygon formula), within 2%; the double-sided roof's underside reflects the floor's light
    back, B = that of the roof turned to face down (within 3%), and well above the single-sided
    one. Fails if double_sided were ignored (double = single) or back faces reflected (single
    would exceed its closed form)."""
    s = Scene()
    white = s.material("white", color=(0.8, 0.8, 0.8, 1))
    both = s.material("white-both-sides", color=(0.8, 0.8, 0.8, 1), double_sided=True)
    floor = s.quad_mesh("floor", (6, 6), white)
    roofs = {"single_up": s.quad_mesh("single_up", (2, 2), white), "double_up": s.quad_mesh("double_up", (2, 2), both),
             "single_down": s.quad_mesh("single_down", (2, 2), white, facing_down=True)}
    for k, (name, mesh) in enumerate(roofs.items()):
        s.node(f"{name}-floor", mesh=floor, translation=[12.0 * k, 0, 0])
        s.node(name, mesh=mesh, translation=[12.0 * k, 0.3, 0])
    result, pages = bake_scene(s, tmp_path, "sides", samples=128, bounces=3, sky_nits=1000.0)
    under = {}
    for k, name in enumerate(roofs):
        p, b = surface_samples(result.scene, pages, f"{name}-floor", count=8192)
        local = p - [12.0 * k, 0, 0]
        sel = (np.abs(local[:, 0]) < 0.8) & (np.abs(local[:, 2]) < 0.8)
        under[name] = (local[sel], b[sel, 0])
    roof = np.array([[-1, 0.3, -1], [1, 0.3, -1], [1, 0.3, 1], [-1, 0.3, 1]], np.float64)
    pts, b_single = under["single_up"]
    want = 1000.0 * (1 - polygon_irradiance(pts, UP, roof) / math.pi)
    assert abs(b_single.sum() / want.sum() - 1) < 0.02, b_single.sum() / want.sum()
    means = {k: float(v[1].mean()) for k, v in under.items()}
    assert abs(means["double_up"] / means["single_down"] - 1) < 0.03, means
    assert means["double_up"] > 1.3 * means["single_up"], means


# ---- 9. cameras -----------------------------------------------------------------------------------


def render(pack: Path, png: Path, size: int = 64) -> np.ndarray:
    """The demo's first frame of `pack` from where the pack says the view starts (headless,
    validation on): the screenshot as (h, w, 3) uint8. Requires exit 0 and no validation error."""
    r = run_demo([pack, "--headless", "--flight", "0", "--frames", "1", "--width", size, "--height", size, "--render-scale", "1", "--screenshot", png, "--validation"])
    assert r.returncode == 0, f"demo failed ({r.returncode}):\n{r.stdout}\n{r.stderr}"
    assert "validation errors: 0" in r.stdout, r.stdout
    assert "[vulkan validation error]" not in r.stderr, r.stderr
    return np.asarray(Image.open(png).convert("RGB"))


QUICK_CLI = ("--quality", "draft", "--samples", "4", "--probe-samples", "16", "--texels-per-metre", "2", "-q")


def test_first_camera_is_a_camera_spawn_and_the_demo_starts_there(tmp_path):
    """A glTF camera (yfov 0.6, znear 0.05) at (0, 1.5, 4) turned 30 degrees about +Y, with a red
    quad 3 m along its view; a green ground and a blue box elsewhere, so that the demo's
    fallback view (framing the scene's bounds) looks at green. The pack gets one `camera`
    spawn at the node's position and rotation with yfov and znear; a second camera is not
    imported; the demo's first frame has the red quad in its centre. Fails if cameras were not
    imported (the centre is green ground: the fallback view), or the spawn's rotation or
    position were ignored (the quad would be off-centre or out of view)."""
    eye, yaw = np.array([0.0, 1.5, 4.0]), 30.0
    forward = np.array([-math.sin(math.radians(yaw)), 0.0, -math.cos(math.radians(yaw))])
    s = Scene()
    s.node("ground", mesh=s.quad_mesh("ground", (30, 30), s.material("green", color=(0.1, 0.6, 0.1, 1))))
    s.node("far", mesh=s.box_mesh("far", (3, 3, 3), s.material("blue", color=(0.1, 0.1, 0.8, 1))), translation=[12, 1.5, -12])
    s.node("target", mesh=s.quad_mesh("target", (1, 1), s.material("red", color=(0.9, 0.05, 0.05, 1))),
           translation=(eye + 3 * forward).tolist(), rotation=quaternion_from_to(UP, -forward))
    s.camera("eye", yfov=0.6, znear=0.05, translation=eye.tolist(), rotation=quaternion([0, 1, 0], yaw))
    s.camera("second", yfov=1.0, translation=[10, 10, 10])
    src = s.write(tmp_path / "camera.gltf")
    out = tmp_path / "camera.pack"
    cook_ok(src, out, *QUICK_CLI)
    (spawn,) = manifest(out)["spawns"]
    assert spawn["kind"] == "camera" and spawn["name"] == "eye"
    np.testing.assert_allclose(spawn["position"], eye, atol=1e-6)
    np.testing.assert_allclose(spawn["rotation"], quaternion([0, 1, 0], yaw), atol=1e-6)
    assert spawn["params"] == pytest.approx({"yfov": 0.6, "znear": 0.05})
    img = render(out, tmp_path / "camera.png").astype(int)
    centre = img[28:36, 28:36].reshape(-1, 3).mean(0)
    assert centre[0] > 60 and centre[0] > 2 * centre[1] and centre[0] > 2 * centre[2], centre


# ---- 10. extensions refused by name -----------------------------------------------------------------


def test_a_required_unsupported_extension_is_refused_by_name_a_supported_one_cooks(tmp_path, run_cook):
    """extensionsRequired ["KHR_draco_mesh_compression"]: exit 2, one line naming it, nothing
    written; extensionsRequired ["KHR_texture_transform"] (implemented): the file cooks. Fails
    if unknown required extensions were read anyway (or refused without their name), or if a
    supported one were refused."""
    s = Scene()
    s.node("floor", mesh=s.quad_mesh("floor", (1, 1), s.material("grey")))
    s.extension("KHR_draco_mesh_compression", required=True)
    src = s.write(tmp_path / "draco.gltf")
    r = run_cook(src, "-o", tmp_path / "draco.pack", "--no-bake", "-q")
    assert r.returncode == 2, (r.returncode, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "KHR_draco_mesh_compression" in lines[0] and "draco.gltf" in lines[0], r.stderr
    assert not (tmp_path / "draco.pack").exists()

    s = Scene()
    texture = s.image_texture("checker", rgba(4, 4, (255, 0, 0, 255), (255, 255, 255, 255)))
    material = s.material("moved", texture=texture, base_uv={"extensions": {"KHR_texture_transform": {"offset": [0.5, 0.0]}}})
    s.node("floor", mesh=s.quad_mesh("floor", (1, 1), material))
    s.extension("KHR_texture_transform", required=True)
    src = s.write(tmp_path / "transform.gltf")
    r = run_cook(src, "-o", tmp_path / "transform.pack", "--no-bake", "-q")
    assert r.returncode == 0, r.stderr
    (mat,) = manifest(tmp_path / "transform.pack")["materials"]
    assert mat["base_color_uv"]["offset"] == [0.5, 0.0]


# ---- 11. the runtime reads what the cooker writes -----------------------------------------------------


def test_a_baked_scene_with_lights_textures_and_emission_renders_with_validation(tmp_path):
    """Smoke test: a room-ish scene with a KHR sun, point and spot light, a floor with a
    transformed base colour texture read through TEXCOORD_1, a clamped emissive texture with
    KHR_materials_emissive_strength, a dynamic crate (lit by the probes), cooked with every stage (LODs, bake, mips) and rendered by
    the demo with the validation layer: exit 0, no validation error, a lit frame (not black).
    Fails if the runtime could not read any of it (a pack error exits 2) or used it wrongly
    enough to upset the validation layer (exit 3)."""
    s = Scene()
    squares = (np.indices((32, 32)) // 8).sum(0) % 2  # a 4 x 4 checker of 8-texel squares
    checker = s.image_texture("checker", np.where(squares[..., None], (255, 255, 255, 255), (60, 60, 60, 255)).astype(np.uint8))
    moved = {"offset": [0.25, 0.0], "rotation": 0.3, "scale": [2, 2]}
    floor_mat = s.material("floor", texture=checker, base_uv={"texCoord": 1, "extensions": {"KHR_texture_transform": moved}})
    s.node("floor", mesh=s.quad_mesh("floor", (8, 8), floor_mat, uv1=True))
    s.node("wall", mesh=s.box_mesh("wall", (8, 3, 0.2), s.material("wall", color=(0.7, 0.6, 0.5, 1))), translation=[0, 1.5, -4])
    glow = s.image_texture("glow", rgba(8, 8, (255, 128, 0, 255), (0, 0, 0, 255)), {"wrapS": CLAMP, "wrapT": CLAMP})
    lamp = s.material("lamp", color=(0, 0, 0, 1), emissive=(1, 1, 1), emissive_strength=2000.0, emissive_texture=glow)
    s.node("lamp", mesh=s.quad_mesh("lamp", (1, 1), lamp, facing_down=True), translation=[1, 2.5, 0])
    crate = s.node("crate", mesh=s.box_mesh("crate", (0.8, 0.8, 0.8), s.material("crate", color=(0.2, 0.4, 0.8, 1))), translation=[-1, 0.4, 1])
    s.doc["nodes"][crate]["extras"] = {"static": False}  # lit by the probes at run time
    s.light("sun", "directional", intensity=5000.0, node={"rotation": quaternion_from_to([0, 0, -1], [0.3, -1, -0.4])})
    s.light("bulb", "point", intensity=200.0, color=(1, 0.8, 0.6), node={"translation": [-2, 2, 1]}, range=6.0)
    s.light("spot", "spot", intensity=400.0, node={"translation": [2, 3, 2], "rotation": quaternion_from_to([0, 0, -1], DOWN)},
            spot={"innerConeAngle": 0.3, "outerConeAngle": 0.6})
    s.camera("view", yfov=1.0, translation=[0, 2, 6], rotation=quaternion([1, 0, 0], -15))
    src = s.write(tmp_path / "room.gltf")
    out = tmp_path / "room.pack"
    cook_ok(src, out, "--quality", "draft", "--samples", "8", "--probe-samples", "16", "--texels-per-metre", "4", "-q")
    doc = manifest(out)
    assert len(doc["lights"]) == 3 and len(doc["lightmap"]["textures"]) == len(doc["lightmap"]["pages"]) >= 1
    assert doc["probes"] is not None and any(len(t["mips"]) > 1 for t in doc["textures"])
    assert not node_named(doc, "crate")["is_static"] and node_named(doc, "floor")["lightmap"] is not None
    img = render(out, tmp_path / "room.png")
    assert img.mean() > 20 and img.std() > 5, (img.mean(), img.std())
