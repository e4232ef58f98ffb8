"""The LOD stage (asset_pipeline.lod): triangle counts, stored errors against an independent
Hausdorff estimate, closed seams, valid attributes, materials, determinism."""

from __future__ import annotations

import numpy as np
import pytest

from asset_pipeline import ir
from asset_pipeline._core import MeshBvh
from asset_pipeline.lod import LodSettings, build_lods

# ---- test meshes --------------------------------------------------------------------------------


def _grid_sphere(nlat: int, nlon: int, radius: float = 1.0, bump: float = 0.0):
    """Lat-long sphere: a UV seam at u = 0/1 (duplicated column) and one pole vertex per column."""
    th = np.linspace(0.0, np.pi, nlat + 1)
    ph = np.linspace(0.0, 2.0 * np.pi, nlon + 1)
    T, P = np.meshgrid(th, ph, indexing="ij")
    d = np.stack([np.sin(T) * np.cos(P), np.cos(T), np.sin(T) * np.sin(P)], -1)
    d[:, -1] = d[:, 0]  # the seam column is bitwise the first one
    d[0, :] = d[0, 0]
    d[-1, :] = d[-1, 0]
    r = radius * (1.0 + bump * np.sin(5 * T) * np.cos(4 * P))
    r[:, -1] = r[:, 0]
    r[0, :], r[-1, :] = r[0, 0], r[-1, 0]
    pos = (d * r[..., None]).reshape(-1, 3)
    uv = np.stack([P / (2 * np.pi), T / np.pi], -1).reshape(-1, 2)
    idx = np.arange((nlat + 1) * (nlon + 1)).reshape(nlat + 1, nlon + 1)
    a, b, c, e = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    t1 = np.stack([a, c, b], -1)[:-1].reshape(-1, 3)  # outward winding; (a,c,b) degenerate at the south pole
    t2 = np.stack([a, e, c], -1)[1:].reshape(-1, 3)  # degenerate at the north pole
    tris = np.concatenate([t1, t2])
    normal = d.reshape(-1, 3)
    tangent = np.stack([-np.sin(P), np.zeros_like(P), np.cos(P), np.ones_like(P)], -1).reshape(-1, 4)
    return pos, tris, normal, tangent, uv


def textured_sphere(nlat=40, nlon=80, bump=0.05) -> ir.Lod:
    pos, tris, normal, tangent, uv = _grid_sphere(nlat, nlon, bump=bump)
    color = np.clip((pos * 0.5 + 0.5) * 255, 0, 255)
    color = np.concatenate([color, np.full((len(pos), 1), 255)], 1)
    return ir.Lod(
        attributes={
            "position": pos.astype(np.float32),
            "normal": normal.astype(np.float32),
            "tangent": tangent.astype(np.float32),
            "uv0": uv.astype(np.float32),
            "color": color.astype(np.uint8),
        },
        triangles=tris.astype(np.uint32),
        materials=np.zeros(len(tris), np.uint32),
    )


def two_material_box(n=24) -> ir.Lod:
    """A unit box, each face an n x n grid with its own vertices (hard normals, one UV chart per
    face); the +-x faces use material 1, the rest material 0."""
    pos, nrm, uv, tris, mats = [], [], [], [], []
    base = 0
    g = np.linspace(0.0, 1.0, n + 1)
    U, V = np.meshgrid(g, g, indexing="ij")
    for axis in range(3):
        for side in (0.0, 1.0):
            p = np.zeros((n + 1, n + 1, 3))
            p[..., axis] = side
            p[..., (axis + 1) % 3] = U
            p[..., (axis + 2) % 3] = V
            pos.append(p.reshape(-1, 3) - 0.5)
            nn = np.zeros(3)
            nn[axis] = 1.0 if side else -1.0
            nrm.append(np.tile(nn, ((n + 1) ** 2, 1)))
            uv.append(np.stack([U, V], -1).reshape(-1, 2))
            idx = base + np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
            a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
            t = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
            if not side:
                t = t[:, ::-1]
            tris.append(t)
            mats.append(np.full(len(t), 1 if axis == 0 else 0))
            base += (n + 1) ** 2
    return ir.Lod(
        attributes={
            "position": np.concatenate(pos).astype(np.float32),
            "normal": np.concatenate(nrm).astype(np.float32),
            "uv0": np.concatenate(uv).astype(np.float32),
        },
        triangles=np.concatenate(tris).astype(np.uint32),
        materials=np.concatenate(mats).astype(np.uint32),
    )


