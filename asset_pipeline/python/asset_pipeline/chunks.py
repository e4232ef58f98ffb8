"""Level chunks: large static meshes cut into spatial pieces, each a mesh and instance of its own.

``split_chunks(scene, settings) -> (scene, stats)`` is a pure function: the same scene and
settings give the same chunks, bit for bit. A CSG level's meshes are whole buildings (the temple
is one mesh of 2542 triangles, 24 m across), which the runtime can only cull, occlude and pick a
LOD for as a whole. Cut into chunks, each an ordinary static instance with its own bounds and
LOD chain, they are culled and simplified piece by piece. The runtime needs no change.

What is split
-------------
A mesh is split when every node placing it is static (and there is one), it has no morph targets
and no spawn names it (a flock's bird), it has at least ``min_mesh_triangles`` triangles, and its
bounding box is more than ``size`` metres long along some axis (in the world: object units times
the largest uniform scale it is placed at). Props and small meshes stay whole.

How a mesh is cut
-----------------
Whole triangles are partitioned, none is cut: the chunks' triangles together are the mesh's,
with the same vertices bit for bit.

1. **Long triangles apart.** A triangle longer than ``size`` along some axis would stretch the
   bounds of any chunk it joins to its own length (CSG meshes have many: a wall's two triangles
   span the whole wall). They become one chunk of their own (chunk 0), split only to stay within
   ``max_triangles``, so the other chunks' bounds stay near ``size``. (When fewer than
   ``min_triangles`` are long, or fewer than that would be left, they stay with the others.)
2. **Cut the rest in two, again and again,** by triangle centroid: a piece whose centroids span
   more than ``size`` along an axis, or that holds more than ``max_triangles`` triangles, is cut
   across the axis where its centroids spread most. The span is seen as n = ceil(span / size)
   equal cells and the cut falls between cell n // 2 and the next (centroids on it go to the low
   side), so pieces end near ``size`` rather than down to half of it (a 20 m span gives three
   cells of 6.7 m); a piece within ``size`` but over the triangle budget is cut at its
   midpoint. A cut that would leave fewer than ``min_triangles`` triangles on a side is tried at
   the midpoint instead, and if that too is lopsided the piece stays whole.

Chunks are numbered in that order (the long triangles first, then depth first, low side before
high). Each chunk keeps its triangles in the mesh's order and only the vertices they use, in the
mesh's order, with all their attributes (lightmap UVs included), and each face its material and
lightmap block.

Into the scene
--------------
The mesh's slot holds chunk 0 (``<mesh>#0``) and chunks 1.. are appended (``<mesh>#k``), so no
other mesh index moves (nodes and spawns keep theirs). Every node that placed the mesh keeps its
name, parent, transform and static flag but no longer draws anything; it gets one child per chunk
(``<node>#k``, appended after every other node, identity transform, so its world matrix is the
node's bit for bit), static, with the node's lightmap region. The chunks share that region: each
keeps its vertices' lightmap UVs, so a point on the border between two chunks reads the same
texels from both. That is why this stage runs after the bake (pipeline.py): the pages are baked,
denoised and stitched from the whole mesh exactly as without chunks, and the LOD stage runs after
this one, simplifying chunk meshes with ``LodSettings(lock_borders=True)`` so two neighbours'
shared border stays the same chain of edges at any LODs.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from asset_pipeline import ir
from asset_pipeline._core import CookError

IDENTITY = (1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0)


@dataclass(frozen=True)
class ChunkSettings:
    """Settings of the chunk stage (part of its cache key). ``size`` is in world metres."""

    size: float = 8.0  # split while a piece's centroids span more than this (and set apart triangles longer than it)
    max_triangles: int = 4096  # ... or while it holds more triangles than this
    min_triangles: int = 32  # no cut leaves fewer triangles than this on a side
    min_mesh_triangles: int = 1024  # meshes with fewer triangles stay whole

    def check(self) -> None:
        """A one-line CookError naming the first bad setting (and its `cook` option, if it has one)."""
        try:
            size = float(self.size)
        except (TypeError, ValueError):
            size = math.nan
        if isinstance(self.size, bool) or not (math.isfinite(size) and size > 0):
            raise CookError(f"chunk settings: size (--chunk-size) must be a positive number of metres, got {self.size!r}")
        for name, least in (("max_triangles", 1), ("min_triangles", 1), ("min_mesh_triangles", 0)):
            v = getattr(self, name)
            if not isinstance(v, (int, np.integer)) or isinstance(v, bool) or v < least:
                option = " (--chunk-triangles)" if name == "max_triangles" else ""
                raise CookError(f"chunk settings: {name}{option} must be a whole number >= {least}, got {v!r}")
        if self.max_triangles < 2 * self.min_triangles:
            raise CookError(f"chunk settings: max_triangles (--chunk-triangles) {self.max_triangles} is below twice "
                            f"min_triangles ({self.min_triangles}): a piece over it could not be cut")


# ---- the partition ------------------------------------------------------------------------------


def _halves(centroids: np.ndarray, idx: np.ndarray, size: float, s: ChunkSettings) -> list[np.ndarray]:
    """Triangles `idx` (ascending) cut in two by centroid, again and again, until each piece's
    centroids span at most `size` and it holds at most `max_triangles` (or a cut would leave a
    side below `min_triangles`). Pieces depth first, low side first, each ascending."""
    out: list[np.ndarray] = []
    stack = [idx]
    while stack:
        piece = stack.pop()
        c = centroids[piece]
        lo, hi = c.min(axis=0), c.max(axis=0)
        axis = int(np.argmax(hi - lo))
        span = float(hi[axis] - lo[axis])
        if span <= size and len(piece) <= s.max_triangles:
            out.append(piece)
            continue
        # The span in n equal cells of at most `size`, cut between cell n // 2 and the next: the
        # pieces come out near `size` (halving a 60 m span would end at 3.75 m, cells at 7.5 m).
        n = math.ceil(span / size) if span > size else 2
        cuts = [lo[axis] + span * (n // 2) / n, 0.5 * (lo[axis] + hi[axis])]  # the midpoint if that cut is lopsided
        for cut in cuts:
            low = c[:, axis] <= cut
            n_low = int(low.sum())
            if s.min_triangles <= n_low <= len(piece) - s.min_triangles:
                stack += [piece[~low], piece[low]]  # the low side is popped first
                break
        else:
            out.append(piece)
    return out


def partition(positions: np.ndarray, triangles: np.ndarray, size: float, settings: ChunkSettings) -> np.ndarray:
    """The chunk of every triangle, (m,) uint32, chunks numbered 0.. (see the module's "How a
    mesh is cut"); `size` in the mesh's own units."""
    s = settings
    corners = positions.astype(np.float64)[triangles.astype(np.int64)]  # (m, 3, 3)
    centroids = corners.mean(axis=1)
    long = (corners.max(axis=1) - corners.min(axis=1)).max(axis=1) > size
    everything = np.arange(len(triangles))
    n_long = int(long.sum())
    if n_long >= s.min_triangles and len(triangles) - n_long >= s.min_triangles:
        pieces = _halves(centroids, everything[long], math.inf, s) + _halves(centroids, everything[~long], size, s)
    else:
        pieces = _halves(centroids, everything, size, s)
    labels = np.empty(len(triangles), np.uint32)
    for k, piece in enumerate(pieces):
        labels[piece] = k
    return labels


def cut(lod: ir.Lod, labels: np.ndarray) -> list[ir.Lod]:
    """`lod` cut by `labels` (chunk per triangle): per chunk its triangles in `lod`'s order, the
    vertices they use in `lod`'s order with every attribute, materials and lightmap blocks."""
    order = np.argsort(labels, kind="stable")  # each chunk's triangles stay ascending
    ends = np.cumsum(np.bincount(labels, minlength=int(labels.max(initial=0)) + 1))
    out = []
    for a, b in zip(np.concatenate([[0], ends[:-1]]), ends):
        sel = order[a:b]
        used, local = np.unique(lod.triangles[sel], return_inverse=True)
        out.append(ir.Lod(
            attributes={k: np.ascontiguousarray(v[used]) for k, v in lod.attributes.items()},
            triangles=np.ascontiguousarray(local.reshape(-1, 3).astype(np.uint32)),
            materials=np.ascontiguousarray(lod.materials[sel]),
            lightmap_blocks=None if lod.lightmap_blocks is None else np.ascontiguousarray(lod.lightmap_blocks[sel]),
        ))
    return out


# ---- the scene ----------------------------------------------------------------------------------


@dataclass
class Candidate:
    """A mesh that may be split: its index, the nodes placing it and its size in its own units."""

    mesh: int
    nodes: list[int]
    size: float  # settings.size in the mesh's units (metres / the largest scale it is placed at)


def candidates(scene: ir.Scene, settings: ChunkSettings) -> list[Candidate]:
    """The meshes to split (see the module's "What is split"), in mesh order."""
    from asset_pipeline.pipeline import uniform_scale

    world = scene.world_matrices()
    placing: dict[int, list[int]] = {}
    for k, n in enumerate(scene.nodes):
        if n.mesh is not None:
            placing.setdefault(n.mesh, []).append(k)
    named = {sp.params.get("mesh") for sp in scene.spawns}
    out = []
    for i, nodes in sorted(placing.items()):
        m = scene.meshes[i]
        base = m.base
        if (i in named or base.morph_positions is not None or base.triangle_count < settings.min_mesh_triangles
                or not all(scene.nodes[k].static and scene.nodes[k].skin is None for k in nodes)):
            continue
        size = settings.size / max(uniform_scale(world[k]) for k in nodes)
        p = base.attributes["position"]
        # (Non-finite positions are left for the LOD stage to refuse.)
        if base.vertex_count and np.isfinite(p).all() and float((p.max(axis=0).astype(np.float64) - p.min(axis=0)).max()) > size:
            out.append(Candidate(i, nodes, size))
    return out


def partition_key(c: Candidate, base: ir.Lod, settings: ChunkSettings) -> str:
    """A mesh's partition's cache key: the settings, its size in its units, positions and triangles."""
    from asset_pipeline.cache import Hasher

    return (Hasher("chunks").settings(dataclasses.asdict(settings)).text(repr(float(c.size)))
            .array(base.attributes["position"]).array(base.triangles).key())


def split_chunks(scene: ir.Scene, settings: ChunkSettings | None = None, *, cache=None, advance=None) -> tuple[ir.Scene, dict]:
    """The scene with its large static meshes cut into chunks (see the module's docstring), and
    what was done: ``{"meshes": [per split mesh: name, nodes, triangles, chunk triangles and
    extents]}, "chunk_meshes": [mesh indices of every chunk], "items": meshes considered,
    "cached": partitions from the cache}``. `cache`: a StageCache keeping each mesh's partition;
    `advance()`: called once per mesh considered."""
    s = settings or ChunkSettings()
    s.check()
    meshes, nodes = list(scene.meshes), list(scene.nodes)
    todo = candidates(scene, s)
    stats: dict = {"settings": dataclasses.asdict(s), "meshes": [], "chunk_meshes": [], "items": len(todo), "cached": 0}
    children = []  # (node, chunk mesh indices), node order
    for c in todo:
        mesh = scene.meshes[c.mesh]
        base = mesh.base
        key = partition_key(c, base, s) if cache is not None else None
        hit = cache.load("chunks", key) if cache is not None else None
        labels = hit[1][0] if hit is not None and len(hit[1]) == 1 else None
        if labels is not None and labels.dtype == np.uint32 and labels.shape == (base.triangle_count,) and np.bincount(labels).all():
            stats["cached"] += 1
        else:
            labels = partition(base.attributes["position"], base.triangles, c.size, s)
            if cache is not None:
                cache.store("chunks", key, {}, [labels])
        if advance is not None:
            advance()
        if int(labels.max(initial=0)) == 0:
            continue  # one piece: the mesh stays as it is
        pieces = cut(base, labels)
        index = [c.mesh] + list(range(len(meshes), len(meshes) + len(pieces) - 1))
        # Each chunk's coordinates are stored over the whole mesh's bounds: a vertex on a cut is
        # stored alike in the chunks either side of it (pack::vertex; no lightmap seam).
        bounds = ir.uv_bounds(base) if mesh.uv_bounds is None else mesh.uv_bounds
        chunk_meshes = [ir.Mesh(name=f"{mesh.name}#{k}", lods=[lod], texels_per_metre=mesh.texels_per_metre, uv_bounds=bounds)
                        for k, lod in enumerate(pieces)]
        meshes[c.mesh] = chunk_meshes[0]
        meshes += chunk_meshes[1:]
        children += [(k, index) for k in c.nodes]
        stats["chunk_meshes"] += index
        stats["meshes"].append({
            "mesh": mesh.name, "nodes": [scene.nodes[k].name for k in c.nodes], "triangles": base.triangle_count,
            "chunks": len(pieces), "chunk_triangles": [p.triangle_count for p in pieces],
            # Each chunk's bounding box's longest side in metres (at the largest scale the mesh is placed at).
            "chunk_extents": [float(np.ptp(p.attributes["position"].astype(np.float64), axis=0).max()) * s.size / c.size for p in pieces],
        })
    for k, index in sorted(children):
        node = nodes[k]
        nodes[k] = dataclasses.replace(node, mesh=None, lightmap=None)
        nodes += [dataclasses.replace(node, name=f"{node.name}#{j}", parent=k, local=IDENTITY, mesh=m) for j, m in enumerate(index)]
    stats["chunk_meshes"] = sorted(stats["chunk_meshes"])
    return dataclasses.replace(scene, meshes=meshes, nodes=nodes), stats


def describe(stats: dict) -> list[str]:
    """Report lines for the chunk stage."""
    s = stats.get("settings", {})
    size = f"{s.get('size'):g} m"
    lines = [f"Static meshes of at least {s.get('min_mesh_triangles')} triangles and longer than {size} are cut into chunks whose "
             f"triangle centroids span at most {size} and that hold at most {s.get('max_triangles')} triangles (no cut leaves fewer "
             f"than {s.get('min_triangles')}); triangles longer than {size} go to a chunk of their own. Each chunk is a mesh and "
             f"instance of its own and shares its node's lightmap region. Extent: a chunk's bounding box's longest side.", ""]
    if not stats.get("meshes"):
        return lines + ["No mesh was split."]
    lines += ["| mesh | triangles | chunks | triangles (extent in m) per chunk |", "| --- | ---: | ---: | --- |"]
    for m in stats["meshes"]:
        each = ", ".join(f"{t} ({e:.1f})" for t, e in zip(m["chunk_triangles"], m["chunk_extents"]))
        lines.append(f"| {m['mesh']} | {m['triangles']} | {m['chunks']} | {each} |")
    total = sum(m["chunks"] for m in stats["meshes"])
    lines += ["", f"{total} chunks from {len(stats['meshes'])} mesh(es)."]
    return lines
