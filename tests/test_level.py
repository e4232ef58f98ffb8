"""Levels authored as CSG: spec validation (level.py) and brushes -> closed meshes (csg.py)."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from asset_pipeline import CookError, _core, ir
from asset_pipeline.csg import build_level
from asset_pipeline.level import load_level
from asset_pipeline.vertex_format import uv_precision_warnings
from conftest import COOK

REPO = Path(__file__).resolve().parent.parent
TEMPLE = REPO / "content" / "levels" / "temple.toml"

HEADER = """
[[materials]]
name = "stone"
uv_scale = 2.0

[[materials]]
name = "plaster"
uv_scale = 0.5
"""


# One box brush "b" made into object "o": the smallest valid geometry, for tests about other parts.
ONE_BOX = """
[[brushes]]
name = "b"
kind = "box"
size = [1, 1, 1]
material = "stone"

[[objects]]
name = "o"
op = "union"
operands = ["b"]
"""


def write(tmp_path: Path, body: str, name: str = "level.toml") -> Path:
    p = tmp_path / name
    p.write_text(textwrap.dedent(body))
    return p


def build(tmp_path: Path, body: str) -> ir.Scene:
    return build_level(load_level(write(tmp_path, HEADER + textwrap.dedent(body))))


def check_closed(lod: ir.Lod, what: str) -> float:
    """Weld by position; require a closed, consistently and outwardly oriented surface. Returns the volume."""
    pos = lod.attributes["position"]
    _, weld = np.unique(pos, axis=0, return_inverse=True)
    t = weld.reshape(-1)[lod.triangles]
    assert (t[:, 0] != t[:, 1]).all() and (t[:, 1] != t[:, 2]).all() and (t[:, 2] != t[:, 0]).all(), f"{what}: degenerate triangle"
    directed = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    _, n_undirected = np.unique(np.sort(directed, axis=1), axis=0, return_counts=True)
    assert (n_undirected == 2).all(), f"{what}: {(n_undirected != 2).sum()} edges not shared by exactly two triangles"
    _, n_directed = np.unique(directed, axis=0, return_counts=True)
    assert (n_directed == 1).all(), f"{what}: {(n_directed != 1).sum()} directed edges repeated (inconsistent orientation)"
    p = pos.astype(np.float64)[lod.triangles]
    volume = float(np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum() / 6)
    assert volume > 0, f"{what}: volume {volume} (inside out)"
    return volume


def check_shading(lod: ir.Lod, what: str) -> None:
    a = lod.attributes
    n, t = a["normal"].astype(np.float64), a["tangent"].astype(np.float64)
    assert np.allclose(np.linalg.norm(n, axis=1), 1, atol=1e-5), f"{what}: normals not unit length"
    assert np.allclose(np.linalg.norm(t[:, :3], axis=1), 1, atol=1e-5), f"{what}: tangents not unit length"
    assert np.isin(t[:, 3], (-1.0, 1.0)).all(), f"{what}: tangent w is not a handedness sign"
    assert np.abs(np.sum(n * t[:, :3], axis=1)).max() < 1e-4, f"{what}: tangent not perpendicular to normal"
    assert (a["color"] == 255).all()
    # every corner's normal faces the same way as its triangle
    p = a["position"].astype(np.float64)[lod.triangles]
    fn = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    assert (np.einsum("ij,ikj->ik", fn, n[lod.triangles]) > 0).all(), f"{what}: a vertex normal faces away from its triangle"
    # tangents follow uv0: dP/du of each triangle, from its positions and uvs
    uv = a["uv0"].astype(np.float64)[lod.triangles]
    e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    d1, d2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    det = d1[:, 0] * d2[:, 1] - d2[:, 0] * d1[:, 1]
    ok = np.abs(det) > 1e-9
    dpdu = (e1 * d2[:, 1:2] - e2 * d1[:, 1:2])[ok] / det[ok, None]
    dpdv = (e2 * d1[:, 0:1] - e1 * d2[:, 0:1])[ok] / det[ok, None]
    dpdu /= np.linalg.norm(dpdu, axis=1, keepdims=True)
    tri_t = t[lod.triangles][ok]
    agree = np.einsum("ij,ikj->ik", dpdu, tri_t[:, :, :3])
    flat = np.einsum("ij,ikj->ik", fn[ok] / np.linalg.norm(fn[ok], axis=1, keepdims=True), n[lod.triangles][ok]) > 1 - 1e-6
    assert (agree[flat] > 0.999).all(), f"{what}: tangent is not dP/du on a flat face"
    assert (agree > 0.5).all(), f"{what}: tangent does not follow dP/du"  # smooth corners turn with their normal
    # glTF handedness: bitangent = cross(N, T) * w points towards decreasing v
    bit = np.cross(n[lod.triangles][ok], tri_t[:, :, :3]) * tri_t[:, :, 3:]
    assert (np.einsum("ij,ikj->ik", -dpdv, bit) > 0).all(), f"{what}: tangent handedness disagrees with uv0"


# ---- the demo level -----------------------------------------------------------------------


@pytest.fixture(scope="module")
def temple() -> ir.Scene:
    return build_level(load_level(TEMPLE))


def test_temple_meshes_are_closed_and_outward(temple):
    assert {m.name for m in temple.meshes} >= {"ground", "temple", "courtyard", "fountain"}
    # The two glass lanterns' parts (dynamic props), the character spawns' golems, each skinned
    # by its own skin, and the flock's bird (drawn by the boids pass, no node) are the only
    # dynamic meshes.
    static = set(temple.static_meshes())
    lantern = ["post", "cap", "flame", "glass"]
    assert [m.name for i, m in enumerate(temple.meshes) if i not in static] == lantern + lantern + ["golem", "golem", "dove"]
    assert sum(m.alpha_mode == "Blend" for m in temple.materials) == 2  # the glass of each lantern
    doves = next(s for s in temple.spawns if s.kind == "boids")
    assert temple.meshes[doves.params["mesh"]].name == "dove"
    assert [s.name for s in temple.skins] == ["priest/golem", "pilgrim/golem"]
    for m in (temple.meshes[i] for i in static):
        check_closed(m.base, m.name)
        check_shading(m.base, m.name)
        assert m.texels_per_metre is None
    assert temple.lightmap.texels_per_metre == 5 and temple.lightmap.pages == []


def test_temple_contents(temple):
    temple.validate()
    ir.from_wire(*ir.to_wire(temple))  # the Rust crossing accepts it
    assert {l.kind for l in temple.lights} == {"sun", "point", "spot", "rect"}
    assert {s.kind for s in temple.spawns} == {"player", "character", "boids", "particles"}
    assert temple.sky is not None and temple.sky.intensity > 0
    assert any(max(m.emissive) > 0 for m in temple.materials)
    assert all(t.mips[0].shape == (t.height, t.width, 4) for t in temple.textures)
    # Base colours are sRGB; the bricks, flagstones and planks also have a normal map and an
    # occlusion-roughness map (one texture, the glTF ORM layout), the checker marble none.
    mats = {m.name: m for m in temple.materials}
    for name in ("paving", "sandstone", "red_brick", "timber"):
        m = mats[name]
        assert temple.textures[m.base_color_texture].format == "Rgba8Srgb", name
        assert (temple.textures[m.normal_texture].format, temple.textures[m.normal_texture].usage) == ("Rgba8Unorm", "normal"), name
        assert m.metallic_roughness_texture == m.occlusion_texture and temple.textures[m.occlusion_texture].usage == "data", name
    assert mats["marble_floor"].normal_texture is None and mats["marble_floor"].metallic_roughness_texture is None
    # The two golems (one asset spawned twice) share their stone's three textures.
    t = temple.textures
    assert not [(i, j) for i in range(len(t)) for j in range(i) if t[i].same_as(t[j])]
    assert sum(x.name.startswith("golem stone") for x in t) == 3
    assert 1_000 < sum(temple.meshes[i].base.triangle_count for i in temple.static_meshes()) < 50_000
    # every level mesh sits at the world origin: positions are world space (characters are placed
    # by their spawn's root node)
    assert all(n.local == ir.Node(n.name).local for n in temple.nodes if n.mesh is not None and n.static)
    # the hall is open to the sky: straight down through the oculus the first surface is the floor
    lod = temple.meshes[[m.name for m in temple.meshes].index("temple")].base
    p = lod.attributes["position"].astype(np.float64)[lod.triangles]
    a, b, c = (p[:, k][:, [0, 2]] - [0.0, -8.0] for k in range(3))
    cross = lambda u, v: u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]
    s = np.sign(np.stack([cross(a, b), cross(b, c), cross(c, a)], axis=1))
    over = ((s >= 0).all(axis=1) | (s <= 0).all(axis=1)) & (np.abs(s).sum(axis=1) > 0)
    assert over.any() and p[over][:, :, 1].max() <= 0.6 + 1e-5


def test_temple_pillars_are_its_columns_braziers_and_fountain(temple):
    # 6 portico and 2 x 4 hall columns, the 2 braziers, the fountain's basin and column. Not the
    # arches and the oculus (cutters, and the arches lie on their side), nor the water in the
    # basin and the coals in the braziers (each inside a larger pillar).
    names = [p.name for p in temple.pillars]
    assert len(names) == 18, names
    assert names == [f"portico_columns[{k}]" for k in range(6)] + [f"hall_columns_west[{k}]" for k in range(4)] \
        + [f"hall_columns_east[{k}]" for k in range(4)] + ["brazier_outer[0]", "brazier_outer[1]", "basin_outer", "fountain_column"]
    col = temple.pillars[2]  # portico_columns copy 2: translation [-10, 3.9, 3.6] + 2 * [4, 0, 0]
    assert col.centre == pytest.approx((-2.0, 3.6)) and col.radius == pytest.approx(0.45)
    assert (col.y_min, col.y_max) == pytest.approx((0.5, 7.3))
    assert temple.pillars[14].radius == pytest.approx(0.6)  # a tapered brazier: its larger radius
    back = ir.from_wire(*ir.to_wire(temple))
    assert back.pillars == temple.pillars


def test_cooked_pack_carries_the_pillars(run_cook, tmp_path):
    import json

    from asset_pipeline import _core

    path = write(tmp_path, HEADER + textwrap.dedent(ONE_BOX.replace('operands = ["b"]', 'operands = ["b", "col"]')) + textwrap.dedent("""
        [[brushes]]
        name = "col"
        kind = "cylinder"
        radius = 0.25
        height = 3
        translation = [0, 1.5, 0]
        material = "stone"
        repeat = { count = 2, step = [0, 0, 2] }
    """))
    out = tmp_path / "level.pack"
    r = run_cook(path, "-o", out, "-q", "--no-bake", "--no-lightmap-uvs", "--no-lods", "--no-report")
    assert r.returncode == 0, r.stderr
    pillars = json.loads(_core.read_pack_manifest(out))["pillars"]
    assert [p["name"] for p in pillars] == ["col[0]", "col[1]"]
    assert pillars[1]["centre"] == pytest.approx([0.0, 2.0]) and pillars[1]["radius"] == pytest.approx(0.25)
    assert (pillars[1]["y_min"], pillars[1]["y_max"]) == pytest.approx((0.0, 3.0))


def test_pillars_follow_scale_and_skip_tilted_and_cut_cylinders(tmp_path):
    scene = build(tmp_path, """
        [[brushes]]
        name = "floor"
        kind = "box"
        size = [20, 1, 20]
        material = "stone"

        [[brushes]]
        name = "fat"                 # scaled: radius 0.5 * 2, height 2 * 1.5, turned about Y
        kind = "cylinder"
        radius = 0.5
        height = 2
        scale = [2, 1.5, 2]
        rotation = [0, 30, 0]
        translation = [3, 1, 4]
        material = "stone"

        [[brushes]]
        name = "oval"                # not round in plan: no pillar
        kind = "cylinder"
        radius = 0.5
        height = 2
        scale = [1, 1, 2]
        translation = [-3, 1, 0]
        material = "stone"

        [[brushes]]
        name = "log"                 # lying down: no pillar
        kind = "cylinder"
        radius = 0.3
        height = 4
        rotation = [0, 0, 90]
        translation = [0, 1, -4]
        material = "stone"

        [[brushes]]
        name = "well"                # cut out of the floor: no pillar
        kind = "cylinder"
        radius = 1
        height = 2
        translation = [-5, 0, -5]
        material = "plaster"

        [[objects]]
        name = "holed"
        op = "difference"
        operands = ["floor", "well"]

        [[objects]]
        name = "all"
        op = "union"
        operands = ["holed", "fat", "oval", "log"]
    """)
    assert [p.name for p in scene.pillars] == ["fat"]
    p = scene.pillars[0]
    assert p.centre == pytest.approx((3.0, 4.0)) and p.radius == pytest.approx(1.0)
    assert (p.y_min, p.y_max) == pytest.approx((-0.5, 2.5))


# ---- small specs: shapes and booleans --------------------------------------------------------


@pytest.mark.parametrize("brush", [
    'kind = "box"\nsize = [1, 2, 3]\nrotation = [10, 20, 30]',
    'kind = "cylinder"\nradius = 0.5\nheight = 2\nsegments = 24\nrotation = [90, 0, 0]',
    'kind = "cylinder"\nradius = 0.5\nradius_top = 0\nheight = 1',
    'kind = "sphere"\nradius = 1\nsegments = 16\nscale = [1, 2, 1]',
    'kind = "extrude"\npoints = [[0, 0], [0, 2], [1, 2], [1, 1], [2, 1], [2, 0]]\nheight = 0.5',  # clockwise L
    'kind = "box"\nsize = [1, 1, 1]\nrepeat = { count = 3, step = [0.5, 0, 0] }',
])
def test_each_brush_kind_is_closed(tmp_path, brush):
    scene = build(tmp_path, f"""
        [[brushes]]
        name = "b"
        material = "stone"
        translation = [3, 1, -2]
        {brush}

        [[objects]]
        name = "o"
        op = "union"
        operands = ["b"]
    """.replace("\n        ", "\n"))
    check_closed(scene.meshes[0].base, "o")
    check_shading(scene.meshes[0].base, "o")


BOX_MINUS_BOX = """
    [[brushes]]
    name = "outer"
    kind = "box"
    size = [4, 3, 4]
    material = "stone"

    [[brushes]]
    name = "hole"
    kind = "box"
    size = [2, 5, 2]
    translation = [0.5, 0, 0]
    material = "plaster"

    [[objects]]
    name = "room"
    op = "difference"
    operands = ["outer", "hole"]