def skinned_cylinder(rings=48, segments=40, height=2.0, radius=0.25, bones=5) -> ir.Lod:
    """A capped cylinder along +y with a UV seam, skinned to `bones` joints spaced along its axis
    (each vertex weighted between its two nearest joints), with a little bend so it is not a
    perfect prism."""
    y = np.linspace(0.0, height, rings + 1)
    ph = np.linspace(0.0, 2 * np.pi, segments + 1)
    Y, P = np.meshgrid(y, ph, indexing="ij")
    X, Z = radius * np.cos(P), radius * np.sin(P)
    X = X + 0.1 * np.sin(Y * 2.0)
    X[:, -1], Z[:, -1] = X[:, 0], Z[:, 0]
    side = np.stack([X, Y, Z], -1).reshape(-1, 3)
    side_n = np.stack([np.cos(P), np.zeros_like(P), np.sin(P)], -1).reshape(-1, 3)
    side_uv = np.stack([P / (2 * np.pi), Y / height], -1).reshape(-1, 2)
    idx = np.arange((rings + 1) * (segments + 1)).reshape(rings + 1, segments + 1)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    tris = [np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)]
    pos, nrm, uv = [side], [side_n], [side_uv]
    base = len(side)
    for ring, sgn in ((0, -1.0), (rings, 1.0)):  # caps: own vertices (hard edge), a centre fan
        rim = side.reshape(rings + 1, segments + 1, 3)[ring, :-1]
        centre = np.array([[rim[:, 0].mean(), y[ring], 0.0]])
        cp = np.concatenate([centre, rim])
        pos.append(cp)
        nrm.append(np.tile([0.0, sgn, 0.0], (len(cp), 1)))
        uv.append(cp[:, [0, 2]] * 0.5 + 0.5)
        k = np.arange(segments)
        fan = np.stack([np.zeros(segments, int), 1 + k, 1 + (k + 1) % segments], -1) + base
        tris.append(fan[:, ::-1] if sgn > 0 else fan)
        base += len(cp)
    pos = np.concatenate(pos)
    # Winding: side quads above are (a, b, c) with a at (ring i, seg j), b at ring i+1: outward.
    bone_y = np.linspace(0.0, height, bones)
    t = np.clip(pos[:, 1] / height * (bones - 1), 0, bones - 1 - 1e-9)
    j0 = np.floor(t).astype(int)
    f = t - j0
    joints = np.stack([j0, j0 + 1, np.zeros_like(j0), np.zeros_like(j0)], 1)
    weights = np.stack([1 - f, f, np.zeros_like(f), np.zeros_like(f)], 1)
    assert bone_y.shape == (bones,)
    return ir.Lod(
        attributes={
            "position": pos.astype(np.float32),
            "normal": np.concatenate(nrm).astype(np.float32),
            "uv0": np.concatenate(uv).astype(np.float32),
            "joints": joints.astype(np.uint16),
            "weights": weights.astype(np.float32),
        },
        triangles=np.concatenate(tris).astype(np.uint32),
        materials=np.zeros(sum(len(x) for x in tris), np.uint32),
    )


MESHES = {"textured_sphere": textured_sphere, "two_material_box": two_material_box, "skinned_cylinder": skinned_cylinder}

# ---- independent measurements -------------------------------------------------------------------


