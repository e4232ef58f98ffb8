"""The LOD stage: a chain of simplified meshes per mesh, each with its measured geometric error.

``build_lods(lod0, settings) -> [LOD1, LOD2, ...]`` is a pure function: the same LOD 0 and settings
give the same arrays, bit for bit (the orchestrator caches it by content hash).

How a level is made
-------------------
1. **Weld by position.** glTF and CSG meshes split vertices wherever an attribute changes (UV seams,
   hard normals, material borders): same position, different attributes. Simplifying that mesh
   would let the two sides of a seam move independently and open cracks, so positions are welded
   (bitwise equality) into one connected surface, and the chain is simplified in that welded space
   only. A crack needs two copies of a position; there are none.
2. **Simplify** the previous level (the chain is built level on level, as meshoptimizer advises) to
   half its triangles with ``fast_simplification.simplify(..., return_collapses=True)`` (quadric
   error metric; vertices move to the quadric optimum). Seams on smooth surfaces are kept as chains
   of edges (see ``_simplify``: "flaps" make their vertices fast-simplification borders);
   seams on creases (hard edges of a box) need no help, the quadrics of the two faces keep them.
3. **Track faces through the collapses.** The collapse list ``(i0, i1)`` says ``i1`` merged into
   ``i0``; following it gives each input vertex its surviving vertex, and fast-simplification never
   creates triangles: it deletes the ones that degenerate, keeps the others in order with their
   corner order, and numbers the referenced vertices in order. So every output triangle is a LOD 0
   triangle whose corners moved, and corner j of it descends from corner j of that LOD 0 triangle.
   (``replay_simplification`` computes the same mapping, but replays every collapse and runs a
   Python loop per dropped vertex: about as slow as the simplification itself at 1M triangles.
   The mapping here is checked against fast-simplification's own output on every call.)
4. **Split vertices and carry attributes by walking LOD 0.** For each output corner, walk over
   LOD 0 from the triangle the corner's face descends from toward the corner's (moved) position,
   crossing only edges whose split vertices both faces share (same UV island, smoothing group,
   material and lightmap page), to the closest point reachable that way; the corner's attributes
   are LOD 0's, interpolated there (barycentric). Staying on the start triangle's side means a
   corner gets the values of *its face's* side of a seam: the two copies of a seam vertex get each
   side's values, a pole of a lat-long sphere gets one copy per face, and a face the simplifier
   pushed across a seam gets its own side's values clamped at the seam rather than the other
   side's (which would smear the whole texture across it). Corners that reach the same point of
   LOD 0 share an output vertex; elsewhere a position gets one output vertex per side, like LOD 0.
   (A vertex with no seam vertex among the LOD 0 vertices merged into it has one side only: it is
   walked once, not per corner, from where its survivor's walk ended a level before.) Then normals are renormalised, tangents re-orthonormalised
   (handedness from the nearest corner), colours rounded, and skin weights blended per joint over
   the three corners, the four largest kept and renormalised to sum 1 (joints stay indices LOD 0
   used). Faces keep their material and lightmap page.
5. **Measure the error**: the symmetric Hausdorff distance between the level and LOD 0, estimated
   by sampling both ways in Rust (``MeshBvh.directed_hausdorff``): each triangle on a barycentric
   grid (corners included; LOD 0's with at least 2 and the level's with at least
   ``min_subdivisions`` subdivisions per edge, and no coarser than ``sample_spacing`` LOD 0 mean
   edge lengths), each sample's exact distance to the other mesh, then a local search around the
   largest samples (a grid misses sharp maxima, such as where a simplified edge cuts a crease).
   Stored error = that maximum x (1 + ``error_safety``) + 1e-6 of the bounding-box diagonal
   (float32 resolution), in metres, object space, and never below the previous level's.

Stop rules: each level targets half the previous triangle count (never below the floor); the chain
stops when a step saves less than ``min_saving`` of the triangles, at the floor, at ``max_lods``, or
before a level whose error exceeds ``max_error_fraction`` of LOD 0's bounding-box diagonal.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import fast_simplification
import numpy as np

from asset_pipeline import ir
from asset_pipeline._core import MeshBvh, carry_attributes, face_adjacency, seam_edges, weld_positions


@dataclass(frozen=True)
class LodSettings:
    """Settings of the LOD stage (part of its cache key)."""

    floor_triangles: int = 64  # no level below this many triangles
    floor_fraction: float = 0.0  # ... nor below this fraction of LOD 0's triangles (the larger floor wins)
    min_saving: float = 0.25  # a level must have at most (1 - min_saving) x the previous level's triangles
    max_error_fraction: float = 0.05  # stop before a level whose error exceeds this x LOD 0's bbox diagonal
    max_lods: int = 12  # LOD 1..max_lods at most
    aggressiveness: float = 7.0  # fast-simplification's `agg` (its default; lower = slower, better)
    # Seams (UV, normal, material, page) whose faces meet at less than this dihedral angle are kept
    # as edge chains; sharper ones are creases the quadrics keep anyway. 0 = keep none: lower
    # geometric error, but UVs near seams get clamped where the simplifier crosses them.
    seam_angle_deg: float = 30.0
    error_safety: float = 0.05  # stored error = sampled Hausdorff maximum x (1 + error_safety)
    sample_spacing: float = 2.0  # Hausdorff sample spacing, in LOD 0 mean edge lengths
    min_subdivisions: int = 2  # grid subdivisions per edge of a level's triangles (then a local search)


def build_lods(lod0: ir.Lod, settings: LodSettings = LodSettings()) -> list[ir.Lod]:
    """LOD 1..n of `lod0` (not including it), each with `.error` in metres. Pure and deterministic."""
    lod0.validate("lod0")
    s = settings
    if not (0.0 < s.min_saving < 1.0) or s.max_lods < 0 or s.floor_triangles < 1:
        raise ValueError(f"bad LodSettings: {s}")
    pos0 = lod0.attributes["position"]
    m0 = lod0.triangle_count
    floor = max(int(s.floor_triangles), math.ceil(s.floor_fraction * m0))
    if m0 <= floor or s.max_lods == 0:
        return []
    if not np.isfinite(pos0).all():
        raise ir.IrError("lod0: a position is not finite")

    ctx = _Lod0(lod0)
    used = np.zeros(len(pos0), dtype=bool)
    used[lod0.triangles.ravel()] = True
    diag = float(np.linalg.norm(pos0[used].max(axis=0).astype(np.float64) - pos0[used].min(axis=0)))
    limit = s.max_error_fraction * diag
    spacing = s.sample_spacing * ctx.mean_edge

    lods: list[ir.Lod] = []
    level = ctx.level0
    error = 0.0
    while len(lods) < s.max_lods and level.triangle_count > floor:
        target = max(level.triangle_count // 2, floor)
        new = _simplify(level, target, s.aggressiveness, s.seam_angle_deg)
        if new is None or new.triangle_count > (1.0 - s.min_saving) * level.triangle_count:
            break
        level = new
        lod, near = _split_and_carry(ctx, level)
        level.split = lod.triangles  # the next level finds its seams in this level's splits
        measured = _hausdorff(ctx, lod, near, spacing, s.min_subdivisions)
        error = max(error, measured * (1.0 + s.error_safety) + 1e-6 * diag)
        if error > limit:
            break
        lod.error = error
        lods.append(lod)
    return lods


# ---- LOD 0 ------------------------------------------------------------------------------------


@dataclass
class _Level:
    """A level in welded form, and where its faces came from in LOD 0."""

    points: np.ndarray  # (n, 3) float64
    faces: np.ndarray  # (m, 3) int32; corner j of a face descends from corner j of its LOD 0 face
    face_origin: np.ndarray  # (m,) the LOD 0 face each face descends from
    seamy: np.ndarray  # (n,) bool: a LOD 0 vertex with several split copies was merged into it
    near: np.ndarray  # (n,) uint32 LOD 0 triangle near each vertex, where attribute walks start
    split: np.ndarray | None = None  # (m, 3) uint32 split vertex of each corner (equal ids: equal attributes)

    @property
    def triangle_count(self) -> int:
        return len(self.faces)


class _Lod0:
    """What every level needs from LOD 0: its welded level, face adjacency, a BVH."""

    def __init__(self, lod0: ir.Lod):
        self.lod = lod0
        pos = np.ascontiguousarray(lod0.attributes["position"])
        tri = np.ascontiguousarray(lod0.triangles)
        weld, first = weld_positions(pos)  # welded ids in order of first use: the input's locality
        wf = weld[tri]
        ok = (wf[:, 0] != wf[:, 1]) & (wf[:, 1] != wf[:, 2]) & (wf[:, 0] != wf[:, 2])
        # A welded vertex is on a seam when faces use more than one split copy of it.
        used = np.zeros(len(pos), dtype=bool)
        used[tri.ravel()] = True
        copies = np.bincount(weld[used], minlength=len(first))
        near = np.full(len(first), len(tri), dtype=np.int64)  # the first face around each vertex
        np.minimum.at(near, wf.ravel(), np.repeat(np.arange(len(tri)), 3))
        # Zero-area faces (two corners at one position) go: simplification has no use for them.
        self.level0 = _Level(
            points=pos[first].astype(np.float64),
            faces=np.ascontiguousarray(wf[ok].astype(np.int32)),
            face_origin=np.flatnonzero(ok),
            seamy=copies > 1,
            near=near.astype(np.uint32),
            split=tri[ok],
        )
        # Walks cross edges whose split vertices both faces share, between faces of one material
        # and lightmap page: they stay within a region where attributes are continuous.
        key = lod0.materials
        if lod0.lightmap_pages is not None:
            pages = int(lod0.lightmap_pages.max(initial=0)) + 1
            if int(key.max(initial=0)) < (1 << 32) // pages:
                key = key * np.uint32(pages) + lod0.lightmap_pages
            else:
                key = np.unique(np.stack([key, lod0.lightmap_pages], 1), axis=0, return_inverse=True)[1]
        self.adjacency = face_adjacency(tri, np.ascontiguousarray(key, dtype=np.uint32).ravel())
        a, b, c = (pos[tri[:, k]].astype(np.float64) for k in range(3))
        area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1).sum()
        # Edge of an equilateral triangle of the mean area: LOD 0's sampling scale.
        self.mean_edge = math.sqrt(4.0 * area / (math.sqrt(3.0) * max(int(ok.sum()), 1))) if area > 0 else 0.0

    @functools.cached_property
    def bvh(self) -> MeshBvh:
        """LOD 0's closest-point tree, for measuring errors (built on first use)."""
        return MeshBvh(self.lod.attributes["position"], self.lod.triangles)


