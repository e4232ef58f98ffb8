"""Baked reflection probes in the cooker (issue 22 item 2; /work/notes_tmp/reflection_contract.md):
authoring (a level's [[reflection_probes]], a glTF node's extras, a glTF scene's default probe),
their validation errors, the bake settings and cache key, the cubes the baker returns (a probe in a
box of coloured emissive walls sees each wall in its own face), and the pack's
`reflection_probes` field."""

from __future__ import annotations

import dataclasses
import json
import re
import struct
import textwrap
from pathlib import Path

import numpy as np
import pytest

from asset_pipeline import CookError, _core, bake, ir
from asset_pipeline.csg import build_level
from asset_pipeline.gltf_import import import_gltf_scene
from asset_pipeline.level import load_level
from asset_pipeline.pipeline import CookSettings, _bake_key, cook, with_lightmap_uvs
from gltf_scenes import Scene, quaternion
from test_bake import ROOM

# ---- a level with a probe ------------------------------------------------------------------------

# ROOM (test_bake.py: a 6 x 4 x 6 m room, inside x, z -2.7..2.7, y 0.3..3.7, on a slab, under a
# sun and a sky, a lamp inside) with a probe in the room and one over the yard.
PROBES = """
[[reflection_probes]]
name = "room"
position = [0, 1.7, 0]
box_min = [-2.7, 0.3, -2.7]
box_max = [2.7, 3.7, 2.7]
blend_distance = 1.0

[[reflection_probes]]
position = [5, 1.7, 5]
box_min = [3, 0, 3]
box_max = [8, 6, 8]
"""

QUICK = bake.BakeSettings(preset="draft", samples=8, probe_samples=16)


def write(tmp_path: Path, body: str, name: str = "level.toml") -> Path:
    p = tmp_path / name
    p.write_text(textwrap.dedent(body))
    return p


def test_level_probes_are_read_with_their_defaults_and_cross_the_wire(tmp_path):
    scene = build_level(load_level(write(tmp_path, ROOM + PROBES)))
    room, yard = scene.reflection_probes
    assert room == ir.ReflectionProbe("room", (0.0, 1.7, 0.0), (-2.7, 0.3, -2.7), (2.7, 3.7, 2.7), 1.0)
    assert yard == ir.ReflectionProbe("reflection_probe_1", (5.0, 1.7, 5.0), (3.0, 0.0, 3.0), (8.0, 6.0, 8.0), 0.5)
    assert scene.reflection_cubes is None  # authored, not baked
    # Through the wire (the source stage's cache and the pack writer's crossing): unbaked, no
    # `reflection_probes` for the pack; baked, the contract's shape with each cube an array.
    text, arrays = ir.to_wire(scene)
    doc = json.loads(text)
    assert doc["reflection_probes"] is None and len(doc["authored_reflection_probes"]) == 2
    back = ir.from_wire(text, arrays)
    assert back.reflection_probes == scene.reflection_probes and back.reflection_cubes is None
    t = ir.cube_texels(8, 2)
    assert t == 6 * 64 + 6 * 16
    cubes = [np.full((t, 4), k + 1, np.float16) for k in range(2)]
    baked = dataclasses.replace(scene, reflection_cubes=ir.ReflectionCubes(8, 2, cubes))
    text, arrays = ir.to_wire(baked)
    rp = json.loads(text)["reflection_probes"]
    assert (rp["face_size"], rp["levels"]) == (8, 2)
    assert [p["name"] for p in rp["probes"]] == ["room", "reflection_probe_1"]
    assert rp["probes"][0] == {"name": "room", "position": [0.0, 1.7, 0.0], "box_min": [-2.7, 0.3, -2.7], "box_max": [2.7, 3.7, 2.7],
                               "blend_distance": 1.0, "data": rp["probes"][0]["data"]}
    assert [arrays[p["data"]].dtype.str for p in rp["probes"]] == ["<f2", "<f2"]
    back = ir.from_wire(text, arrays)
    assert back.reflection_probes == scene.reflection_probes
    assert all(np.array_equal(a, b) for a, b in zip(back.reflection_cubes.cubes, cubes))
    # A cube of the wrong size or type is refused before it reaches the pack.
    for bad in (np.zeros((t - 1, 4), np.float16), np.zeros((t, 4), np.float32)):
        with pytest.raises(ir.IrError, match="its cube is"):
            ir.to_wire(dataclasses.replace(scene, reflection_cubes=ir.ReflectionCubes(8, 2, [bad, cubes[1]])))