def _welded_edges(lod: ir.Lod):
    """Undirected edges of the mesh after welding equal positions, with their face counts."""
    pos = lod.attributes["position"]
    _, weld = np.unique(pos, axis=0, return_inverse=True)
    t = weld.reshape(-1)[lod.triangles.astype(np.int64)]
    e = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    e = np.sort(e, axis=1)
    e = e[e[:, 0] != e[:, 1]]
    return np.unique(e, axis=0, return_counts=True)


def boundary_edges(lod: ir.Lod) -> int:
    _, counts = _welded_edges(lod)
    return int((counts == 1).sum())


def _surface_samples(lod: ir.Lod, n: int, rng: np.random.Generator) -> np.ndarray:
    """The mesh's vertices plus `n` area-weighted uniform random points on its triangles."""
    p = lod.attributes["position"].astype(np.float64)
    t = lod.triangles.astype(np.int64)
    a, b, c = p[t[:, 0]], p[t[:, 1]], p[t[:, 2]]
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    f = rng.choice(len(t), size=n, p=area / area.sum())
    r1, r2 = rng.random(n), rng.random(n)
    s = np.sqrt(r1)
    pts = (1 - s)[:, None] * a[f] + (s * (1 - r2))[:, None] * b[f] + (s * r2)[:, None] * c[f]
    return np.concatenate([p[np.unique(t)], pts]).astype(np.float32)


def sampled_hausdorff(x: ir.Lod, y: ir.Lod, n: int, seed: int) -> float:
    """Symmetric Hausdorff distance between two meshes from random samples, exact closest points."""
    rng = np.random.default_rng(seed)
    dx, _, _ = MeshBvh(y.attributes["position"], y.triangles).closest(_surface_samples(x, n, rng))
    dy, _, _ = MeshBvh(x.attributes["position"], x.triangles).closest(_surface_samples(y, n, rng))
    return float(max(dx.max(), dy.max()))


# ---- tests --------------------------------------------------------------------------------------


@pytest.fixture(scope="module", params=sorted(MESHES))
def chain(request):
    lod0 = MESHES[request.param]()
    return request.param, lod0, build_lods(lod0, LodSettings())


def test_triangle_counts_roughly_halve(chain):
    name, lod0, lods = chain
    assert len(lods) >= 3, f"{name}: only {len(lods)} LODs"
    counts = [lod0.triangle_count] + [l.triangle_count for l in lods]
    for prev, cur in zip(counts, counts[1:]):
        assert cur <= 0.75 * prev, f"{name}: {counts}"
        assert cur >= 0.35 * prev, f"{name}: {counts}"  # about half, not a collapse to nothing
    assert counts[-1] >= LodSettings().floor_triangles


def test_errors_are_monotonic_and_bound_an_independent_hausdorff(chain):
    name, lod0, lods = chain
    errors = [l.error for l in lods]
    assert all(e > 0 for e in errors), errors
    assert errors == sorted(errors), f"{name}: errors not monotonic: {errors}"
    for i, lod in enumerate(lods, 1):
        # Different sampler (random, area-weighted) and density from the stage's own grid.
        h = sampled_hausdorff(lod, lod0, n=60_000, seed=1000 + i)
        assert h <= lod.error, f"{name} LOD{i}: sampled Hausdorff {h:.6g} > stored error {lod.error:.6g}"
        diag = float(np.linalg.norm(np.ptp(lod0.attributes["position"], axis=0)))
        assert lod.error <= 1.5 * h + 2e-6 * diag, f"{name} LOD{i}: stored error {lod.error:.6g} far above {h:.6g}"


def test_no_new_boundary_edges(chain):
    name, lod0, lods = chain
    assert boundary_edges(lod0) == 0
    for i, lod in enumerate(lods, 1):
        assert boundary_edges(lod) == 0, f"{name} LOD{i}: seams or material borders opened"