# ---- one level --------------------------------------------------------------------------------


def _simplify(level: _Level, target: int, agg: float, seam_angle_deg: float) -> _Level | None:
    """Simplify a welded level to about `target` triangles, keeping its smooth seams as seams.

    Seams (edges where the faces on either side have different split vertices) on a smooth surface
    are invisible to the quadrics, so the simplifier would happily collapse across them, and the
    faces it leaves straddle the seam: their corners then get clamped UVs (see
    ``_split_and_carry``), which stretches the texture near the seam. fast-simplification has no
    vertex locks, but it never collapses a border vertex with a non-border one, and finds borders
    once, before it starts. So each such seam edge (a, b) gets a *flap*: a triangle (a, b, x) with
    a new vertex x above the edge's midpoint along the surface normal. That makes a and b border
    vertices; from then on they only collapse with border vertices (along their seam, to an end
    point or the midpoint), and the flap's plane, perpendicular to the surface through the seam,
    adds the boundary-constraint quadric of Garland & Heckbert against cutting a curved seam's
    corners. The flap is free to remove (x lies on every plane it has), so it collapses in the
    first pass; flaps that remain are dropped from the output. Creases (sharper than
    `seam_angle_deg`) get no flap: their two face planes already make crossing them cost error,
    and border vertices of two creases meeting at a corner could collapse into each other. Nor do
    junctions of three or more seams (the pole of a lat-long UV sphere, where every edge is a
    seam): flaps there would make a whole fan of vertices borders that can hardly collapse.

    Measured (tests' lat-long sphere and skinned cylinder, the benchmark's cube-sphere): flaps keep
    UVs right along seams (the sphere's largest u error: 0.001 with flaps, 0.12 without) for
    about 1.2x (0.7x to 2.4x, worst at the coarsest levels) the geometric error at equal triangle
    count. ``seam_angle_deg=0`` turns them off.
    """
    points, faces = level.points, level.faces
    n, m = len(points), len(faces)
    seams = seam_edges(faces.view(np.uint32), level.split).astype(np.int64)
    edges = seams[:, :2]
    f = faces[seams[:, 2:]]  # (k, 2, 3): the two faces at each seam edge
    fn = np.cross(points[f[..., 1]] - points[f[..., 0]], points[f[..., 2]] - points[f[..., 0]])
    normals = (fn / np.maximum(np.linalg.norm(fn, axis=2, keepdims=True), 1e-300)).sum(axis=1)
    # Two unit normals at dihedral angle t sum to length 2 cos(t / 2).
    smooth = np.linalg.norm(normals, axis=1) > 2.0 * math.cos(math.radians(seam_angle_deg) / 2.0)
    # Only seam chains, not junctions of three or more seams.
    valence = np.bincount(edges.ravel(), minlength=n)
    chain = (valence[edges[:, 0]] <= 2) & (valence[edges[:, 1]] <= 2)
    edges, normals = edges[smooth & chain], normals[smooth & chain]
    if len(edges):
        pa, pb = points[edges[:, 0]], points[edges[:, 1]]
        up = normals / np.linalg.norm(normals, axis=1, keepdims=True)
        tips = 0.5 * (pa + pb) + 0.5 * np.linalg.norm(pb - pa, axis=1, keepdims=True) * up
        points = np.concatenate([points, tips])
        flaps = np.stack([edges[:, 0], edges[:, 1], n + np.arange(len(edges))], 1)
        faces = np.concatenate([faces, flaps.astype(np.int32)])
    out_points, out_faces, collapses = fast_simplification.simplify(
        np.ascontiguousarray(points), np.ascontiguousarray(faces), target_count=int(target), agg=float(agg), return_collapses=True
    )
    # Where each vertex ended up: follow the collapse chains (i1 -> i0) by pointer jumping.
    root = np.arange(len(points), dtype=np.int64)
    if len(collapses):
        root[collapses[:, 1]] = collapses[:, 0]
        while True:
            nxt = root[root]
            if np.array_equal(nxt, root):
                break
            root = nxt
    mapped = root[faces]
    alive = (mapped[:, 0] != mapped[:, 1]) & (mapped[:, 1] != mapped[:, 2]) & (mapped[:, 0] != mapped[:, 2])
    used = np.zeros(len(points), dtype=bool)
    used[mapped[alive].ravel()] = True
    number = np.cumsum(used) - 1
    if not np.array_equal(number[mapped[alive]], out_faces):
        # fast-simplification's numbering changed: the face tracking would be wrong.
        raise RuntimeError("lod: fast_simplification's output does not match its collapse list")
    # The real faces (flaps were appended after them) and the vertices they use. (A flap tip that
    # absorbed a real vertex stands in for it, at its position: it is just a vertex.)
    keep = alive[:m]
    real = mapped[:m][keep]
    if len(real) == 0:
        return None
    used_real = np.zeros(len(points), dtype=bool)
    used_real[real.ravel()] = True
    renumber = np.cumsum(used_real) - 1
    roots = np.flatnonzero(used_real)
    seamy = np.bincount(root[:n], weights=level.seamy, minlength=len(points)) > 0
    # A vertex's walk starts where its survivor's ended (for a flap tip that absorbed vertices:
    # the first of them).
    survivor = roots
    if len(points) > n:
        first = np.full(len(points), n, dtype=np.int64)
        np.minimum.at(first, root[:n], np.arange(n))
        survivor = np.where(roots < n, roots, first[roots])
    return _Level(
        points=np.ascontiguousarray(out_points[number[roots]], dtype=np.float64),
        faces=np.ascontiguousarray(renumber[real], dtype=np.int32),
        face_origin=level.face_origin[keep],
        seamy=seamy[roots],
        near=level.near[survivor],
    )