# Each bad probe: (the change to PROBES' first probe, what the message says).
BAD_PROBES = {
    "empty-box": (("box_max = [2.7, 3.7, 2.7]", "box_max = [2.7, 0.3, 2.7]"),
                  ("reflection_probes[0].box_max: reflection probe 'room': the box is empty", "on y")),
    "inverted-box": (("box_min = [-2.7, 0.3, -2.7]", "box_min = [2.8, 0.3, -2.7]"),
                     ("reflection_probes[0].box_max: reflection probe 'room': the box is empty", "on x")),
    "position-outside": (("position = [0, 1.7, 0]", "position = [0, 1.7, 3]"),
                         ("reflection_probes[0].position: reflection probe 'room': the capture point [0.0, 1.7, 3.0] is outside its box",
                          "(on z)")),
    "non-finite-position": (("position = [0, 1.7, 0]", "position = [0, inf, 0]"),
                            ("reflection_probes[0].position: reflection probe 'room': every number must be finite",)),
    "non-finite-box": (("box_min = [-2.7, 0.3, -2.7]", "box_min = [nan, 0.3, -2.7]"),
                       ("reflection_probes[0].box_min: reflection probe 'room': every number must be finite",)),
    "negative-blend": (("blend_distance = 1.0", "blend_distance = -0.5"),
                       ("reflection_probes[0].blend_distance: reflection probe 'room': blend_distance must be a finite number >= 0, got -0.5",)),
    "nan-blend": (("blend_distance = 1.0", "blend_distance = nan"),
                  ("reflection_probes[0].blend_distance: reflection probe 'room': blend_distance must be a finite number >= 0, got nan",)),
    "missing-box": (("box_min = [-2.7, 0.3, -2.7]\n", ""),
                    ("reflection_probes[0].box_min: reflection probe 'room': missing",)),
    "two-numbers": (("position = [0, 1.7, 0]", "position = [0, 1.7]"),
                    ("reflection_probes[0].position: reflection probe 'room': expected an array of 3 numbers, got 2 values",)),
    "unknown-key": (("blend_distance = 1.0", "blend = 1.0"),
                    ("reflection_probes[0].blend: reflection probe 'room': unknown key 'blend'",)),
    "duplicate-name": (('name = "room"', 'name = "reflection_probe_1"'),
                       ("reflection_probes[1].name: 'reflection_probe_1' is already the name of reflection_probes[0]",)),
}


@pytest.mark.parametrize("case", list(BAD_PROBES))
def test_a_bad_level_probe_is_a_one_line_error_naming_the_file_line_and_probe(tmp_path, case):
    (old, new), needles = BAD_PROBES[case]
    assert old in PROBES
    path = write(tmp_path, ROOM + PROBES.replace(old, new, 1))
    with pytest.raises(CookError) as e:
        load_level(path)
    msg = str(e.value)
    assert "\n" not in msg and re.match(rf"{re.escape(str(path))}:\d+: reflection_probes\[", msg), msg
    for n in needles:
        assert n in msg, msg


def test_cook_refuses_a_bad_probe_with_status_2_and_writes_nothing(run_cook, tmp_path):
    path = write(tmp_path, ROOM + PROBES.replace("position = [0, 1.7, 0]", "position = [0, 9, 0]", 1))
    r = run_cook(path, "-o", tmp_path / "out.pack")
    assert r.returncode == 2, r.stderr
    (line,) = r.stderr.strip().splitlines()
    assert line.startswith(f"cook: error: {path}:") and "reflection probe 'room': the capture point [0.0, 9.0, 0.0] is outside" in line, line
    assert not (tmp_path / "out.pack").exists()


@pytest.mark.parametrize("args, message", [
    (("--reflection-face", "100"), "argument --reflection-face: 100 is not a power of two of 8 or more"),
    (("--reflection-face", "4"), "argument --reflection-face: 4 is not a power of two of 8 or more"),
    (("--reflection-samples", "0"), "argument --reflection-samples: 0 is not 1 or more"),
])
def test_bad_reflection_arguments_are_one_line_errors(run_cook, tmp_path, args, message):
    r = run_cook(write(tmp_path, ROOM + PROBES), "-o", tmp_path / "x.pack", *args)
    assert r.returncode == 2 and message in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert not (tmp_path / "x.pack").exists()