def test_attributes_valid(chain):
    name, lod0, lods = chain
    for i, lod in enumerate(lods, 1):
        lod.validate(f"{name} LOD{i}")
        assert set(lod.attributes) == set(lod0.attributes)
        assert set(np.unique(lod.materials)) <= set(np.unique(lod0.materials))
        a = lod.attributes
        if "normal" in a:
            np.testing.assert_allclose(np.linalg.norm(a["normal"], axis=1), 1.0, atol=1e-5)
        if "tangent" in a:
            np.testing.assert_allclose(np.linalg.norm(a["tangent"][:, :3], axis=1), 1.0, atol=1e-5)
            assert np.all(np.abs(np.einsum("kc,kc->k", a["tangent"][:, :3], a["normal"])) < 1e-4)
            assert set(np.unique(a["tangent"][:, 3])) <= {-1.0, 1.0}
        if "weights" in a:
            np.testing.assert_allclose(a["weights"].sum(axis=1), 1.0, atol=1e-4)
            assert a["weights"].min() >= 0.0
            assert int(a["joints"].max()) <= int(lod0.attributes["joints"].max())
        if "uv0" in a:
            lo, hi = lod0.attributes["uv0"].min(axis=0), lod0.attributes["uv0"].max(axis=0)
            assert np.all(a["uv0"] >= lo - 1e-6) and np.all(a["uv0"] <= hi + 1e-6)


def test_uv_seams_stay_seams_and_charts_stay_apart():
    """The sphere's UV seam (u = 0 | 1) survives as a split: seam positions carry both u = 0 and
    u = 1 copies, and no triangle spans the seam (which would smear the whole texture across it)."""
    lod0 = textured_sphere()
    for i, lod in enumerate(build_lods(lod0), 1):
        uv = lod.attributes["uv0"][lod.triangles.astype(np.int64)]  # (m, 3, 2)
        span = uv[:, :, 0].max(axis=1) - uv[:, :, 0].min(axis=1)
        assert span.max() < 0.5, f"LOD{i}: a triangle spans {span.max():.2f} of the texture in u"
        # Texture coordinates follow the surface: u is the longitude of the vertex (away from poles).
        p = lod.attributes["position"].astype(np.float64)
        u = lod.attributes["uv0"][:, 0]
        away = np.abs(p[:, 1]) < 0.8
        lon = np.mod(np.arctan2(p[:, 2], p[:, 0]), 2 * np.pi) / (2 * np.pi)
        du = np.abs(u - lon)
        du = np.minimum(du, 1.0 - du)  # seam copies are at 0 or 1
        assert du[away].max() < 0.02, f"LOD{i}: uv drifted {du[away].max():.3f}"


def test_skinned_weights_follow_the_bones():
    lod0 = skinned_cylinder()
    lods = build_lods(lod0)
    for i, lod in enumerate(lods, 1):
        y = lod.attributes["position"][:, 1].astype(np.float64)
        j = lod.attributes["joints"].astype(np.float64)
        w = lod.attributes["weights"].astype(np.float64)
        bone = (j * w).sum(axis=1)  # weighted joint index ~ y / spacing for this rig
        want = np.clip(y / 2.0 * 4, 0, 4)
        assert np.abs(bone - want).max() < 0.35, f"LOD{i}: skin drifted {np.abs(bone - want).max():.3f}"


def test_hard_edges_and_materials_survive():
    lod0 = two_material_box()
    for i, lod in enumerate(build_lods(lod0), 1):
        p = lod.attributes["position"].astype(np.float64)
        n = lod.attributes["normal"].astype(np.float64)
        t = lod.triangles.astype(np.int64)
        fn = np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]])
        area = np.linalg.norm(fn, axis=1)
        keep = area > 1e-9  # the simplifier may leave slivers of zero area on a flat face
        t, fn = t[keep], fn[keep] / area[keep, None]
        # Every corner's normal is its face's (the box stays flat-shaded: no smoothing across edges).
        for k in range(3):
            assert np.all(np.einsum("kc,kc->k", n[t[:, k]], fn) > 0.999), f"LOD{i}"
        # Material 1 is exactly the +-x faces.
        x_face = np.abs(fn[:, 0]) > 0.999
        np.testing.assert_array_equal(lod.materials[keep] == 1, x_face)