"""


def test_box_minus_box_materials_follow_the_brush(tmp_path):
    """Rule: a triangle has the material of the brush whose surface it lies on, so the faces a
    cutter leaves (the hole's walls) have the cutter's material."""
    scene = build(tmp_path, BOX_MINUS_BOX)
    lod = scene.meshes[0].base
    assert check_closed(lod, "room") == pytest.approx(4 * 3 * 4 - 2 * 3 * 2)
    names = [m.name for m in scene.materials]
    p = lod.attributes["position"][lod.triangles].astype(np.float64)
    c = p.mean(axis=1)
    in_hole = (np.abs(c[:, 0] - 0.5) < 1.0 + 1e-6) & (np.abs(c[:, 2]) < 1.0 + 1e-6)
    mats = np.array(names)[lod.materials]
    assert (mats[in_hole] == "plaster").all() and in_hole.sum() == 8
    assert (mats[~in_hole] == "stone").all()


def test_normals_crisp_on_boxes_smooth_on_cylinders(tmp_path):
    scene = build(tmp_path, BOX_MINUS_BOX + """
        [[brushes]]
        name = "pillar"
        kind = "cylinder"
        radius = 0.5
        height = 3
        segments = 32
        translation = [10, 0, 0]
        material = "stone"

        [[objects]]
        name = "pillar_obj"
        op = "union"
        operands = ["pillar"]
    """)
    room, pillar = (m.base for m in scene.meshes)
    n = room.attributes["normal"]
    assert np.allclose(np.sort(np.abs(n), axis=1), [0, 0, 1], atol=1e-6), "box normals are face normals"
    n, p = pillar.attributes["normal"].astype(np.float64), pillar.attributes["position"].astype(np.float64)
    side = np.abs(n[:, 1]) < 0.5
    radial = (p[side] - [10, 0, 0]) * [1, 0, 1]
    radial /= np.linalg.norm(radial, axis=1, keepdims=True)
    assert np.einsum("ij,ij->i", n[side], radial).min() > 0.999, "cylinder side normals are radial (smooth)"
    # smooth: split vertices at one position (uv seams) still share one normal
    _, first, at = np.unique(p[side], axis=0, return_index=True, return_inverse=True)
    assert np.abs(n[side] - n[side][first][at.reshape(-1)]).max() < 1e-6


def vertex_uv_scale(lod: ir.Lod, level: Path) -> np.ndarray:
    """Each vertex's material's uv_scale (metres per repeat)."""
    scale = np.array([m.uv_scale for m in load_level(level).materials])
    vert_mat = np.zeros(len(lod.attributes["position"]), dtype=int)
    vert_mat[lod.triangles.ravel()] = np.repeat(lod.materials, 3)
    return scale[vert_mat]


def whole_repeats(uv: np.ndarray, world: np.ndarray) -> np.ndarray:
    """uv - world (in repeats) where that is a whole number of repeats per vertex (asserted)."""
    shift = uv - world
    assert np.allclose(shift, np.rint(shift), atol=2e-3), "uv0 differs from the projection by whole repeats only"
    return np.rint(shift)


def test_uv0_tiles_at_the_materials_scale(tmp_path):
    scene = build(tmp_path, BOX_MINUS_BOX)
    lod = scene.meshes[0].base
    p, uv, n = (lod.attributes[k].astype(np.float64) for k in ("position", "uv0", "normal"))
    s = vertex_uv_scale(lod, tmp_path / "level.toml")
    up = n[:, 1] > 0.9  # top faces: u = x / uv_scale, v = z / uv_scale (plus whole repeats)
    whole_repeats(uv[up], p[up][:, [0, 2]] / s[up, None])
    east = n[:, 0] > 0.9  # +X faces: u = -z, v = -y
    whole_repeats(uv[east], -p[east][:, [2, 1]] / s[east, None])
    assert set(np.round(s, 3)) == {2.0, 0.5}  # both materials' scales are in use


def test_uv0_of_a_room_far_from_the_origin_spans_the_room_not_the_distance(tmp_path):
    """World-space projection puts u = x on a floor and u = -z on a wall: far from the origin one
    room's uv0 would span its distance from it. Each projection is moved by whole repeats (the
    texture looks the same) to lie around 0, so the pack's 16-bit coordinates keep their
    precision: the span is the room's size, every face reads the same texels as before, and
    neighbouring faces of one projection and material stay continuous (one shift for them)."""
    far = BOX_MINUS_BOX.replace('size = [4, 3, 4]', 'size = [4, 3, 4]\n    translation = [1200, 40, -900]')
    scene = build(tmp_path, far.replace('translation = [0.5, 0, 0]', 'translation = [1200.5, 40, -900]'))
    lod = scene.meshes[0].base
    p, uv, n = (lod.attributes[k].astype(np.float64) for k in ("position", "uv0", "normal"))
    assert p[:, 0].min() > 1100, "the room is far from the origin"
    s = vertex_uv_scale(lod, tmp_path / "level.toml")
    size = (p.max(axis=0) - p.min(axis=0)).max()
    assert np.ptp(uv) <= size / s.min() + 2, f"uv0 spans {np.ptp(uv):.1f} repeats for a room of {size:.1f} m"
    for face, world in ((n[:, 1] > 0.9, lambda q: q[:, [0, 2]]), (n[:, 0] > 0.9, lambda q: -q[:, [2, 1]]), (n[:, 2] < -0.9, lambda q: -q[:, [0, 1]])):
        shifts = whole_repeats(uv[face], world(p[face]) / s[face, None])
        for scale_of in np.unique(s[face]):
            assert len(np.unique(shifts[s[face] == scale_of], axis=0)) == 1, "one shift per projection and material: its faces stay continuous"
    assert not uv_precision_warnings(scene), "the pack's 16-bit uv0 holds it"


def test_nested_objects_and_intersection(tmp_path):
    scene = build(tmp_path, """
        [[brushes]]
        name = "ball"
        kind = "sphere"
        radius = 1
        material = "stone"

        [[brushes]]
        name = "cube"
        kind = "box"
        size = [1.5, 1.5, 1.5]
        material = "plaster"

        [[brushes]]
        name = "drill"
        kind = "cylinder"
        radius = 0.3
        height = 4
        rotation = [0, 0, 90]
        material = "plaster"

        [[objects]]
        name = "rounded"
        op = "intersection"
        operands = ["ball", "cube"]

        [[objects]]
        name = "drilled"
        op = "difference"
        operands = ["rounded", "drill"]
    """)
    assert [m.name for m in scene.meshes] == ["drilled"], "objects used as operands are not output"
    v = check_closed(scene.meshes[0].base, "drilled")
    assert 1.5 ** 3 * 0.5 < v < 1.5 ** 3
    assert set(scene.meshes[0].base.materials.tolist()) == {0, 1}


def test_object_settings(tmp_path):
    scene = build(tmp_path, """
        [level]
        texels_per_metre = 8

        [[brushes]]
        name = "b"
        kind = "box"
        size = [1, 1, 1]
        material = "stone"

        [[objects]]
        name = "static_default"
        op = "union"
        operands = ["b"]

        [[objects]]
        name = "dense"
        op = "union"
        operands = ["b"]
        texels_per_metre = 64

        [[objects]]
        name = "moving"
        op = "union"
        operands = ["b"]
        static = false
    """)
    by = {m.name: m for m in scene.meshes}
    static = {n.name: n.static for n in scene.nodes}
    assert scene.lightmap.texels_per_metre == 8 and scene.lightmap.pages == []
    assert by["static_default"].texels_per_metre is None and by["dense"].texels_per_metre == 64
    assert static == {"static_default": True, "dense": True, "moving": False}


def test_props_are_merged_under_a_placed_node(tmp_path):
    (tmp_path / "statue.glb").write_bytes(b"glTF")  # only its existence is checked here
    lod = ir.Lod(attributes={"position": np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)},
                 triangles=np.array([[0, 1, 2]], np.uint32), materials=np.array([1], np.uint32))
    prop = ir.Scene(name="statue", source="statue.glb", meshes=[ir.Mesh("body", [lod])],
                    materials=[ir.Material("a"), ir.Material("b", base_color_texture=0)],
                    textures=[ir.Texture("t", 1, 1, "Rgba8Srgb", [np.zeros((1, 1, 4), np.uint8)])],
                    nodes=[ir.Node("root"), ir.Node("child", parent=0, mesh=0, static=True)],
                    lights=[ir.Light("lamp", "point", position=(0, 1, 0))])
    spec = load_level(write(tmp_path, HEADER + textwrap.dedent(ONE_BOX + """

        [[props]]
        name = "statue"
        gltf = "statue.glb"
        translation = [5, 0, 0]
        rotation = [0, 90, 0]
    """)))
    seen = []
    scene = build_level(spec, import_gltf=lambda p: seen.append(p) or prop)
    assert seen == [tmp_path / "statue.glb"]
    # The level's switch decides for the prop's mesh nodes (default: not static), whatever the
    # prop's own import said.
    assert [m.name for m in scene.meshes] == ["o", "body"] and scene.static_meshes() == [0]
    assert scene.meshes[1].base.materials.tolist() == [2 + 1]  # after the level's two materials
    assert scene.materials[3].base_color_texture == 0 and len(scene.textures) == 1
    assert [n.name for n in scene.nodes] == ["o", "statue", "statue/root", "statue/child"]
    assert [n.parent for n in scene.nodes] == [None, None, 1, 2] and scene.nodes[3].mesh == 1
    local = np.array(scene.nodes[1].local).reshape(4, 4, order="F")
    assert np.allclose(local[:3, 3], [5, 0, 0]) and np.allclose(local[:3, :3] @ [1, 0, 0], [0, 0, -1])
    assert scene.lights[-1].name == "statue/lamp" and np.allclose(scene.lights[-1].position, [5, 1, 0])
    assert prop.meshes[0].base.materials.tolist() == [1] and prop.nodes[0].parent is None  # prop untouched
    spec_static = load_level(tmp_path / "level.toml")
    spec_static.props[0].static = True
    assert build_level(spec_static, import_gltf=lambda p: prop).static_meshes() == [0, 1]


def test_lights_and_spawns_in_physical_units(tmp_path):
    scene = build(tmp_path, ONE_BOX + """

        [[lights]]
        name = "spot"
        kind = "spot"
        position = [0, 3, 0]
        direction = [0, -2, 0]
        intensity = 500
        inner_cone_deg = 10
        outer_cone_deg = 30

        [[spawns]]
        name = "npc"
        kind = "character"
        rotation = [0, 90, 0]
        params = { animation = "idle" }
    """)
    spot = scene.lights[0]
    assert spot.direction == (0.0, -1.0, 0.0) and spot.intensity == 500
    assert spot.inner_cone == pytest.approx(np.radians(10)) and spot.outer_cone == pytest.approx(np.radians(30))
    q = scene.spawns[0].rotation
    assert np.allclose(q, [0, np.sin(np.pi / 4), 0, np.cos(np.pi / 4)])


# ---- errors name the file, the line and the key ----------------------------------------------

def error_of(tmp_path: Path, body: str, build_too: bool = False) -> str:
    path = write(tmp_path, HEADER + textwrap.dedent(body))
    with pytest.raises(CookError) as e:
        spec = load_level(path)
        if build_too:
            build_level(spec)
    msg = str(e.value)
    assert msg.startswith(str(path)), msg
    assert "\n" not in msg
    return msg


def line_of(tmp_path: Path, needle: str) -> int:
    lines = (tmp_path / "level.toml").read_text().splitlines()
    return next(i + 1 for i, l in enumerate(lines) if needle in l)


def test_error_unknown_key(tmp_path):
    msg = error_of(tmp_path, ONE_BOX + """
        [[brushes]]
        name = "c"
        kind = "box"
        size = [1, 1, 1]
        colour = "red"
        material = "stone"
    """)
    assert f":{line_of(tmp_path, 'colour')}: brushes[1].colour: unknown key 'colour'" in msg


def test_error_unknown_key_for_the_kind(tmp_path):
    msg = error_of(tmp_path, ONE_BOX.replace('size = [1, 1, 1]', 'size = [1, 1, 1]\nradius = 2'))
    assert f":{line_of(tmp_path, 'radius')}: brushes[0].radius: unknown key 'radius' for a box brush" in msg


def test_error_bad_operand(tmp_path):
    msg = error_of(tmp_path, ONE_BOX.replace('operands = ["b"]', 'operands = ["b", "nope"]'))
    assert f":{line_of(tmp_path, 'operands')}: objects[0].operands[1]: 'nope' is not a brush or an object" in msg


def test_error_operand_defined_later(tmp_path):
    msg = error_of(tmp_path, ONE_BOX.replace('operands = ["b"]', 'operands = ["later"]') + """
        [[objects]]
        name = "later"
        op = "union"
        operands = ["b"]
    """)
    assert "objects[0].operands[0]" in msg and "defined before" in msg


def test_error_unknown_op(tmp_path):
    msg = error_of(tmp_path, ONE_BOX.replace('op = "union"', 'op = "xor"'))
    assert f":{line_of(tmp_path, 'xor')}: objects[0].op: unknown value 'xor'" in msg


def test_error_empty_result(tmp_path):
    msg = error_of(tmp_path, ONE_BOX.replace('operands = ["b"]', 'operands = ["b", "far"]').replace('"union"', '"intersection"') + """
        [[brushes]]
        name = "far"
        kind = "box"
        size = [1, 1, 1]
        translation = [10, 0, 0]
        material = "stone"
    """, build_too=True)
    assert f":{line_of(tmp_path, 'intersection')}: objects[0].op: object 'o': the intersection of b, far is empty" in msg


def test_error_touching_brushes(tmp_path):
    msg = error_of(tmp_path, ONE_BOX.replace('operands = ["b"]', 'operands = ["b", "edge"]') + """
        [[brushes]]
        name = "edge"
        kind = "box"
        size = [1, 1, 1]
        translation = [1, 1, 0]
        material = "stone"
    """, build_too=True)
    assert "objects[0]: object 'o': surfaces touch without merging" in msg


def test_error_toml_syntax(tmp_path):
    msg = error_of(tmp_path, ONE_BOX + '\n[[brushes]]\nname = "x\n')
    line = line_of(tmp_path, 'name = "x')
    assert re.search(rf":{line}:\d+: ", msg), msg


def test_error_negative_size(tmp_path):
    msg = error_of(tmp_path, ONE_BOX.replace("size = [1, 1, 1]", "size = [1, -2, 1]"))
    assert f":{line_of(tmp_path, 'size')}: brushes[0].size: must be > 0, got -2" in msg


def test_error_zero_segments(tmp_path):
    msg = error_of(tmp_path, ONE_BOX.replace('kind = "box"\nsize = [1, 1, 1]', 'kind = "cylinder"\nradius = 1\nheight = 1\nsegments = 0'))
    assert "brushes[0].segments: must be >= 3, got 0" in msg


def test_error_unknown_material(tmp_path):
    msg = error_of(tmp_path, ONE_BOX.replace('material = "stone"', 'material = "granite"'))
    assert f":{line_of(tmp_path, 'granite')}: brushes[0].material: unknown material 'granite'" in msg


def test_error_missing_prop_file(tmp_path):
    msg = error_of(tmp_path, ONE_BOX + """
        [[props]]
        name = "statue"
        gltf = "props/statue.glb"
    """)
    assert f":{line_of(tmp_path, 'statue.glb')}: props[0].gltf: prop file 'props/statue.glb' not found" in msg


def test_error_missing_texture_file(tmp_path):
    msg = error_of(tmp_path, ONE_BOX + '\n[[materials]]\nname = "tiles"\ntexture = "wall.png"\n')
    assert f":{line_of(tmp_path, 'wall.png')}: materials[2].texture: texture file 'wall.png' not found" in msg


def test_error_wrong_type_and_unknown_section(tmp_path):
    msg = error_of(tmp_path, ONE_BOX.replace('name = "o"', 'name = "o"\nstatic = "yes"'))
    assert f":{line_of(tmp_path, 'yes')}: objects[0].static: expected true or false, got a string" in msg
    msg = error_of(tmp_path, ONE_BOX + "\n[[brushs]]\nname = 'x'\n")
    assert f":{line_of(tmp_path, '[[brushs]]')}: brushs: unknown key 'brushs'" in msg


def test_error_duplicate_name_and_spawn_param(tmp_path):
    msg = error_of(tmp_path, ONE_BOX.replace('name = "o"', 'name = "b"'))
    assert "objects[0].name: 'b' is already the name of brushes[0]" in msg
    msg = error_of(tmp_path, ONE_BOX + '\n[[spawns]]\nname = "p"\nkind = "boids"\nparams = { count = 3, colour = 1 }\n')
    assert f":{line_of(tmp_path, 'colour')}: spawns[0].params.colour: unknown parameter 'colour' for a boids spawn" in msg


def test_particle_blend_key_is_kept_for_the_runtime(tmp_path):
    scene = build(tmp_path, ONE_BOX + """
        [[spawns]]
        name = "mist"
        kind = "particles"
        params = { rate_per_s = 10, blend = "additive" }
    """)
    assert scene.spawns[0].params["blend"] == "additive"


BAD_BLEND = ONE_BOX + '\n[[spawns]]\nname = "torch_fire"\nkind = "particles"\nparams = { rate_per_s = 10, blend = "glow" }\n'


def test_error_unknown_particle_blend(tmp_path):
    msg = error_of(tmp_path, BAD_BLEND)
    assert (f":{line_of(tmp_path, 'glow')}: spawns[0].params.blend: spawn 'torch_fire': unknown blend 'glow' "
            "(expected one of: alpha, additive)") in msg
    msg = error_of(tmp_path, BAD_BLEND.replace('"glow"', "1"))
    assert "spawns[0].params.blend: spawn 'torch_fire': unknown blend 1" in msg


def test_cook_rejects_an_unknown_particle_blend_with_status_2(run_cook, tmp_path):
    path = write(tmp_path, HEADER + textwrap.dedent(BAD_BLEND))
    r = run_cook(path, "-o", tmp_path / "out.pack")
    assert r.returncode == 2, r.stderr
    assert f"{path}:" in r.stderr and "spawn 'torch_fire': unknown blend 'glow'" in r.stderr, r.stderr
    assert "Traceback" not in r.stderr and not (tmp_path / "out.pack").exists()


def test_png_texture(tmp_path):
    from PIL import Image

    Image.new("RGBA", (4, 2), (10, 20, 30, 255)).save(tmp_path / "wall.png")
    spec = load_level(write(tmp_path, HEADER + ONE_BOX + '\n[[materials]]\nname = "tiles"\ntexture = "wall.png"\n'))
    tex = build_level(spec).textures[0]
    assert (tex.width, tex.height, tex.format) == (4, 2, "Rgba8Srgb") and tuple(tex.mips[0][0, 0]) == (10, 20, 30, 255)


@pytest.mark.parametrize("kind", ["checker", "bricks", "planks", "flagstones"])
def test_procedural_textures_tile(kind):
    from asset_pipeline.procedural_textures import procedural_texture

    p = {"procedural": kind, "size": 64, "count": 4, "mortar": 0.1, "colors": [(0.8, 0.7, 0.6), (0.3, 0.3, 0.3)], "seed": 7}
    img = procedural_texture(p)
    assert img.shape == (64, 64, 4) and img.dtype == np.uint8 and (img[..., 3] == 255).all()
    assert np.array_equal(img, procedural_texture(p)), "deterministic"
    # seamless: the jump across the wrap is no bigger than jumps inside the image
    f = img[..., :3].astype(np.int32)
    inner = max(np.abs(np.diff(f, axis=0)).mean(axis=(1, 2)).max(), np.abs(np.diff(f, axis=1)).mean(axis=(0, 2)).max())
    assert np.abs(f[0] - f[-1]).mean() <= inner and np.abs(f[:, 0] - f[:, -1]).mean() <= inner


@pytest.mark.parametrize("kind", ["bricks", "planks", "flagstones"])
def test_procedural_relief_sinks_the_joints(kind):
    """The normal map is unit, tiles, is flat on the faces' middles and on the joints' floors
    and tilts at the bevels, away from the joint (glTF: x along +u, y up the image); roughness
    is highest in the joints and occlusion lowest."""
    from asset_pipeline.procedural_textures import _pattern, procedural_relief

    p = {"procedural": kind, "size": 128, "count": 4, "mortar": 0.1, "colors": [(0.8, 0.7, 0.6), (0.3, 0.3, 0.3)], "seed": 7, "relief": 1.0}
    normal, orm = procedural_relief(p)
    assert normal.shape == orm.shape == (128, 128, 4) and normal.dtype == orm.dtype == np.uint8
    n = normal[..., :3].astype(np.float64) / 255 * 2 - 1
    assert np.allclose(np.linalg.norm(n, axis=-1), 1.0, atol=0.02)
    assert (n[..., 2] > 0.3).all(), "no normal points into the surface"
    # Tiles: the jump across the wrap is no bigger than inside.
    inner = np.abs(np.diff(n, axis=0)).max()
    assert np.abs(n[0] - n[-1]).max() <= inner + 1e-9 and np.abs(n[:, 0] - n[:, -1]).max() <= np.abs(np.diff(n, axis=1)).max() + 1e-9
    _, dist, _, _, half = _pattern(p)
    joint = dist == 0
    # A face pixel next to a joint on its left tilts left (-x): the face rises away from it.
    left_edge = (~joint) & np.roll(joint, 1, axis=1) & ~np.roll(joint, 1, axis=0) & ~np.roll(joint, -1, axis=0)
    assert left_edge.sum() > 10 and (n[left_edge, 0] < -0.05).mean() > 0.9
    # A face pixel under a joint tilts up the image (+y).
    top_edge = (~joint) & np.roll(joint, 1, axis=0) & ~np.roll(joint, 1, axis=1) & ~np.roll(joint, -1, axis=1)
    assert top_edge.sum() > 10 and (n[top_edge, 1] > 0.05).mean() > 0.9
    rough, occ = orm[..., 1].astype(int), orm[..., 0].astype(int)
    assert (rough[joint] == 255).all() and rough[dist > 3].mean() < 230
    assert occ[joint].max() < occ[dist > 3].min()
    assert procedural_relief({**p, "relief": 0.0}) is None
    assert procedural_relief({**p, "procedural": "checker"}) is None


def test_real_gltf_prop(tmp_path, gltf_samples):
    box = gltf_samples / "BoxTextured" / "BoxTextured.gltf"
    if not box.is_file():
        pytest.skip(f"{box} missing")
    level = write(tmp_path, HEADER + ONE_BOX + f"""
