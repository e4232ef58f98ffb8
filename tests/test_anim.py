"""Animation in the cooker and the runtime's sampler: a generated interpolation asset (one node
per sampler type and animated property) cooked and sampled through `demo --dump-pose`, checked
against the glTF spec's formulas evaluated here, independently of the code under test; skin
weight clean-up; errors on bad animation data; the Khronos skinning samples against a numpy
skinning of the source file."""

from __future__ import annotations

import base64
import json
import math
import subprocess
from pathlib import Path

import numpy as np
import pytest

from conftest import COOK, DEMO, run_demo

from asset_pipeline import CookError
from asset_pipeline.gltf_import import import_gltf

# ---- writing small glTF files ------------------------------------------------------------------

COMPONENT = {np.dtype(np.float32): 5126, np.dtype(np.uint16): 5123, np.dtype(np.uint8): 5121, np.dtype(np.uint32): 5125}
TYPE = {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4", 16: "MAT4"}


class Gltf:
    """A glTF document with one embedded buffer, built accessor by accessor."""

    def __init__(self):
        self.doc = {"asset": {"version": "2.0"}, "buffers": [], "bufferViews": [], "accessors": [], "nodes": [], "meshes": [], "scenes": [{"nodes": []}], "scene": 0}
        self.blob = bytearray()

    def view(self, data: bytes) -> int:
        while len(self.blob) % 4:
            self.blob.append(0)
        self.doc["bufferViews"].append({"buffer": 0, "byteOffset": len(self.blob), "byteLength": len(data)})
        self.blob += data
        return len(self.doc["bufferViews"]) - 1

    def accessor(self, a, sparse: dict[int, np.ndarray] | None = None) -> int:
        a = np.ascontiguousarray(a)
        k = 1 if a.ndim == 1 else a.shape[1]
        acc = {"bufferView": self.view(a.tobytes()), "componentType": COMPONENT[a.dtype], "count": len(a), "type": TYPE[k]}
        if a.dtype == np.float32 and k <= 4 and np.isfinite(a).all():  # JSON has no NaN
            flat = a.reshape(len(a), -1)
            acc["min"], acc["max"] = [float(x) for x in flat.min(0)], [float(x) for x in flat.max(0)]
        if sparse:
            idx = np.array(sorted(sparse), np.uint32)
            vals = np.array([sparse[i] for i in sorted(sparse)], a.dtype)
            acc["sparse"] = {"count": len(idx), "indices": {"bufferView": self.view(idx.tobytes()), "componentType": 5125},
                             "values": {"bufferView": self.view(vals.tobytes())}}
            acc.pop("min", None), acc.pop("max", None)
        self.doc["accessors"].append(acc)
        return len(self.doc["accessors"]) - 1

    def node(self, **kw) -> int:
        self.doc["nodes"].append(kw)
        self.doc["scenes"][0]["nodes"].append(len(self.doc["nodes"]) - 1)
        return len(self.doc["nodes"]) - 1

    def write(self, path: Path) -> Path:
        self.doc["buffers"] = [{"byteLength": len(self.blob), "uri": "data:application/octet-stream;base64," + base64.b64encode(bytes(self.blob)).decode()}]
        path.write_text(json.dumps(self.doc))
        return path


TRIANGLE = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)


def triangle_mesh(g: Gltf, name: str, attributes: dict[str, int] | None = None, targets=None, weights=None) -> int:
    prim = {"attributes": {"POSITION": g.accessor(TRIANGLE), **(attributes or {})}}
    if targets:
        prim["targets"] = [{"POSITION": g.accessor(t)} for t in targets]
    mesh = {"name": name, "primitives": [prim]}
    if weights is not None:
        mesh["weights"] = weights
    g.doc["meshes"].append(mesh)
    return len(g.doc["meshes"]) - 1


# ---- the spec's sampler, written out here --------------------------------------------------------