# ---- glTF scenes ---------------------------------------------------------------------------------


def _floor_and_box(s: Scene) -> None:
    """A static 4 x 4 m floor at y 0 and a static 1 m cube standing on it at x 1, and a dynamic
    cube far away (extras static false: not baked, not in the static bounds)."""
    grey = s.material("grey", color=(0.5, 0.5, 0.5, 1))
    s.node("floor", mesh=s.quad_mesh("floor", size=(4, 4), material=grey))
    cube = s.box_mesh("cube", material=grey)
    s.node("cube", mesh=cube, translation=[1, 0.5, 0])
    crate = s.node("crate", mesh=cube, translation=[50, 0.5, 0])
    s.doc["nodes"][crate]["extras"] = {"static": False}


def test_a_gltf_scene_gets_a_default_probe_over_its_static_bounds(tmp_path):
    s = Scene()
    _floor_and_box(s)
    scene = import_gltf_scene(s.write(tmp_path / "scene.gltf"))
    (p,) = scene.reflection_probes
    # Static bounds x -2..2, y 0..1, z -2..2: centred there, grown by 1% of the largest size (4 m).
    assert p.name == "reflection_probe_0" and p.blend_distance == 0.5
    assert np.allclose(p.position, (0, 0.5, 0))
    assert np.allclose(p.box_min, (-2.02, -0.02, -2.02)) and np.allclose(p.box_max, (2.02, 1.02, 2.02))


def test_gltf_node_extras_place_probes_at_their_world_translation(tmp_path):
    s = Scene()
    _floor_and_box(s)
    # A probe under a parent moved to x 5 and turned 90 degrees about +Y: its local (0, 1.5, 2)
    # is world (7, 1.5, 0); the box stays on the world axes, centred there.
    child = s.node("mirror_probe", translation=[0, 1.5, 2], root=False)
    s.doc["nodes"][child]["extras"] = {"reflection_probe": {"size": [2, 3, 4], "blend_distance": 0.25}}
    s.node("group", translation=[5, 0, 0], rotation=quaternion((0, 1, 0), 90), children=[child])
    # Without a size: the static bounds' (grown) size.
    plain = s.node("plain_probe", translation=[0, 1, 0])
    s.doc["nodes"][plain]["extras"] = {"reflection_probe": {}, "note": "kept"}
    scene = import_gltf_scene(s.write(tmp_path / "scene.gltf"))
    mirror, plain = sorted(scene.reflection_probes, key=lambda p: p.name)  # no default probe beside them
    assert mirror.name == "mirror_probe" and mirror.blend_distance == 0.25
    assert np.allclose(mirror.position, (7, 1.5, 0), atol=1e-6)
    assert np.allclose(mirror.box_min, (6, 0, -2), atol=1e-6) and np.allclose(mirror.box_max, (8, 3, 2), atol=1e-6)
    assert plain.name == "plain_probe" and plain.blend_distance == 0.5 and np.allclose(plain.position, (0, 1, 0))
    assert np.allclose(np.subtract(plain.box_max, plain.box_min), (4.04, 1.04, 4.04))
    # The source stage's cache keeps them.
    assert ir.from_wire(*ir.to_wire(scene)).reflection_probes == scene.reflection_probes


@pytest.mark.parametrize("extras, message", [
    ({"size": [1, 0, 1]}, "the box is empty (size [1, 0, 1] must be > 0 on every axis)"),
    ({"size": [1, 1]}, "size must be 3 finite numbers, got [1, 1]"),
    ({"size": "big"}, "size must be 3 finite numbers, got \"big\""),
    ({"blend_distance": -1}, "blend_distance must be a finite number >= 0, got -1"),
    ({"radius": 2}, "unknown key 'radius' (expected size, blend_distance)"),
    (True, "expected an object"),
])
def test_a_bad_gltf_probe_is_a_one_line_error_naming_the_file_and_node(tmp_path, extras, message):
    s = Scene()
    _floor_and_box(s)
    n = s.node("probe", translation=[0, 1, 0])
    s.doc["nodes"][n]["extras"] = {"reflection_probe": extras}
    path = s.write(tmp_path / "scene.gltf")
    with pytest.raises(CookError) as e:
        import_gltf_scene(path)
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith(f"{path}: node {n} 'probe': extras reflection_probe: "), msg
    assert message in msg, msg