[[props]]
name = "crate"
gltf = "{box}"
translation = [0, 0.5, 3]
static = true
""")
    # The samples live outside the level's folder: allowed only when asked.
    with pytest.raises(CookError, match="reaches outside the level's folder"):
        load_level(level)
    scene = build_level(load_level(level, allow_external_uris=True))
    scene.validate()
    assert [m.name for m in scene.meshes][0] == "o" and len(scene.meshes) == 2 and scene.static_meshes() == [0, 1]
    assert str(box.resolve()) in scene.files  # what the cook's key covers
    assert scene.materials[2].base_color_texture == 0 and len(scene.textures) == 1
    assert scene.nodes[1].name == "crate" and scene.nodes[2].parent == 1


# ---- character spawns bring their skinned assets in -----------------------------------------

def skinned_prop() -> ir.Scene:
    """A one-triangle skinned character: root, mesh node and one joint; clips 'idle' and 'walk'."""
    lod = ir.Lod(attributes={"position": np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)},
                 triangles=np.array([[0, 1, 2]], np.uint32), materials=np.array([0], np.uint32))
    key = lambda node, x: ir.Channel(node, "translation", "linear", np.array([0, 1], np.float32), np.array([[0, 0, 0], [x, 0, 0]], np.float32))
    return ir.Scene(name="golem", source="golem.gltf", meshes=[ir.Mesh("body", [lod])], materials=[ir.Material("skin")],
                    nodes=[ir.Node("root"), ir.Node("body", parent=0, mesh=0, skin=0), ir.Node("hip", parent=0)],
                    skins=[ir.Skin("rig", joints=[2], inverse_bind=np.eye(4, dtype=np.float32).reshape(1, 16))],
                    clips=[ir.Clip("idle", [key(2, 0.1)]), ir.Clip("walk", [key(2, 1.0)])])


CHARACTERS = ONE_BOX + """

    [[spawns]]
    name = "priest"
    kind = "character"
    position = [3, 0, 0]
    params = { asset = "golem.gltf", animation = "idle" }

    [[spawns]]
    name = "pilgrim"
    kind = "character"
    position = [-3, 0, 0]
    params = { asset = "golem.gltf", animation = "walk", speed = 1.2 }