def _split_and_carry(ctx: _Lod0, level: _Level) -> tuple[ir.Lod, np.ndarray]:
    """The output LOD: split vertices and their attributes (see the module docstring, step 4);
    and for each output vertex, the LOD 0 triangle it was found on. Sets `level.near` to where
    each vertex's walk ended.

    One Rust call (``carry_attributes``, without the GIL). A vertex none of whose merged LOD 0
    vertices was on a seam lies inside one region of continuous attributes, so all its corners
    would walk to the same point: it is walked once (from where its survivor's walk ended a level
    before: a step or two) and becomes one output vertex. Only corners of vertices near seams are
    walked one by one and merged by where they arrive (to 2^-20 in barycentric weights)."""
    lod0 = ctx.lod
    attributes, triangles, near, level.near = carry_attributes(
        lod0.attributes["position"], lod0.triangles, ctx.adjacency, lod0.attributes,
        level.points.astype(np.float32), level.faces.view(np.uint32), level.face_origin.astype(np.uint32),
        level.seamy, level.near,
    )
    origin = level.face_origin
    lod = ir.Lod(
        attributes=attributes,
        triangles=triangles,
        materials=lod0.materials[origin].astype(np.uint32),
        lightmap_pages=None if lod0.lightmap_pages is None else lod0.lightmap_pages[origin].astype(np.uint32),
    )
    return lod, near


# ---- error ------------------------------------------------------------------------------------


def _hausdorff(ctx: _Lod0, lod: ir.Lod, near: np.ndarray, spacing: float, min_subdiv: int) -> float:
    """Sampled symmetric Hausdorff distance between `lod` and LOD 0, in metres (Rust; see
    ``MeshBvh.directed_hausdorff``: grid samples, then a local search around the largest).
    `near` (a LOD 0 triangle near each of the level's vertices) speeds up the level -> LOD 0 side."""
    pos, tri = lod.attributes["position"], lod.triangles
    lod0 = ctx.lod
    # LOD 0 -> level: LOD 0's small triangles, corners and edge midpoints at least (the farthest
    # point of LOD 0 is often inside a triangle, over a ridge of the level).
    a, _, _ = MeshBvh(pos, tri).directed_hausdorff(lod0.attributes["position"], lod0.triangles, spacing, 2)
    # Level -> LOD 0: big triangles, at least `min_subdiv` cells per edge and LOD 0's spacing.
    b, _, _ = ctx.bvh.directed_hausdorff(pos, tri, spacing, min_subdiv, vertex_hints=near.astype(np.uint32))
    return max(a, b)