def test_a_real_sample_gets_a_default_probe(gltf_samples):
    path = gltf_samples / "BoxTextured" / "BoxTextured.gltf"
    if not path.exists():
        pytest.skip(f"{path} is not among the samples")
    scene = import_gltf_scene(path)
    (p,) = scene.reflection_probes
    world = scene.world_matrices()
    pts = np.concatenate([scene.meshes[scene.nodes[k].mesh].base.attributes["position"] @ world[k][:3, :3].T + world[k][:3, 3]
                          for k in scene.static_nodes()])
    lo, hi = pts.min(0), pts.max(0)
    assert np.allclose(p.position, (lo + hi) / 2, atol=1e-6)
    assert (np.array(p.box_min) < lo).all() and (np.array(p.box_max) > hi).all()
    assert np.allclose(np.subtract(p.box_max, p.box_min), hi - lo + 0.01 * (hi - lo).max())


def test_the_temples_probes_sit_in_open_space_inside_their_rooms():
    # The demo level: the hall, the two side rooms and the courtyard, each capture point in the
    # open (no probe ray of it hits the back of a wall) and at head height above its floor.
    temple = build_level(load_level(Path(__file__).resolve().parent.parent / "content" / "levels" / "temple.toml"))
    probes = {p.name: p for p in temple.reflection_probes}
    assert sorted(probes) == ["courtyard", "east_room", "hall", "west_room"]
    floor = {"hall": 0.6, "west_room": 0.6, "east_room": 0.6, "courtyard": 0.0}
    for name, p in probes.items():
        assert p.box_min[1] == floor[name] and 1.6 <= p.position[1] - floor[name] <= 2.0, p
        assert p.blend_distance == 1.0
    baker = _core.Baker(*bake.static_scene(temple).baker_args)
    points = np.array([p.position for p in probes.values()], np.float32)
    _, _, backface, _ = baker.bake_probes(points, preset="draft", probe_samples=256)
    assert (backface == 0).all(), dict(zip(probes, backface))


# ---- settings, cache key, report -----------------------------------------------------------------


def test_presets_give_the_contracts_faces_levels_and_samples():
    assert bake.BakeSettings(preset="draft").reflection() == (64, 5, 16)
    assert bake.BakeSettings(preset="medium").reflection() == (128, 6, 32)
    assert bake.BakeSettings(preset="high").reflection() == (128, 6, 128)
    assert bake.BakeSettings(preset="draft", reflection_face=256, reflection_samples=4).reflection() == (256, 7, 4)
    assert bake.BakeSettings(reflection_face=8).reflection()[:2] == (8, 2)  # the smallest level is 4 texels
    for face in (4, 12, 100):
        with pytest.raises(ValueError, match="power of two >= 8"):
            bake.BakeSettings(reflection_face=face).reflection()
    assert ir.cube_texels(128, 6) == 6 * sum((128 >> k) ** 2 for k in range(6)) == 131040


def test_reflection_settings_and_capture_points_key_the_bake_only_where_there_are_probes(tmp_path):
    with_probes = with_lightmap_uvs(build_level(load_level(write(tmp_path, ROOM + PROBES))))[0]
    without = dataclasses.replace(with_probes, reflection_probes=[])
    s = bake.BakeSettings(preset="draft")
    for scene, changes in ((with_probes, True), (without, False)):
        base = _bake_key(scene, s)
        assert (_bake_key(scene, dataclasses.replace(s, reflection_samples=17)) != base) == changes
        assert (_bake_key(scene, dataclasses.replace(s, reflection_face=32)) != base) == changes
        assert _bake_key(scene, dataclasses.replace(s, threads=1)) == base
    # A capture point is an input of the bake; a box, a name or a blend distance is not (only the pack's).
    p = with_probes.reflection_probes
    moved = dataclasses.replace(with_probes, reflection_probes=[dataclasses.replace(p[0], position=(0.1, 1.7, 0)), p[1]])
    renamed = dataclasses.replace(with_probes, reflection_probes=[dataclasses.replace(p[0], name="x", blend_distance=0.1, box_max=(3, 4, 3)), p[1]])
    assert _bake_key(moved, s) != _bake_key(with_probes, s) == _bake_key(renamed, s)