def test_deterministic():
    lod0 = textured_sphere(30, 60)
    a, b = build_lods(lod0), build_lods(lod0)
    assert len(a) == len(b)
    for x, y in zip(a, b):
        assert x.error == y.error
        np.testing.assert_array_equal(x.triangles, y.triangles)
        np.testing.assert_array_equal(x.materials, y.materials)
        for k in x.attributes:
            np.testing.assert_array_equal(x.attributes[k], y.attributes[k])


def test_serial_turns_give_the_same_chain(monkeypatch):
    """lod.SERIAL (the benchmark's one-thread-at-a-time mode: the caller waits for each level's
    carrying and measuring) changes when work runs, never what comes out."""
    from asset_pipeline import lod as lod_module

    lod0 = textured_sphere(30, 60)
    a = build_lods(lod0)
    monkeypatch.setattr(lod_module, "SERIAL", True)
    b = build_lods(lod0)
    assert len(a) == len(b) >= 3
    for x, y in zip(a, b):
        assert x.error == y.error
        np.testing.assert_array_equal(x.triangles, y.triangles)
        for k in x.attributes:
            np.testing.assert_array_equal(x.attributes[k], y.attributes[k])


def test_chains_in_flight_give_the_same_lods():
    """start_lods for several meshes at once (the cook's LOD stage keeps a few in flight),
    finished later in any order: each mesh's LODs are what build_lods makes of it alone."""
    from asset_pipeline.lod import start_lods

    meshes = [textured_sphere(30, 60), two_material_box(16), skinned_cylinder(24, 20), textured_sphere(20, 40, bump=0.1)]
    alone = [build_lods(m) for m in meshes]
    started = [start_lods(m) for m in meshes]
    together = [started[i].finish() for i in (2, 0, 3, 1)]
    for i, lods in zip((2, 0, 3, 1), together):
        assert len(lods) == len(alone[i]) >= 2
        for x, y in zip(lods, alone[i]):
            assert x.error == y.error
            np.testing.assert_array_equal(x.triangles, y.triangles)
            np.testing.assert_array_equal(x.materials, y.materials)
            for k in y.attributes:
                np.testing.assert_array_equal(x.attributes[k], y.attributes[k])