"""


def test_character_spawns_merge_their_asset_as_dynamic_skinned_meshes(tmp_path):
    (tmp_path / "golem.gltf").write_text("{}")  # only its existence is checked here
    prop = skinned_prop()
    spec = load_level(write(tmp_path, HEADER + textwrap.dedent(CHARACTERS)))
    scene = build_level(spec, import_gltf=lambda p: prop)
    assert [n.name for n in scene.nodes] == ["o", "priest", "priest/root", "priest/body", "priest/hip",
                                              "pilgrim", "pilgrim/root", "pilgrim/body", "pilgrim/hip"]
    # Both characters are dynamic (never lightmapped), each node skinned by its own copy of the skin.
    assert scene.static_meshes() == [0] and [n.name for n in scene.nodes if n.static] == ["o"]
    assert [scene.nodes[i].skin for i in (3, 7)] == [0, 1]
    assert [s.joints for s in scene.skins] == [[4], [8]]
    assert [c.name for c in scene.clips] == ["priest/idle", "priest/walk", "pilgrim/idle", "pilgrim/walk"]
    assert [c.channels[0].node for c in scene.clips] == [4, 4, 8, 8]
    assert np.allclose(np.array(scene.nodes[5].local).reshape(4, 4, order="F")[:3, 3], [-3, 0, 0])
    assert prop.skins[0].joints == [2] and prop.nodes[1].skin == 0  # the asset is untouched


def test_error_character_asset_missing(tmp_path):
    msg = error_of(tmp_path, CHARACTERS, build_too=True)
    line = line_of(tmp_path, '"idle"')
    assert f":{line}: spawns[0].params.asset: character 'priest': asset 'golem.gltf' not found" in msg
    # The command line reports it as a cook error: exit 2, one line, no traceback.
    r = subprocess.run([str(COOK), str(tmp_path / "level.toml"), "-o", str(tmp_path / "out.pack")], capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    assert f"level.toml:{line}: spawns[0].params.asset: character 'priest': asset 'golem.gltf' not found" in r.stderr


def test_error_character_without_the_named_clip_or_a_skin(tmp_path):
    (tmp_path / "golem.gltf").write_text("{}")
    spec = load_level(write(tmp_path, HEADER + textwrap.dedent(CHARACTERS.replace('"walk"', '"dance"'))))
    with pytest.raises(CookError) as e:
        build_level(spec, import_gltf=lambda p: skinned_prop())
    assert "spawns[1].params.animation: character 'pilgrim': 'golem.gltf' has no clip 'dance' (it has: idle, walk)" in str(e.value)
    unskinned = skinned_prop()
    unskinned.skins = []
    with pytest.raises(CookError) as e:
        build_level(load_level(tmp_path / "level.toml"), import_gltf=lambda p: unskinned)
    assert "spawns[0].params.asset: character 'priest': 'golem.gltf' has no skin" in str(e.value)


# ---- boids spawns bring their bird mesh in ------------------------------------------------

FLOCK = ONE_BOX + """

    [[spawns]]
    name = "flock"
    kind = "boids"
    position = [0, 5, 0]
    params = { count = 8, asset = "birds/dove.gltf" }