def test_half_rgba_clamps_to_half_range_with_alpha_one():
    rgb = np.array([[1.5, 0.0, 1e6], [-2.0, 65504.0, 3.0]], np.float32)
    out = bake.half_rgba(rgb)
    assert out.dtype == np.float16 and out.shape == (2, 4)
    assert out.tolist() == [[1.5, 0.0, 65504.0, 1.0], [0.0, 65504.0, 3.0, 1.0]]
    with pytest.raises(ValueError, match="NaN"):
        bake.half_rgba(np.array([[np.nan, 0, 0]], np.float32))


def test_the_report_line_counts_the_probes():
    stats = {"preset": "draft", "reflections": {"count": 5, "face_size": 128, "levels": 6, "samples": 32, "rays": 12_300_000,
                                                "seconds": 41.04, "bytes": 5 * 8 * 131040}}
    (line,) = [l for l in bake.describe(stats) if l.startswith("Reflection probes")]
    assert line == ("Reflection probes: 5, cube faces 128 px with 6 levels, 32 samples per texel; 12.3 M rays in 41.0 s; "
                    "5241600 bytes (5.00 MiB, half-float RGBA).")


# ---- baked (needs Baker.bake_reflection_probe) ----------------------------------------------------


def manifest_and_data(pack: Path) -> tuple[int, dict, bytes]:
    """(format version, manifest, data blob) of a pack (engine/pack/src/lib.rs's header)."""
    version = struct.unpack_from("<I", pack.read_bytes(), 8)[0]
    doc, data = _core.read_pack(pack)
    return version, json.loads(doc), data


@pytest.fixture(scope="module")
def cooked_room(tmp_path_factory):
    d = tmp_path_factory.mktemp("room")
    out = d / "room.pack"
    # The cubes forced to BC6H: at draft samples the room's mirror level is too noisy for the
    # compress stage's bar (test_a_noisy_cube_stays_half_float), and this checks the BC6H layout.
    result = cook(write(d, ROOM + PROBES, "room.toml"), out, CookSettings(bake=QUICK, lods=False, texture_compression={"reflection *": "force"}))
    return out, result


def test_a_cooked_level_carries_its_probes_per_the_contract(cooked_room):
    out, result = cooked_room
    version, doc, data = manifest_and_data(out)
    rp = doc.get("reflection_probes")
    # The cooker hands the cubes to the Rust core in the wire form (ir.to_wire); the core writes the pack.
    assert rp is not None, ("the pack has no reflection_probes: the Rust pack writer (cook_core wire.rs, pack_build.rs) does not "
                            "write the wire's 'reflection_probes' yet (/work/notes_tmp/reflection_wire.md)")
    assert version == 11
    assert (rp["face_size"], rp["levels"]) == (64, 5)  # draft
    # Compressed by default (issue 24): BC6H blocks, each face of each level whole 4x4 blocks.
    assert rp["format"] == "Bc6hUfloat"
    assert [p["name"] for p in rp["probes"]] == ["room", "reflection_probe_1"]
    room, yard = rp["probes"]
    assert room["position"] == pytest.approx([0, 1.7, 0]) and room["box_min"] == pytest.approx([-2.7, 0.3, -2.7])
    assert room["box_max"] == pytest.approx([2.7, 3.7, 2.7]) and room["blend_distance"] == 1.0 and yard["blend_distance"] == 0.5
    for p in rp["probes"]:
        assert p["data"]["len"] == ir.cube_block_bytes(64, 5) == 16 * 6 * (16 * 16 + 8 * 8 + 4 * 4 + 2 * 2 + 1)
        rgba = _decoded_cube(data[p["data"]["offset"]:p["data"]["offset"] + p["data"]["len"]], 64, 5)
        assert np.isfinite(rgba).all() and (rgba >= 0).all(), p["name"]
        assert (rgba[:, 3] == 1).all()
        assert rgba[:, :3].max() > 0, f"{p['name']} sees nothing"
    # The pack's bytes are the scene's cubes as the compress stage made them.
    cubes = result.scene.reflection_cubes.cubes
    assert result.scene.reflection_cubes.format == "Bc6hUfloat"
    assert bytes(data[room["data"]["offset"]:][:room["data"]["len"]]) == cubes[0].tobytes()
    # Level 0's mean radiance: the sunlit yard is brighter than the room.
    mean = [_decoded_cube(data[p["data"]["offset"]:][:p["data"]["len"]], 64, 5)[:6 * 64 * 64, :3].astype(np.float64).mean()
            for p in rp["probes"]]
    assert mean[1] > 2 * mean[0], mean
    report = result.report.read_text()
    assert "Reflection probes: 2, cube faces 64 px with 5 levels, 16 samples per texel;" in report, report