def test_stop_rules():
    lod0 = textured_sphere(30, 60)
    m = lod0.triangle_count
    # The floor: no level below it.
    lods = build_lods(lod0, LodSettings(floor_triangles=m // 5))
    assert lods and all(l.triangle_count >= m // 5 for l in lods)
    # The error limit: nothing above it.
    limit = 0.01
    diag = float(np.linalg.norm(np.ptp(lod0.attributes["position"], axis=0)))
    lods = build_lods(lod0, LodSettings(max_error_fraction=limit))
    assert all(l.error <= limit * diag for l in lods)
    assert len(lods) < len(build_lods(lod0))
    # max_lods, and a mesh already at the floor.
    assert len(build_lods(lod0, LodSettings(max_lods=2))) == 2
    assert build_lods(lod0, LodSettings(floor_triangles=m)) == []


def test_lightmap_blocks_and_uv1_are_carried():
    lod0 = two_material_box(12)
    m = lod0.triangle_count
    pages = (np.arange(m) >= m // 2).astype(np.uint32)  # two pages, split along face order
    lod0 = ir.Lod({**lod0.attributes, "uv1": lod0.attributes["uv0"] * 0.5}, lod0.triangles, lod0.materials, pages)
    for lod in build_lods(lod0):
        lod.validate("lod")
        assert lod.lightmap_blocks is not None and set(np.unique(lod.lightmap_blocks)) <= {0, 1}


def test_open_and_messy_input():
    """An open patch (a border that must stay a border, not grow), with zero-area triangles, a
    duplicated triangle and unused vertices in the input: valid LODs, no new border edges."""
    n = 40
    g = np.linspace(0.0, 1.0, n + 1)
    X, Z = np.meshgrid(g, g, indexing="ij")
    pos = np.stack([X, 0.1 * np.sin(4 * X) * np.cos(3 * Z), Z], -1).reshape(-1, 3)
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    tris = np.concatenate([np.stack([a, c, b], -1).reshape(-1, 3), np.stack([a, d, c], -1).reshape(-1, 3)])
    extra = len(pos)
    pos = np.concatenate([pos, pos[:3], [[5.0, 5.0, 5.0]]])  # copies of 3 vertices + an unused one
    tris = np.concatenate([tris, [[0, extra, 1], [extra + 1, extra + 1, 2]], tris[:1]])  # degenerate x2, duplicate
    lod0 = ir.Lod({"position": pos.astype(np.float32)}, tris.astype(np.uint32), np.zeros(len(tris), np.uint32))
    lods = build_lods(lod0)
    assert len(lods) >= 3
    border0 = boundary_edges(lod0)
    for i, lod in enumerate(lods, 1):
        lod.validate(f"LOD{i}")
        assert boundary_edges(lod) <= border0, f"LOD{i}"
        assert np.isfinite(lod.error) and lod.error > 0


def test_tiny_and_bad_input():
    tri = ir.Lod({"position": np.eye(3, dtype=np.float32)}, np.array([[0, 1, 2]], np.uint32), np.zeros(1, np.uint32))
    assert build_lods(tri) == []  # below the floor: nothing to do
    bad = textured_sphere(10, 20)
    bad.attributes["position"][5, 1] = np.nan
    with pytest.raises(ir.IrError, match="not finite"):
        build_lods(bad)
    with pytest.raises(ValueError):
        build_lods(textured_sphere(10, 20), LodSettings(min_saving=0.0))


def test_without_seam_flaps_uvs_clamp_but_stay_on_their_side():
    """seam_angle_deg=0 lets the simplifier cross UV seams (lower geometric error); corners across
    a seam then get their face's side of it, so no triangle spans the texture."""
    lod0 = textured_sphere()
    for i, lod in enumerate(build_lods(lod0, LodSettings(seam_angle_deg=0.0)), 1):
        uv = lod.attributes["uv0"][lod.triangles.astype(np.int64)]
        span = uv[:, :, 0].max(axis=1) - uv[:, :, 0].min(axis=1)
        assert span.max() < 0.5, f"LOD{i}: a triangle spans {span.max():.2f} of the texture in u"
        assert boundary_edges(lod) == 0


def test_closest_points_binding_matches_brute_force():
    lod = textured_sphere(8, 16, bump=0.1)
    p = lod.attributes["position"].astype(np.float64)
    t = lod.triangles.astype(np.int64)
    rng = np.random.default_rng(3)
    q = rng.normal(size=(200, 3)).astype(np.float32) * 0.8
    dist, tri, bary = MeshBvh(lod.attributes["position"], lod.triangles).closest(q, np.zeros(len(q), np.uint32))
    # The reported point is on the reported triangle at the reported distance ...
    at = np.einsum("kj,kjc->kc", bary, p[t[tri]])
    np.testing.assert_allclose(np.linalg.norm(at - q, axis=1), dist, rtol=1e-9, atol=1e-9)
    # ... and no triangle is closer (brute force over a fine barycentric grid of every triangle).
    w = np.array([(i / 12, j / 12, 1 - (i + j) / 12) for i in range(13) for j in range(13 - i)])
    cloud = np.einsum("gj,mjc->mgc", w, p[t]).reshape(-1, 3)
    brute = np.sqrt(((q[:, None, :].astype(np.float64) - cloud[None]) ** 2).sum(-1)).min(1)
    assert np.all(dist <= brute + 1e-9)
