"""Morph LODs (issue 23): meshes with morph targets get a LOD chain whose levels carry their own
morph deltas, and each level's stored error bounds its distance to LOD 0 at rest and with every
morph target at weight 1.

The golem (content/characters/make_creature.py, as `make cook` makes and cooks it) is cooked into
a temporary folder and its pack read back as the runtime reads it: each LOD's own vertices,
indices and deltas. Distances are measured here independently of the cooker's own grid sampler:
random area-weighted samples with exact closest points (test_lod's `sampled_hausdorff`)."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from asset_pipeline import _core, ir
from asset_pipeline._core import MeshBvh
from asset_pipeline.cook import cook_detailed
from asset_pipeline.lod import LodSettings, build_lods
from conftest import REPO
from test_lod import sampled_hausdorff

VERTEX_STRIDE = _core.VERTEX_STRIDE  # the stored vertex: position (3 f32) first


def read_pack(path):
    """(manifest, data blob) of a pack, validated by the pack crate."""
    doc, data = _core.read_pack(path)
    return json.loads(doc), data


def _array(data: bytes, r: dict, dtype, shape) -> np.ndarray:
    return np.frombuffer(data, dtype, count=r["len"] // np.dtype(dtype).itemsize, offset=r["offset"]).reshape(shape)


def pack_lods(manifest: dict, data: bytes, mesh: int) -> list[dict]:
    """Per LOD of `mesh`: positions, triangles, stored error and morph position deltas
    (targets, n, 3), as the pack holds them."""
    deform = next(d for d in manifest["animation"]["meshes"] if d["mesh"] == mesh)
    targets = len(deform["morph_weights"])
    out = []
    for lod, dl in zip(manifest["meshes"][mesh]["lods"], deform["lods"]):
        n = lod["vertex_count"]
        vertices = _array(data, lod["vertices"], np.uint8, (n, VERTEX_STRIDE))
        positions = np.ascontiguousarray(vertices[:, :12]).view(np.float32).reshape(n, 3)
        triangles = _array(data, lod["indices"], {"u16": np.uint16, "u32": np.uint32}[lod["index_format"]], (-1, 3)).astype(np.uint32)
        morph = None if dl["morph"] is None else _array(data, dl["morph"]["positions"], np.float32, (targets, n, 3))
        out.append({"positions": positions, "triangles": triangles, "error": lod["error"], "morph": morph, "skin": dl["skin"]})
    return out


def surface(positions: np.ndarray, triangles: np.ndarray) -> ir.Lod:
    return ir.Lod(attributes={"position": np.ascontiguousarray(positions, np.float32)}, triangles=np.ascontiguousarray(triangles, np.uint32),
                  materials=np.zeros(len(triangles), np.uint32))


# ---- the golem ---------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def golem(tmp_path_factory):
    """The golem made by its generator and cooked as `make cook` cooks build/golem.pack, into a
    temporary folder: (CookResult, manifest, data)."""
    d = tmp_path_factory.mktemp("golem")
    src = d / "golem.gltf"
    subprocess.run([sys.executable, str(REPO / "content" / "characters" / "make_creature.py"), str(src)], check=True, capture_output=True, timeout=300)
    result = cook_detailed(src, d / "golem.pack", progress=False)
    manifest, data = read_pack(d / "golem.pack")
    return result, manifest, data


def test_the_golem_gets_a_lod_chain_with_its_morph_target_on_every_level(golem):
    result, manifest, data = golem
    [mesh] = [i for i, m in enumerate(manifest["meshes"]) if m["name"] == "golem"]
    lods = pack_lods(manifest, data, mesh)
    counts = [len(l["triangles"]) for l in lods]
    errors = [l["error"] for l in lods]
    print("golem LODs: triangles", counts, "stored errors (m)", [f"{e:.5f}" for e in errors])
    assert counts[0] == 22_848
    assert len(lods) >= 4, f"only {len(lods)} LODs: {counts}"
    assert all(b < a for a, b in zip(counts, counts[1:])), counts
    for l, lod in enumerate(lods):
        n = len(lod["positions"])
        assert lod["morph"] is not None and lod["morph"].shape == (1, n, 3), f"LOD {l}: no deltas of its own"
        assert lod["skin"] is not None, f"LOD {l}: no skin"
        assert np.isfinite(lod["morph"]).all()
    # The breathe target swells the chest on every level by about as much as on LOD 0 (a carried
    # delta is a blend of LOD 0's: never longer than the longest of them).
    reach = [float(np.linalg.norm(l["morph"][0], axis=1).max()) for l in lods]
    assert all(r <= reach[0] * (1 + 1e-6) for r in reach), reach
    assert all(r >= 0.5 * reach[0] for r in reach), reach
    lod_stage = next(s for s in result.stages if s.name == "lod")
    print(f"golem lod stage: {lod_stage.seconds:.2f} s")
    assert lod_stage.items == 1 and lod_stage.cached == 0
    assert lod_stage.seconds < 10.0, "the LOD stage should take seconds, not more"


@pytest.mark.parametrize("pose", ["rest", "breathe"])
def test_each_golem_lod_is_within_its_stored_error_at_rest_and_with_the_target_at_weight_1(golem, pose):
    _, manifest, data = golem
    [mesh] = [i for i, m in enumerate(manifest["meshes"]) if m["name"] == "golem"]
    lods = pack_lods(manifest, data, mesh)

    def posed(lod):
        # The runtime's morph: position + weight x delta (weight 1), before skinning.
        return surface(lod["positions"] + (lod["morph"][0] if pose == "breathe" else 0.0), lod["triangles"])

    lod0 = posed(lods[0])
    for l, lod in enumerate(lods[1:], 1):
        h = sampled_hausdorff(posed(lod), lod0, n=60_000, seed=2300 + l)
        print(f"LOD {l} {pose}: sampled Hausdorff {h:.5f} m, stored {lod['error']:.5f} m")
        assert h <= lod["error"], f"LOD {l} ({pose}): sampled Hausdorff {h:.6g} > stored error {lod['error']:.6g}"


# ---- a plane with a bump ------------------------------------------------------------------------


def bump_plane(n: int = 48) -> ir.Lod:
    """A flat 2 x 2 m plane of n x n quads (z = 0, normals +z) with two morph targets: `bump`
    lifts a Gaussian bump 0.3 m high in the middle (normal deltas: the bump's normals minus +z),
    `tilt` moves every vertex by (0, 0, 0.1 x + 0.05 y) (a linear field: blends reproduce it)."""
    u = np.linspace(-1.0, 1.0, n + 1)
    x, y = np.meshgrid(u, u, indexing="ij")
    pos = np.stack([x, y, np.zeros_like(x)], -1).reshape(-1, 3)
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    tris = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    s = 0.3
    h = 0.3 * np.exp(-(x ** 2 + y ** 2) / s ** 2)
    gx, gy = h * -2 * x / s ** 2, h * -2 * y / s ** 2
    bump_normal = np.stack([-gx, -gy, np.ones_like(h)], -1)
    bump_normal /= np.linalg.norm(bump_normal, axis=-1, keepdims=True)
    up = np.tile([0.0, 0.0, 1.0], (len(pos), 1))
    bump = np.stack([np.zeros_like(h), np.zeros_like(h), h], -1).reshape(-1, 3)
    tilt = np.stack([np.zeros_like(x), np.zeros_like(x), 0.1 * x + 0.05 * y], -1).reshape(-1, 3)
    return ir.Lod(
        attributes={"position": pos.astype(np.float32), "normal": up.astype(np.float32), "uv0": (pos[:, :2] * 0.5 + 0.5).astype(np.float32)},
        triangles=tris.astype(np.uint32),
        materials=np.zeros(len(tris), np.uint32),
        morph_positions=np.stack([bump, tilt]).astype(np.float32),
        morph_normals=np.stack([bump_normal.reshape(-1, 3) - up, np.zeros_like(up)]).astype(np.float32),
    )


# The plane's open border is kept where it is (else its collapse along the border costs more
# than the bump): at rest every level is then the plane itself, exactly.
PLANE = LodSettings(lock_borders=True)


@pytest.fixture(scope="module")
def plane_chain():
    lod0 = bump_plane()
    return lod0, build_lods(lod0, PLANE)


def test_carried_deltas_are_lod0s_interpolated_where_each_vertex_lies(plane_chain):
    lod0, lods = plane_chain
    assert len(lods) >= 2, f"only {len(lods)} LODs"
    bvh = MeshBvh(lod0.attributes["position"], lod0.triangles)
    t0 = lod0.triangles.astype(np.int64)
    for l, lod in enumerate(lods, 1):
        lod.validate(f"LOD {l}")
        p = lod.attributes["position"]
        n = len(p)
        assert lod.morph_positions.shape == (2, n, 3) and lod.morph_normals.shape == (2, n, 3)
        assert np.abs(p[:, 2]).max() < 1e-6, "a vertex left the plane"
        # Each vertex lies on LOD 0 (a flat plane), so its deltas are LOD 0's barycentric blend
        # at its own position.
        dist, tri, bary = bvh.closest(p)
        assert dist.max() < 1e-6
        for t, name in enumerate(["bump", "tilt"]):
            want = np.einsum("kj,kjc->kc", bary, lod0.morph_positions[t][t0[tri]])
            np.testing.assert_allclose(lod.morph_positions[t], want, atol=2e-6, err_msg=f"LOD {l} {name}")
            want_n = np.einsum("kj,kjc->kc", bary, lod0.morph_normals[t][t0[tri]])
            np.testing.assert_allclose(lod.morph_normals[t], want_n, atol=2e-6, err_msg=f"LOD {l} {name} normals")
        # The linear field comes through exactly: every vertex moves by 0.1 x + 0.05 y.
        np.testing.assert_allclose(lod.morph_positions[1][:, 2], 0.1 * p[:, 0] + 0.05 * p[:, 1], atol=2e-6)
        assert np.abs(lod.morph_positions[:, :, :2]).max() == 0.0


def test_the_plane_s_errors_come_from_the_bump_and_bound_it(plane_chain):
    """At rest the plane is flat and every level is the plane (0 error); the tilt is linear, so
    carried deltas reproduce it exactly (0 error). The bump is what costs error: the stored errors
    must cover the lifted surface, grow as the bump loses vertices, and end the chain (the error
    stop rule) where the rest pose alone would have simplified on."""
    lod0, lods = plane_chain
    diag = float(np.linalg.norm(np.ptp(lod0.attributes["position"], axis=0)))
    errors = [l.error for l in lods]
    assert errors == sorted(errors)
    assert errors[-1] <= PLANE.max_error_fraction * diag
    assert errors[-1] > 0.05, f"the bump (0.3 m) cost little error: {errors}"

    def posed(lod, t):
        p = lod.attributes["position"] + (0.0 if t is None else lod.morph_positions[t])
        return surface(p, lod.triangles)

    for l, lod in enumerate(lods, 1):
        rest = sampled_hausdorff(posed(lod, None), posed(lod0, None), n=40_000, seed=10 + l)
        tilt = sampled_hausdorff(posed(lod, 1), posed(lod0, 1), n=40_000, seed=20 + l)
        bump = sampled_hausdorff(posed(lod, 0), posed(lod0, 0), n=40_000, seed=30 + l)
        print(f"LOD {l} ({lod.triangle_count} triangles): rest {rest:.2e}, tilt {tilt:.2e}, bump {bump:.5f}, stored {lod.error:.5f}")
        assert rest < 1e-5 and tilt < 1e-5, f"LOD {l}: {rest} from the plane at rest, {tilt} tilted"
        assert bump <= lod.error, f"LOD {l} bump: sampled Hausdorff {bump:.6g} > stored error {lod.error:.6g}"
        assert lod.error <= 1.5 * bump + 1e-5, f"LOD {l}: stored error {lod.error:.6g} far above the bump's {bump:.6g}"
    # Without its targets the same plane simplifies further, at no error at all.
    flat = ir.Lod(attributes=dict(lod0.attributes), triangles=lod0.triangles, materials=lod0.materials)
    flat_lods = build_lods(flat, PLANE)
    assert flat_lods[-1].triangle_count < lods[-1].triangle_count
    assert all(l.error < 1e-5 for l in flat_lods)


def test_a_morph_lod_chain_is_deterministic(plane_chain):
    lod0, lods = plane_chain
    again = build_lods(lod0, PLANE)
    assert len(again) == len(lods)
    for a, b in zip(lods, again):
        assert a.error == b.error
        assert np.array_equal(a.morph_positions, b.morph_positions) and np.array_equal(a.morph_normals, b.morph_normals)