def _decoded_cube(blocks: bytes, face: int, levels: int) -> np.ndarray:
    """A BC6H cube ([level][face] blocks) decoded to the half-float layout, float16 (T, 4)."""
    out, at = [], 0
    for k in range(levels):
        s = max(1, face >> k)
        n = 16 * (-(-s // 4)) ** 2
        for _ in range(6):
            out.append(np.asarray(_core.decode_blocks("Bc6hUfloat", s, s, bytes(blocks[at:at + n]))).reshape(-1, 4))
            at += n
    assert at == len(blocks)
    return np.concatenate(out)


def test_a_noisy_cube_stays_half_float(cooked_room, tmp_path):
    # Without the override, the draft room's cubes miss the bar: their level 0 (the mirror,
    # path-traced with 16 samples a texel) carries Monte Carlo noise BC6H's block endpoints do
    # not follow. The set stays half float, and the report says why.
    out, forced = cooked_room
    result = cook(out.parent / "room.toml", tmp_path / "room.pack", CookSettings(bake=QUICK, lods=False, cache_dir=out.parent / ".cook-cache"))
    assert result.scene.reflection_cubes.format == "Rgba16Float"
    records = {r["name"]: r for r in result.compress["per_texture"] if r["name"].startswith("reflection ")}
    assert records["reflection room"]["kept"] == "below the quality bar", records
    assert records["reflection room"]["quality"]["median_rel"] > 0.03
    assert "of its set was kept" in records["reflection reflection_probe_1"]["kept"]
    assert "| reflection room | hdr | 64x64 | Rgba16Float |" in result.report.read_text()
    forced_room = next(r for r in forced.compress["per_texture"] if r["name"] == "reflection room")
    assert forced_room["format"] == "Bc6hUfloat" and "kept" not in forced_room


def test_compressed_cubes_are_within_3_percent_of_the_baked_ones(tmp_path):
    # A room of flat-coloured walls: little noise, so the default rules make its cube BC6H. The
    # same bake (from the cache) without compression gives the half-float cube as baked: the BC6H
    # cube decodes to within 3 % of it (median relative error over the texels, every level), the
    # bar the compress stage holds every cube to (its record gives the worst face's).
    source = coloured_room(tmp_path / "room.gltf")
    settings = dict(bake=bake.BakeSettings(preset="draft", samples=4, probe_samples=8), sky_nits=0.0, lods=False, report=False)
    (tmp_path / "a").mkdir(), (tmp_path / "b").mkdir()
    packed = cook(source, tmp_path / "a" / "room.pack", CookSettings(**settings, cache_dir=tmp_path / "cache"))
    plain = cook(source, tmp_path / "b" / "room.pack", CookSettings(**settings, compress=False, cache_dir=tmp_path / "cache"))
    rc, baked = packed.scene.reflection_cubes, plain.scene.reflection_cubes
    assert rc.format == "Bc6hUfloat" and baked.format == "Rgba16Float"
    (record,) = [r for r in packed.compress["per_texture"] if r["name"].startswith("reflection ")]
    assert record["quality"]["median_rel"] <= 0.03 and record["bytes_after"] * 7 < record["bytes_before"], record
    decoded = _decoded_cube(rc.cubes[0].tobytes(), baked.face_size, baked.levels)[:, :3].astype(np.float64)
    exact = baked.cubes[0][:, :3].astype(np.float64)
    norm, err = np.linalg.norm(exact, axis=1), np.linalg.norm(decoded - exact, axis=1)
    seen = (norm > 0) | (err > 0)
    relative = np.where(norm > 0, err / np.maximum(norm, 1e-30), np.inf)[seen]
    assert np.median(relative) <= 0.03, np.median(relative)
    print(f"BC6H cube: median relative error {100 * np.median(relative):.2f}%, p95 {100 * np.percentile(relative, 95):.2f}%, "
          f"{rc.cubes[0].nbytes} bytes vs {baked.cubes[0].nbytes}")


def test_a_second_cook_takes_the_cubes_from_the_cache_with_the_same_bytes(cooked_room, tmp_path):
    out, _ = cooked_room
    again = tmp_path / "room.pack"
    result = cook(out.parent / "room.toml", again, CookSettings(bake=QUICK, lods=False, report=False, cache_dir=out.parent / ".cook-cache",
                                                                texture_compression={"reflection *": "force"}))
    (stage,) = [s for s in result.stages if s.name == "bake"]
    assert stage.cached == stage.items
    assert again.read_bytes() == out.read_bytes()


def test_the_cli_sets_the_cubes_size_and_samples(run_cook, tmp_path):
    out = tmp_path / "room.pack"
    r = run_cook(write(tmp_path, ROOM + PROBES, "room.toml"), "-o", out, "--no-lods", "--quality", "draft", "--samples", "2",
                 "--probe-samples", "8", "--reflection-face", "16", "--reflection-samples", "4")
    assert r.returncode == 0, r.stderr
    report = out.with_suffix(".report.md").read_text()
    assert "Reflection probes: 2, cube faces 16 px with 3 levels, 4 samples per texel;" in report, report


def test_no_bake_no_probes(tmp_path):
    out = tmp_path / "room.pack"
    result = cook(write(tmp_path, ROOM + PROBES, "room.toml"), out, CookSettings(baking=False, lods=False, report=False))
    assert len(result.scene.reflection_probes) == 2 and result.scene.reflection_cubes is None
    _, doc, _ = manifest_and_data(out)
    assert doc.get("reflection_probes") is None


# A closed 4 m cube room, centred on the origin, whose six walls glow each in their own colour
# (nits; black, so nothing bounces), the +X wall in two halves (upper, lower) and the ceiling in
# two (-Z, +Z), to see which way up each face's rows run. No sky, no lights.
WALLS = {
    "+X up": (10, 0, 0), "+X low": (10, 10, 0),
    "-X": (0, 10, 0),
    "+Y -z": (0, 0, 10), "+Y +z": (0, 10, 10),
    "-Y": (10, 0, 10),
    "+Z": (5, 5, 5),
    "-Z": (2, 4, 8),
}


def _wall(s: Scene, name: str, centre, u, v, half_u: float, half_v: float) -> None:
    """A rectangle centre +- half_u u +- half_v v facing the origin, glowing WALLS[name]."""
    centre, u, v = (np.asarray(x, np.float64) for x in (centre, u, v))
    inward = -centre / np.linalg.norm(centre)
    pos = [centre + a * half_u * u + b * half_v * v for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    idx = [0, 1, 2, 0, 2, 3]
    if np.dot(np.cross(pos[1] - pos[0], pos[2] - pos[0]), inward) < 0:
        idx = [0, 2, 1, 0, 3, 2]
    colour = np.asarray(WALLS[name], np.float64)
    mat = s.material(name, color=(0, 0, 0, 1), emissive=tuple(colour / 10), emissive_strength=10.0)
    mesh = s.mesh_arrays(name, np.array(pos), np.tile(inward, (4, 1)), [[0, 0], [1, 0], [1, 1], [0, 1]], idx, mat)
    s.node(name, mesh=mesh)


def coloured_room(path: Path, probe: dict | None = None) -> Path:
    s = Scene()
    _wall(s, "+X up", (2, 1, 0), (0, 0, 1), (0, 1, 0), 2, 1)
    _wall(s, "+X low", (2, -1, 0), (0, 0, 1), (0, 1, 0), 2, 1)
    _wall(s, "-X", (-2, 0, 0), (0, 0, 1), (0, 1, 0), 2, 2)
    _wall(s, "+Y -z", (0, 2, -1), (1, 0, 0), (0, 0, 1), 2, 1)
    _wall(s, "+Y +z", (0, 2, 1), (1, 0, 0), (0, 0, 1), 2, 1)
    _wall(s, "-Y", (0, -2, 0), (1, 0, 0), (0, 0, 1), 2, 2)
    _wall(s, "+Z", (0, 0, 2), (1, 0, 0), (0, 1, 0), 2, 2)
    _wall(s, "-Z", (0, 0, -2), (1, 0, 0), (0, 1, 0), 2, 2)
    if probe is not None:
        n = s.node("centre", translation=[0, 0, 0])
        s.doc["nodes"][n]["extras"] = {"reflection_probe": probe}
    return s.write(path)


def _faces(cube: np.ndarray, face: int, level: int = 0) -> np.ndarray:
    """Level `level` of a (T, 4) cube of `face`-texel faces as float64 (6, f, f, 3)."""
    start = sum(6 * (face >> k) ** 2 for k in range(level))
    f = face >> level
    return cube[start:start + 6 * f * f, :3].astype(np.float64).reshape(6, f, f, 3)


def test_a_probe_in_a_box_of_coloured_walls_sees_each_wall_in_its_own_face(tmp_path):
    out = tmp_path / "room.pack"
    # The default probe: at the bounds' centre, the origin.
    result = cook(coloured_room(tmp_path / "room.gltf"), out,
                  CookSettings(bake=bake.BakeSettings(preset="draft", samples=4, probe_samples=8), sky_nits=0.0, lods=False, report=False,
                               compress=False))  # the cubes as baked
    (p,) = result.scene.reflection_probes
    assert np.allclose(p.position, 0, atol=1e-6)
    rc = result.scene.reflection_cubes
    assert (rc.face_size, rc.levels) == (64, 5)
    f = rc.face_size
    level0 = _faces(rc.cubes[0], f)
    top, bottom = slice(0, f // 2 - 1), slice(f // 2 + 1, f)  # the rows either side of a split, its own two left out

    def seen(img, name):
        assert np.allclose(img.reshape(-1, 3).mean(0), WALLS[name], rtol=0.01, atol=0.02), (name, img.reshape(-1, 3).mean(0))
        assert np.abs(img - WALLS[name]).max() < 0.5, (name, np.abs(img - WALLS[name]).max())

    # Faces in the pack's order +X, -X, +Y, -Y, +Z, -Z; row 0 at the top: on a side face toward
    # +Y, on the +Y face toward -Z (shading.md section 1.4's table).
    seen(level0[0, top], "+X up")
    seen(level0[0, bottom], "+X low")
    seen(level0[1], "-X")
    seen(level0[2, top], "+Y -z")
    seen(level0[2, bottom], "+Y +z")
    seen(level0[3], "-Y")
    seen(level0[4], "+Z")
    seen(level0[5], "-Z")
    # The roughest level mixes in the neighbouring walls: the +X face now has blue (ceiling,
    # floor, -Z), which level 0 has none of.
    rough = _faces(rc.cubes[0], f, rc.levels - 1)
    assert level0[0, ..., 2].max() < 0.5 and rough[0, ..., 2].mean() > 1.0, rough[0].reshape(-1, 3).mean(0)
    assert np.isfinite(rough).all() and (rough >= 0).all()


def test_the_cubes_are_the_same_for_one_and_two_threads(tmp_path):
    source = coloured_room(tmp_path / "room.gltf", probe={"size": [3.9, 3.9, 3.9], "blend_distance": 0.3})
    cubes = []
    for threads in (1, 2):
        s = bake.BakeSettings(preset="draft", samples=2, probe_samples=8, seed=7, threads=threads, reflection_face=16, reflection_samples=8)
        out = tmp_path / f"t{threads}" / "room.pack"
        out.parent.mkdir()
        r = cook(source, out, CookSettings(bake=s, sky_nits=0.0, lods=False, report=False, compress=False))
        (p,) = r.scene.reflection_probes
        assert p.name == "centre" and np.allclose(p.box_max, 1.95) and p.blend_distance == 0.3
        cubes.append(r.scene.reflection_cubes)
    assert (cubes[0].face_size, cubes[0].levels) == (16, 3)
    assert cubes[0].cubes[0].tobytes() == cubes[1].cubes[0].tobytes()
