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
   ``track_collapses``, in Rust, follows the list, checks the mapping against fast-simplification's
   own output on every call, and takes the seams along: an edge's ends go where they collapsed.)
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
   walked once, not per corner, from where its survivor's walk ended a level before.) Then
   normals are renormalised, tangents re-orthonormalised (handedness from the nearest corner),
   colours rounded, and skin weights blended per joint over the three corners, the four largest
   kept and renormalised to sum 1 (joints stay indices LOD 0 used). Morph targets come along the
   same way, per target: a vertex's position deltas are LOD 0's blended at its point (so at any
   weight it moves as LOD 0's surface moves there), its normal deltas blended and divided by the
   length of the blended normal, the factor its normal was renormalised by (so ``n + w dn``
   points where LOD 0's blended ``n + w dn`` does, at every weight ``w``). Faces keep their
   material and lightmap page. (Rust: ``cook_core::lod``.)
5. **Measure the error**: the symmetric Hausdorff distance between the level and LOD 0, estimated
   by sampling both ways in Rust (``cook_core::lod::level_error``): each triangle on a barycentric
   grid (corners included; the level's with at least ``min_subdivisions`` subdivisions per edge,
   LOD 0's small ones at their corners, and none coarser than ``sample_spacing`` LOD 0 mean
   edge lengths), each sample's exact distance to the other mesh, then a local search around the
   largest samples (a grid misses sharp maxima, such as where a simplified edge cuts a crease).
   A mesh with morph targets is measured in several poses, at rest and with each target at
   weight 1 (the level's positions plus its carried deltas against LOD 0's plus its own), and the
   largest counts: the simplifier only sees the rest pose, and a target that swells a region the
   rest pose let it flatten shows its error there. (Weights in between and mixes of targets are not
   measured; the displacement is linear in the weights, so they stay near these.)
   Stored error = that maximum x (1 + ``error_safety``) + 1e-6 of the bounding-box diagonal
   (float32 resolution), in metres, object space, and never below the previous level's.

Steps 1 to 3 run on the calling thread; 4 and 5 on a Rust thread (``LodChain``), level by level
as they are made, so carrying and measuring overlap the simplification of the next level.

Stop rules: each level targets half the previous triangle count (never below the floor); the chain
stops when a step saves less than ``min_saving`` of the triangles, at the floor, at ``max_lods``, or
before a level whose error exceeds ``max_error_fraction`` of LOD 0's bounding-box diagonal.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import fast_simplification
import numpy as np

from asset_pipeline import ir
from asset_pipeline._core import LodChain, edge_faces, track_collapses, weld_lod0


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
    # Keep every open-border vertex where it is, at every level (fast-simplification's
    # preserve_border: no collapse touches a border vertex, so no border edge changes). For the
    # pieces of a mesh cut apart (level chunks): two neighbours' shared border then stays the same
    # chain of edges in each of their chains, whatever LOD each is drawn at, so no crack opens
    # between them. Seam flaps make their seam's vertices borders too, so with it flapped seams
    # keep all their vertices (less reduction along smooth seams, never a moved seam).
    lock_borders: bool = False


# Benchmarks switch this off to time the stage without its error measurement (every level then
# measures 0, so the error stop rule never applies).
MEASURE_ERRORS = True
# Benchmarks set this (with RAYON_NUM_THREADS=1) to compare thread for thread with the
# single-threaded simplifier: the caller then waits for each level to be carried and measured
# before it simplifies the next, so one thread works at a time. Same result either way.
SERIAL = False


def build_lods(lod0: ir.Lod, settings: LodSettings = LodSettings()) -> list[ir.Lod]:
    """LOD 1..n of `lod0` (not including it), each with `.error` in metres. Pure and deterministic.

    Two threads: this one simplifies level after level (fast-simplification holds the GIL); a
    Rust thread (``LodChain``) carries attributes to each level and measures its error as soon
    as it is made. Simplification never waits for carrying: seams are tracked through the
    collapses, not found again in each level's split vertices. The error stop rule is applied
    when the measurements are in; levels simplified past it meanwhile are dropped, so the result
    does not depend on timing."""
    return start_lods(lod0, settings).finish()


class PendingLods:
    """A mesh's LODs being carried and measured on their chain's thread (see `start_lods`)."""

    def __init__(self, finish):
        self._finish = finish

    def finish(self) -> list[ir.Lod]:
        """Wait for the chain's thread; the LODs `build_lods` returns."""
        return self._finish()


def start_lods(lod0: ir.Lod, settings: LodSettings = LodSettings()) -> PendingLods:
    """`build_lods` in two halves: this one simplifies every level and queues it to the chain's
    thread; `.finish()` waits for their carrying and measuring. A caller with many meshes starts
    the next mesh's simplification while the meshes before are still measured (a small mesh's
    chain otherwise leaves a core idle: its levels are made in a moment, then measured while this
    thread waits). Bad input raises here, as from `build_lods`."""
    lod0.validate("lod0")
    s = settings
    if not (0.0 < s.min_saving < 1.0) or s.max_lods < 0 or s.floor_triangles < 1:
        raise ValueError(f"bad LodSettings: {s}")
    pos0 = lod0.attributes["position"]
    m0 = lod0.triangle_count
    floor = max(int(s.floor_triangles), math.ceil(s.floor_fraction * m0))
    if m0 <= floor or s.max_lods == 0:
        return PendingLods(list)
    if not np.isfinite(pos0).all():
        raise ir.IrError("lod0: a position is not finite")

    ctx = _Lod0(lod0)
    limit = s.max_error_fraction * ctx.diagonal

    def stored(measured: float) -> float:
        return measured * (1.0 + s.error_safety) + 1e-6 * ctx.diagonal

    chain = LodChain(
        np.ascontiguousarray(pos0), np.ascontiguousarray(lod0.triangles), _walk_keys(lod0), lod0.attributes,
        ctx.near0, MEASURE_ERRORS, float(s.sample_spacing), int(s.min_subdivisions),
        None if lod0.morph_positions is None else np.ascontiguousarray(lod0.morph_positions),
        None if lod0.morph_normals is None else np.ascontiguousarray(lod0.morph_normals),
    )
    origins = []  # each level's face origins (its faces' materials and pages)
    level = ctx.level0
    while len(origins) < s.max_lods and level.triangle_count > floor:
        if any(stored(e) > limit for e in chain.errors()):
            break  # a level already measured is past the limit: the chain ends there
        target = max(level.triangle_count // 2, floor)
        new = _simplify(level, target, s.aggressiveness, s.seam_angle_deg, s.lock_borders)
        if new is None or new.triangle_count > (1.0 - s.min_saving) * level.triangle_count:
            break
        level = new
        chain.submit(level.points.astype(np.float32), level.faces.view(np.uint32), level.face_origin.astype(np.uint32), level.seamy, level.survivor)
        if SERIAL:
            chain.wait()
        origins.append(level.face_origin)
    return PendingLods(lambda: _finished(lod0, chain, origins, stored, limit))


def _finished(lod0: ir.Lod, chain: LodChain, origins: list, stored, limit: float) -> list[ir.Lod]:
    """The chain's levels up to the error limit, as `ir.Lod`s."""
    lods: list[ir.Lod] = []
    error = 0.0
    for (attributes, triangles, measured, morph_positions, morph_normals), origin in zip(chain.finish(), origins):
        error = max(error, stored(measured))
        if error > limit:
            break
        lods.append(ir.Lod(
            attributes={k: attributes[k] for k in lod0.attributes},  # the input's attribute order
            triangles=triangles,
            materials=lod0.materials[origin].astype(np.uint32),
            lightmap_blocks=None if lod0.lightmap_blocks is None else lod0.lightmap_blocks[origin].astype(np.uint32),
            error=error,
            morph_positions=morph_positions,
            morph_normals=morph_normals,
        ))
    return lods


# ---- LOD 0 ------------------------------------------------------------------------------------


@dataclass
class _Level:
    """A level in welded form, and where its faces came from in LOD 0."""

    points: np.ndarray  # (n, 3) float64
    faces: np.ndarray  # (m, 3) int32; corner j of a face descends from corner j of its LOD 0 face
    face_origin: np.ndarray  # (m,) the LOD 0 face each face descends from
    seamy: np.ndarray  # (n,) bool: a LOD 0 vertex with several split copies was merged into it
    seams: np.ndarray  # (k, 2) uint32 vertex pairs: the edges on seams (UV, normal, material, page)
    survivor: np.ndarray | None = None  # (n,) uint32 vertex of the level before each one's walk starts from

    @property
    def triangle_count(self) -> int:
        return len(self.faces)


class _Lod0:
    """LOD 0 welded by position, as simplification starts from it (Rust: ``cook_core::lod::weld``)."""

    def __init__(self, lod0: ir.Lod):
        points, faces, origin, seamy, seams, self.near0, self.diagonal = weld_lod0(
            np.ascontiguousarray(lod0.attributes["position"]), np.ascontiguousarray(lod0.triangles)
        )
        self.level0 = _Level(points=points.astype(np.float64), faces=faces.view(np.int32), face_origin=origin, seamy=seamy, seams=seams)


def _walk_keys(lod0: ir.Lod) -> np.ndarray:
    """A key per face: walks cross edges whose split vertices both faces share, between faces of
    one material and lightmap page, so they stay within a region where attributes are continuous."""
    key = lod0.materials
    if lod0.lightmap_blocks is not None:
        pages = int(lod0.lightmap_blocks.max(initial=0)) + 1
        if int(key.max(initial=0)) < (1 << 32) // pages:
            key = key * np.uint32(pages) + lod0.lightmap_blocks
        else:
            key = np.unique(np.stack([key, lod0.lightmap_blocks], 1), axis=0, return_inverse=True)[1]
    return np.ascontiguousarray(key, dtype=np.uint32).ravel()


# ---- one level --------------------------------------------------------------------------------


def _simplify(level: _Level, target: int, agg: float, seam_angle_deg: float, lock_borders: bool = False) -> _Level | None:
    """Simplify a welded level to about `target` triangles, keeping its smooth seams as seams.

    Seams (edges where the faces on either side have different split vertices) on a smooth surface
    are invisible to the quadrics, so the simplifier would happily collapse across them, and the
    faces it leaves straddle the seam: their corners then get clamped UVs (see
    ``cook_core::lod::split``), which stretches the texture near the seam. fast-simplification has no
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

    The new level's seams are the old ones where the collapses took them (an edge whose ends
    merged is gone; one that is no longer an edge of two faces is dropped).

    Measured (tests' lat-long sphere and skinned cylinder, the benchmark's cube-sphere): flaps keep
    UVs right along seams (the sphere's largest u error: 0.001 with flaps, 0.12 without) for
    about 1.2x (0.7x to 2.4x, worst at the coarsest levels) the geometric error at equal triangle
    count. ``seam_angle_deg=0`` turns them off.
    """
    points, faces = level.points, level.faces
    n, m = len(points), len(faces)
    on = edge_faces(faces.view(np.uint32), level.seams)
    two = on[:, 0] != 0xFFFFFFFF  # (seams that are no longer edges of two faces are dropped)
    seams, on = np.ascontiguousarray(level.seams[two]), on[two]
    edges = seams.astype(np.int64)
    f = faces[on]  # (k, 2, 3): the two faces at each seam edge
    fn = np.cross(points[f[..., 1]] - points[f[..., 0]], points[f[..., 2]] - points[f[..., 0]])
    normals = (fn / np.maximum(np.linalg.norm(fn, axis=2, keepdims=True), 1e-300)).sum(axis=1)
    # Two unit normals at dihedral angle t sum to length 2 cos(t / 2).
    smooth = np.linalg.norm(normals, axis=1) > 2.0 * math.cos(math.radians(seam_angle_deg) / 2.0)
    # Only seam chains, not junctions of three or more seams.
    valence = np.bincount(edges.ravel(), minlength=n)
    chain = (valence[edges[:, 0]] <= 2) & (valence[edges[:, 1]] <= 2)
    flapped, normals = edges[smooth & chain], normals[smooth & chain]
    if len(flapped):
        pa, pb = points[flapped[:, 0]], points[flapped[:, 1]]
        up = normals / np.linalg.norm(normals, axis=1, keepdims=True)
        tips = 0.5 * (pa + pb) + 0.5 * np.linalg.norm(pb - pa, axis=1, keepdims=True) * up
        points = np.concatenate([points, tips])
        flaps = np.stack([flapped[:, 0], flapped[:, 1], n + np.arange(len(flapped))], 1)
        faces = np.concatenate([faces, flaps.astype(np.int32)])
    out_points, out_faces, collapses = fast_simplification.simplify(
        np.ascontiguousarray(points), np.ascontiguousarray(faces), target_count=int(target), agg=float(agg), return_collapses=True,
        preserve_border=bool(lock_borders),
    )
    if len(collapses) == 0:
        collapses = np.zeros((0, 2), dtype=np.int32)
    new_faces, kept, rows, seamy, seams, survivor = track_collapses(
        np.ascontiguousarray(faces).view(np.uint32), m, np.ascontiguousarray(collapses, dtype=np.int32).view(np.uint32),
        np.ascontiguousarray(out_faces, dtype=np.int32).view(np.uint32), level.seamy, seams,
    )
    if len(new_faces) == 0:
        return None
    return _Level(
        points=np.ascontiguousarray(out_points[rows], dtype=np.float64),
        faces=new_faces.view(np.int32),
        face_origin=level.face_origin[kept],
        seamy=seamy,
        seams=seams,
        survivor=survivor,
    )