"""


def test_boids_spawn_packs_its_bird_mesh_and_names_it(tmp_path):
    # The demo's own bird, written by its generator and imported by the real glTF importer.
    r = subprocess.run([sys.executable, str(REPO / "content" / "birds" / "make_dove.py"), str(tmp_path / "birds" / "dove.gltf")],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    scene = build(tmp_path, FLOCK)
    mesh = scene.spawns[0].params["mesh"]
    assert scene.meshes[mesh].name == "dove" and scene.meshes[mesh].base.triangle_count == 11
    # No node draws it (the flock does), and it is not baked into the lightmaps.
    assert all(n.mesh != mesh for n in scene.nodes) and mesh not in scene.static_meshes()
    feathers = scene.materials[int(scene.meshes[mesh].base.materials[0])]
    assert feathers.name == "dove feathers" and feathers.double_sided
    assert str(tmp_path / "birds" / "dove.gltf") in scene.files
    # The cooked pack names the mesh in the spawn's parameters, as authored plus `mesh`.
    pack = tmp_path / "flock.pack"
    r = subprocess.run([str(COOK), str(tmp_path / "level.toml"), "-o", str(pack), "--no-bake"], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    doc = json.loads(_core.read_pack_manifest(pack))
    flock = doc["spawns"][0]
    assert flock["params"] == {"count": 8, "asset": "birds/dove.gltf", "mesh": flock["params"]["mesh"]}
    assert doc["meshes"][flock["params"]["mesh"]]["name"] == "dove"


def test_error_boids_without_a_usable_bird(tmp_path):
    msg = error_of(tmp_path, FLOCK.replace(', asset = "birds/dove.gltf"', ""))
    assert f":{line_of(tmp_path, 'count = 8')}: spawns[0].params: boids 'flock': no asset" in msg
    msg = error_of(tmp_path, FLOCK, build_too=True)
    assert "spawns[0].params.asset: boids 'flock': asset 'birds/dove.gltf' not found" in msg
    (tmp_path / "birds").mkdir()
    (tmp_path / "birds" / "dove.gltf").write_text("{}")
    spec = load_level(write(tmp_path, HEADER + textwrap.dedent(FLOCK)))
    two = skinned_prop()
    two.skins, two.clips = [], []
    two.meshes.append(two.meshes[0])
    two.nodes.append(ir.Node("second", mesh=1))
    with pytest.raises(CookError) as e:
        build_level(spec, import_gltf=lambda p: two)
    assert "spawns[0].params.asset: boids 'flock': 'birds/dove.gltf' must hold one mesh (the bird), it has 2" in str(e.value)
    with pytest.raises(CookError) as e:
        build_level(spec, import_gltf=lambda p: skinned_prop())
    assert "boids 'flock': 'birds/dove.gltf' is skinned or morphed" in str(e.value)


def test_character_route_is_read_as_waypoints_and_bad_routes_are_errors(tmp_path):
    (tmp_path / "golem.gltf").write_text("{}")
    routed = CHARACTERS.replace("speed = 1.2 }", "speed = 1.2, walk_speed = 1.5, route = [[-3, 0, 4], [3, 0.5, 4]] }")
    spec = load_level(write(tmp_path, HEADER + textwrap.dedent(routed)))
    pilgrim = spec.spawns[1].params
    assert pilgrim["route"] == [[-3.0, 0.0, 4.0], [3.0, 0.5, 4.0]] and pilgrim["walk_speed"] == 1.5
    for bad, where, reason in [
        ("route = [[-3, 0]]", "spawns[1].params.route[0]", "expected an array of 3 numbers, got 2 values"),
        ("route = []", "spawns[1].params.route", "expected an array of [x, y, z] waypoints, got an empty array"),
        ("route = 4", "spawns[1].params.route", "expected an array of [x, y, z] waypoints, got"),
        ("walk_speed = 0", "spawns[1].params.walk_speed", "must be > 0.0, got 0"),
    ]:
        msg = error_of(tmp_path, CHARACTERS.replace("speed = 1.2 }", f"speed = 1.2, {bad} }}"))
        assert f"{where}: {reason}" in msg, msg


# ---- found by the level TOML fuzz target (fuzz/python/level_toml.py) ----------------------------
# Each input is the minimised one; before the fix it raised something other than a one-line
# CookError naming the file.

@pytest.mark.parametrize("body, says", [
    # A name (or key) holding a line break made the message two lines: they are escaped.
    ('[[materials]]\nname = "st\\re"\n[[brushes]]\nname = "b"\nkind = "box"\nsize = [1, 1, 1]\nmaterial = "stone"\n',
     "brushes[0].material: unknown material 'stone' (defined: st\\re)"),
    ('[level]\n"a\\nb" = 1\n', "level.a\\nb: unknown key 'a\\nb'"),
    # An integer past a float's range: OverflowError in the number checks.
    ("[level]\ntexels_per_metre = 1" + "0" * 400 + "\n", "level.texels_per_metre: expected a number, got an integer too large for a number"),
    ('[[reflection_probes]]\nposition = [1' + "0" * 400 + ', 0, 0]\nbox_min = [0, 0, 0]\nbox_max = [1, 1, 1]\n',
     "reflection_probes[0].position: reflection probe 'reflection_probe_0': every number must be finite"),
    ('[[spawns]]\nname = "p"\nkind = "player"\nparams = { speed = 1' + "0" * 400 + " }\n",
     "spawns[0].params.speed: expected a number, string, boolean or array of numbers"),
    # tomllib's own failures that are not TOMLDecodeError: ValueError for an integer of more
    # than 4300 digits, RecursionError for deep nesting.
    ("x = " + "1" * 4301 + "\n", "not a valid level TOML: Exceeds the limit (4300 digits) for integer string conversion"),
    ("x = " + "[" * 2000 + "]" * 2000 + "\n", "not a valid level TOML: arrays or inline tables nested too deeply"),
])
def test_fuzz_found_inputs_are_one_line_errors(tmp_path, body, says):
    path = tmp_path / "level.toml"
    path.write_text(body)
    with pytest.raises(CookError) as e:
        load_level(path)
    msg = str(e.value)
    assert msg.startswith(str(path)) and len(msg.splitlines()) == 1, repr(msg)
    assert says in msg, msg


def test_a_light_direction_too_long_to_square_is_still_normalised(tmp_path):
    # [1e200, 1e200, 0]: its squared length overflows to infinity, which made the direction
    # (0, 0, 0) without a word (found beside the fuzz target).
    spec = load_level(write(tmp_path, HEADER + ONE_BOX + """
        [[lights]]
        name = "sun"
        kind = "sun"
        intensity = 1000
        direction = [1e200, 1e200, 0]
        """))
    assert spec.lights[0].direction == pytest.approx((2 ** -0.5, 2 ** -0.5, 0.0))


def test_parse_level_is_load_level_of_the_text(tmp_path):
    from asset_pipeline.level import parse_level

    text = TEMPLE.read_text()
    a, b = load_level(TEMPLE), parse_level(text, TEMPLE)
    assert (a.name, len(a.brushes), len(a.objects), len(a.lights), len(a.spawns)) == (b.name, len(b.brushes), len(b.objects), len(b.lights), len(b.spawns))
    with pytest.raises(CookError, match=r"^elsewhere/level\.toml:2:5: "):
        parse_level("[level]\nx = = 1\n", "elsewhere/level.toml")