def quat_matrix(q) -> np.ndarray:
    x, y, z, w = (float(c) for c in q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def spec_sample(times, values, interpolation: str, rotation: bool, t: float) -> np.ndarray:
    """glTF 2.0 Appendix C. `values` (keys, c), or (keys, 3, c) for cubic: in, value, out."""
    times = np.asarray(times, np.float64)
    v = np.asarray(values, np.float64)
    val = (lambda k: v[k, 1]) if interpolation == "CUBICSPLINE" else (lambda k: v[k])
    if t <= times[0]:
        return val(0)
    if t >= times[-1]:
        return val(len(times) - 1)
    k = int(np.searchsorted(times, t, side="right")) - 1
    td = times[k + 1] - times[k]
    u = (t - times[k]) / td
    if interpolation == "STEP":
        return val(k)
    if interpolation == "LINEAR":
        a, b = val(k), val(k + 1)
        if not rotation:
            return (1 - u) * a + u * b
        d = float(np.dot(a, b))
        s = 1.0 if d >= 0 else -1.0
        ang = math.acos(min(abs(d), 1.0))
        if ang < 1e-6:
            return a
        return (math.sin(ang * (1 - u)) * a + s * math.sin(ang * u) * b) / math.sin(ang)
    h00, h10, h01, h11 = 2 * u**3 - 3 * u**2 + 1, u**3 - 2 * u**2 + u, -2 * u**3 + 3 * u**2, u**3 - u**2
    r = h00 * v[k, 1] + h10 * td * v[k, 2] + h01 * v[k + 1, 1] + h11 * td * v[k + 1, 0]
    return r / np.linalg.norm(r) if rotation else r


def test_spec_sampler_here_matches_the_notes_numbers():
    # The notes' fixed numbers pin the reference implementation used by the tests below.
    q = spec_sample([0, 1], [[0, 0, 0, 1], [0, 0, math.sin(math.pi / 4), math.cos(math.pi / 4)]], "LINEAR", True, 0.5)
    np.testing.assert_allclose(q, [0, 0, 0.3826834, 0.9238795], atol=1e-7)
    assert spec_sample([0, 1, 3], [[0], [10], [30]], "LINEAR", False, 2.0)[0] == pytest.approx(20.0)
    assert spec_sample([0, 1], [[0], [10]], "STEP", False, 0.999)[0] == 0.0


# ---- the interpolation asset --------------------------------------------------------------------

TIMES = np.array([0.0, 1.0, 2.5], np.float32)  # uneven, so the cubic tangent scaling matters
SAMPLERS = ["STEP", "LINEAR", "CUBICSPLINE"]


def rot(axis, degrees) -> np.ndarray:
    axis = np.asarray(axis, np.float64) / np.linalg.norm(axis)
    h = math.radians(degrees) / 2
    return np.array([*(axis * math.sin(h)), math.cos(h)])


def interpolation_values() -> dict[str, np.ndarray]:
    # The third rotation key is stored negated: the same rotation, which must still be reached
    # by the short path.
    return {
        "translation": np.array([[0, 0, 0], [1, 2, 3], [-1, 0.5, 2]], np.float32),
        "rotation": np.array([rot([0, 0, 1], 0), rot([0, 0, 1], 90), -rot([1, 1, 0], 100)], np.float32),
        "scale": np.array([[1, 1, 1], [2, 0.5, 1], [1, 3, 0.25]], np.float32),
        "weights": np.array([[0, 0], [1, 0.25], [0.5, 1]], np.float32),
    }


def cubic(values: np.ndarray) -> np.ndarray:
    """(keys, c) values -> (keys, 3, c) with distinctive, key-dependent tangents."""
    k, c = values.shape
    a = np.array([[0.5 * (i + 1) * (-1) ** j for j in range(c)] for i in range(k)], np.float32)
    b = np.array([[0.3 * (i + 2) * (1 if j % 2 else -1) for j in range(c)] for i in range(k)], np.float32)
    if c == 4:
        a, b = a * 0.2, b * 0.2  # gentle tangents keep the rotation curve far from zero length
    return np.stack([a, values, b], axis=1)


def make_interpolation_asset(path: Path) -> tuple[dict, dict]:
    """One node per sampler type for translation, rotation and scale, and one morphing mesh node
    per sampler type for weights; one clip 'interp'. Returns (expected sources, node indices)."""
    g = Gltf()
    vals = interpolation_values()
    mesh = triangle_mesh(g, "morph", targets=[np.array([[0, 0, 1]] * 3, np.float32), np.array([[1, 0, 0]] * 3, np.float32)], weights=[0.0, 0.0])
    channels, samplers, nodes, sources = [], [], {}, {}
    times = g.accessor(TIMES)
    for path_name in ["translation", "rotation", "scale", "weights"]:
        for interp in SAMPLERS:
            name = f"{path_name}_{interp.lower()}"
            node = g.node(name=name, mesh=mesh) if path_name == "weights" else g.node(name=name)
            v = vals[path_name]
            out = cubic(v) if interp == "CUBICSPLINE" else v
            flat = out.reshape(-1) if path_name == "weights" else out.reshape(-1, out.shape[-1])
            sparse = None
            if path_name == "translation" and interp == "LINEAR":
                # A sparse accessor: the middle key's value comes from the sparse substitution.
                base = flat.copy()
                base[1] = [9, 9, 9]
                sparse, flat = {1: out[1]}, base
            samplers.append({"input": times, "output": g.accessor(flat, sparse), "interpolation": interp})
            channels.append({"sampler": len(samplers) - 1, "target": {"node": node, "path": path_name}})
            nodes[name] = node
            sources[name] = (path_name, interp, out)
    g.doc["animations"] = [{"name": "interp", "channels": channels, "samplers": samplers}]
    g.write(path)
    return sources, nodes


def cook_cli(src: Path, out: Path) -> subprocess.CompletedProcess:
    r = subprocess.run([str(COOK), str(src), "-o", str(out)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, f"cook failed:\n{r.stderr}"
    return r


def dump(pack: Path, clip: str, t: float) -> dict:
    r = run_demo(["--dump-pose", pack, "--clip", clip, "--time", t])
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout)


@pytest.fixture(scope="module")
def interp_pack(tmp_path_factory):
    d = tmp_path_factory.mktemp("interp")
    sources, nodes = make_interpolation_asset(d / "interp.gltf")
    cook_cli(d / "interp.gltf", d / "interp.pack")
    return d / "interp.pack", sources, nodes


# Key times, midpoints, points between, and both sides outside the clip.
SAMPLE_TIMES = [0.0, 0.5, 1.0, 1.75, 2.5, 0.3, 2.2, -1.0, 4.0]


@pytest.mark.parametrize("t", SAMPLE_TIMES)
def test_interpolation_asset_matches_the_spec(interp_pack, t):
    pack, sources, nodes = interp_pack
    pose = dump(pack, "interp", t)
    assert pose["duration"] == pytest.approx(2.5)
    meshes = {m["node"]: m for m in pose["meshes"]}
    checked, wrong = 0, []
    for name, (path_name, interp, out) in sources.items():
        want = spec_sample(TIMES, out, interp, path_name == "rotation", t)
        node = nodes[name]
        world = np.array(pose["nodes"][node]["world"], np.float64).reshape(4, 4).T  # column-major
        if path_name == "translation":
            got = world[:3, 3]
        elif path_name == "scale":
            got = np.diag(world[:3, :3])
        elif path_name == "rotation":
            got, want = world[:3, :3], quat_matrix(want)
        else:
            got = np.array(meshes[node]["morph_weights"])
        if not np.allclose(got, want, rtol=0, atol=2e-5):
            wrong.append(f"{name}: got {np.round(got, 6).tolist()}, spec says {np.round(want, 6).tolist()}")
        checked += 1
    assert checked == 12
    assert not wrong, f"at t={t}:\n" + "\n".join(wrong)


def test_interpolation_asset_keys_are_distinct_so_the_checks_can_fail(interp_pack):
    # Every node moves between the first and the middle key: a sampler stuck at its first
    # value would fail the comparisons above.
    pack, sources, nodes = interp_pack
    a, b = dump(pack, "interp", 0.0), dump(pack, "interp", 1.0)
    for name, node in nodes.items():
        if name.startswith("weights"):
            continue
        assert not np.allclose(a["nodes"][node]["world"], b["nodes"][node]["world"]), name


def test_morph_weights_deform_the_mesh(interp_pack):
    pack, _, nodes = interp_pack
    pose = dump(pack, "interp", 1.0)
    m = next(m for m in pose["meshes"] if m["node"] == nodes["weights_linear"])
    # Weights (1, 0.25) at t=1: every vertex moves by 1 * (0,0,1) + 0.25 * (1,0,0).
    positions = np.array(m["positions"])
    base = TRIANGLE[np.array([0, 1, 2])]
    np.testing.assert_allclose(np.sort(positions, axis=0), np.sort(base + [0.25, 0, 1], axis=0), atol=1e-6)


def test_dump_pose_errors_are_one_line_naming_the_clip(interp_pack):
    pack, _, _ = interp_pack
    r = run_demo(["--dump-pose", pack, "--clip", "walk", "--time", 0])
    assert r.returncode == 2
    assert "no clip named 'walk'" in r.stderr and "interp" in r.stderr
    assert "Traceback" not in r.stderr and "panicked" not in r.stderr
    r = run_demo(["--dump-pose", pack, "--clip", "interp"])
    assert r.returncode == 2 and "--time" in r.stderr


# ---- skin weights in the cooker ----------------------------------------------------------------


def skinned_triangle(path: Path, joints0, weights0, joints1=None, weights1=None, joint_count=2, name="Tentacle") -> Path:
    g = Gltf()
    attrs = {"JOINTS_0": g.accessor(np.array(joints0, np.uint16)), "WEIGHTS_0": g.accessor(np.array(weights0, np.float32))}
    if joints1 is not None:
        attrs["JOINTS_1"] = g.accessor(np.array(joints1, np.uint16))
        attrs["WEIGHTS_1"] = g.accessor(np.array(weights1, np.float32))
    mesh = triangle_mesh(g, name, attrs)
    joints = [g.node(name=f"j{i}", translation=[0, float(i), 0]) for i in range(joint_count)]
    g.doc["skins"] = [{"name": "rig", "joints": joints}]
    g.node(name="body", mesh=mesh, skin=0)
    return g.write(path)


def test_weights_sum_to_one_after_cooking_when_the_source_does_not(tmp_path):
    src = skinned_triangle(tmp_path / "w.gltf", [[0, 1, 0, 0]] * 3, [[0.5, 0.3, 0, 0], [0.2, 0.2, 0, 0], [0.9, 0, 0, 0]])
    lod = import_gltf(src).meshes[0].base
    w = lod.attributes["weights"]
    np.testing.assert_allclose(w.sum(axis=1), 1.0, atol=1e-7)
    np.testing.assert_allclose(w[0], [0.625, 0.375, 0, 0], atol=1e-7)


def test_more_than_four_influences_keep_the_four_largest_with_a_warning(tmp_path):
    src = skinned_triangle(tmp_path / "six.gltf", [[0, 1, 2, 3]] * 3, [[0.3, 0.1, 0.2, 0.05]] * 3,
                           [[4, 5, 0, 0]] * 3, [[0.25, 0.08, 0, 0]] * 3, joint_count=6)
    scene = import_gltf(src)
    lod = scene.meshes[0].base
    np.testing.assert_array_equal(lod.attributes["joints"][0], [0, 4, 2, 1])
    np.testing.assert_allclose(lod.attributes["weights"][0], np.array([0.3, 0.25, 0.2, 0.1]) / 0.85, atol=1e-6)
    assert any("mesh 0 'Tentacle'" in w and "more than 4" in w for w in scene.warnings), scene.warnings
    # The CLI shows it even without progress output.
    r = subprocess.run([str(COOK), str(src), "-o", str(tmp_path / "six.pack"), "--quiet"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "warning" in r.stderr and "'Tentacle'" in r.stderr
    report = (tmp_path / "six.report.md").read_text()
    assert "## Warnings" in report and "'Tentacle'" in report and "1 skin(s): rig (6 joints)" in report


# ---- bad animation data --------------------------------------------------------------------------


def animated_node(path: Path, times, values, interpolation="LINEAR", name="Wave") -> Path:
    g = Gltf()
    node = g.node(name="bone")
    out = np.array(values, np.float32)
    g.doc["animations"] = [{"name": name, "samplers": [{"input": g.accessor(np.array(times, np.float32)), "output": g.accessor(out), "interpolation": interpolation}],
                            "channels": [{"sampler": 0, "target": {"node": node, "path": "translation"}}]}]
    return g.write(path)


@pytest.mark.parametrize("times,values,interp,problem", [
    ([0, 1, 1], [[0, 0, 0]] * 3, "LINEAR", "not strictly increasing"),
    ([0, 2, 1], [[0, 0, 0]] * 3, "LINEAR", "not strictly increasing"),
    ([0, float("nan")], [[0, 0, 0]] * 2, "LINEAR", "not a finite number"),
    ([0, 1], [[0, 0, 0], [0, float("nan"), 0]], "LINEAR", "not a finite number"),
    ([0, 1], [[0, 0, 0]] * 3, "LINEAR", "output values for 2 keys"),
    ([0, 1], [[0, 0, 0]] * 2, "CUBICSPLINE", "output values for 2 keys"),
])
def test_bad_animation_data_is_a_cook_error_naming_clip_and_channel(tmp_path, times, values, interp, problem):
    src = animated_node(tmp_path / "bad.gltf", times, values, interp)
    with pytest.raises(CookError) as e:
        import_gltf(src)
    msg = str(e.value)
    assert "animation 0 'Wave' channel 0 (translation of node 0 'bone')" in msg and problem in msg and "bad.gltf" in msg, msg
    r = subprocess.run([str(COOK), str(src), "-o", str(tmp_path / "bad.pack")], capture_output=True, text=True, timeout=300)
    assert r.returncode != 0 and "Traceback" not in r.stderr and "'Wave'" in r.stderr
    assert not (tmp_path / "bad.pack").exists()


def test_joint_index_out_of_range_is_a_cook_error(tmp_path):
    src = skinned_triangle(tmp_path / "j.gltf", [[0, 5, 0, 0]] * 3, [[0.5, 0.5, 0, 0]] * 3, joint_count=2)
    with pytest.raises(CookError) as e:
        import_gltf(src)
    msg = str(e.value)
    assert "joint index out of range" in msg and "'Tentacle'" in msg and "'rig'" in msg and "joint 5" in msg, msg


# ---- the Khronos samples against numpy skinning of the source ----------------------------------


def read_accessor(doc: dict, blobs: list[bytes], i: int) -> np.ndarray:
    acc = doc["accessors"][i]
    dt = {5126: np.float32, 5123: np.uint16, 5121: np.uint8, 5125: np.uint32}[acc["componentType"]]
    k = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}[acc["type"]]
    view = doc["bufferViews"][acc["bufferView"]]
    start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
    itemsize = np.dtype(dt).itemsize * k
    stride = view.get("byteStride", itemsize)
    raw = blobs[view["buffer"]]
    rows = [np.frombuffer(raw, dt, k, start + r * stride) for r in range(acc["count"])]
    return np.array(rows, np.float64)


def numpy_pose(gltf_path: Path, t: float) -> list[np.ndarray]:
    """Skinned vertex positions per skinned primitive, computed from the glTF file with the
    spec's formulas (node TRS, sampler, J = G x IBM, p' = sum w J p)."""
    doc = json.loads(gltf_path.read_text())
    blobs = [(gltf_path.parent / b["uri"]).read_bytes() if not b["uri"].startswith("data:") else base64.b64decode(b["uri"].split(",", 1)[1]) for b in doc["buffers"]]
    trs = [{"translation": np.array(n.get("translation", [0, 0, 0]), float), "rotation": np.array(n.get("rotation", [0, 0, 0, 1]), float),
            "scale": np.array(n.get("scale", [1, 1, 1]), float)} for n in doc["nodes"]]
    for ch in doc["animations"][0]["channels"]:
        s = doc["animations"][0]["samplers"][ch["sampler"]]
        times = read_accessor(doc, blobs, s["input"])[:, 0]
        out = read_accessor(doc, blobs, s["output"])
        path = ch["target"]["path"]
        if path == "rotation":
            # The spec requires unit rotation keys; SimpleSkin's are written to 3 digits
            # (|q| = 0.99985), so normalise them as the cooker does.
            out = out / np.linalg.norm(out, axis=1, keepdims=True)
        trs[ch["target"]["node"]][path] = spec_sample(times, out, s.get("interpolation", "LINEAR"), path == "rotation", t)
    parent = {c: i for i, n in enumerate(doc["nodes"]) for c in n.get("children", [])}

    def local(i):
        if "matrix" in doc["nodes"][i]:
            return np.array(doc["nodes"][i]["matrix"], float).reshape(4, 4).T
        m = np.eye(4)
        m[:3, :3] = quat_matrix(trs[i]["rotation"]) * trs[i]["scale"]
        m[:3, 3] = trs[i]["translation"]
        return m

    def world(i):
        return world(parent[i]) @ local(i) if i in parent else local(i)

    results = []
    for n in doc["nodes"]:
        if "skin" not in n:
            continue
        skin = doc["skins"][n["skin"]]
        ibm = read_accessor(doc, blobs, skin["inverseBindMatrices"]).reshape(-1, 4, 4).transpose(0, 2, 1)
        joints_m = np.array([world(j) @ ibm[k] for k, j in enumerate(skin["joints"])])
        for prim in doc["meshes"][n["mesh"]]["primitives"]:
            p = read_accessor(doc, blobs, prim["attributes"]["POSITION"])
            j = read_accessor(doc, blobs, prim["attributes"]["JOINTS_0"]).astype(int)
            w = read_accessor(doc, blobs, prim["attributes"]["WEIGHTS_0"])
            w = w / w.sum(axis=1, keepdims=True)
            m = np.einsum("vk,vkab->vab", w, joints_m[j])
            skinned = np.einsum("vab,vb->va", m, np.c_[p, np.ones(len(p))])[:, :3]
            idx = read_accessor(doc, blobs, prim["indices"])[:, 0].astype(int) if "NORMAL" not in prim["attributes"] else None
            results.append(skinned[idx] if idx is not None else skinned)  # without normals the cooker unwelds per corner
    return results


@pytest.mark.parametrize("model,t", [("SimpleSkin", 1.3), ("SimpleSkin", 4.0), ("RiggedSimple", 0.9)])
def test_skinning_samples_match_numpy_skinning_of_the_source(gltf_samples, tmp_path, model, t):
    src = gltf_samples / model / f"{model}.gltf"
    cook_cli(src, tmp_path / f"{model}.pack")
    pose = dump(tmp_path / f"{model}.pack", "animation0", t)
    want = numpy_pose(src, t)
    got = [np.array(m["positions"]) for m in pose["meshes"]]
    assert len(got) == len(want) == 1
    size = np.linalg.norm(want[0].max(0) - want[0].min(0))
    assert got[0].shape == want[0].shape
    # The cooker reorders vertices for the GPU's caches (the mesh_opt stage): compare as point
    # sets, each point's nearest in the other set, both ways.
    d = np.linalg.norm(got[0][:, None, :] - want[0][None, :, :], axis=2)
    err = max(d.min(axis=1).max(), d.min(axis=0).max()) / size
    assert err < 1e-4, f"{model} at {t} s: relative error {err:.2e}"
    rest = numpy_pose(src, 0.0)[0]
    assert np.abs(want[0] - rest).max() / size > 1e-3, "the pose must move vertices for the check to mean anything"


@pytest.mark.parametrize("model", ["SimpleSkin", "RiggedSimple", "BoxAnimated", "SimpleMorph"])
def test_sample_models_cook_and_dump(gltf_samples, tmp_path, model):
    cook_cli(gltf_samples / model / f"{model}.gltf", tmp_path / "m.pack")
    pose = dump(tmp_path / "m.pack", "animation0", 0.5)
    assert pose["meshes"] and all(np.isfinite(np.array(m["positions"])).all() for m in pose["meshes"])
