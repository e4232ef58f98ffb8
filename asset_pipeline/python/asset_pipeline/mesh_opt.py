"""The mesh optimisation stage: every LOD's triangles and vertices in the order the GPU's caches
want (meshoptimizer, through the Rust core: `cook_core::mesh_opt`).

Within each draw group (what the pack writer makes a submesh of: one material and lightmap
block), triangles are ordered for the post-transform vertex cache and then for overdraw; the
vertices are renumbered in the order the triangles first use them, and any no triangle uses are
dropped. Geometry does not change: the same triangles with the same windings, the same vertex
values, every per-vertex stream (attributes, skin, morph deltas) and per-triangle value
(material, lightmap block) carried through the same permutation.

The stage measures what it bought with meshoptimizer's FIFO cache model (16 entries): ACMR,
vertices transformed per triangle, before and after, summed over every LOD.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from asset_pipeline import _core, ir


def group_keys(lod: ir.Lod) -> np.ndarray:
    """Each triangle's draw group as one sortable uint64: material, then lightmap block. The
    pack writer sorts triangles by (material, block) stably, so groups in ascending key order
    keep the order this stage chose."""
    keys = lod.materials.astype(np.uint64) << np.uint64(32)
    if lod.lightmap_blocks is not None:
        keys |= lod.lightmap_blocks.astype(np.uint64)
    return keys


def optimize_lod(lod: ir.Lod) -> ir.Lod:
    """The LOD in cache, overdraw and vertex fetch order (see the module's docstring)."""
    if lod.triangle_count == 0:
        return lod
    triangles, order, vertices = _core.optimize_lod(lod.triangles, group_keys(lod), lod.attributes["position"])
    attributes = {name: np.ascontiguousarray(a[vertices]) for name, a in lod.attributes.items()}
    morph = {name: None if d is None else np.ascontiguousarray(d[:, vertices])
             for name, d in (("morph_positions", lod.morph_positions), ("morph_normals", lod.morph_normals))}
    return dataclasses.replace(
        lod,
        attributes=attributes,
        triangles=triangles,
        materials=np.ascontiguousarray(lod.materials[order]),
        lightmap_blocks=None if lod.lightmap_blocks is None else np.ascontiguousarray(lod.lightmap_blocks[order]),
        **morph,
    )


def vertices_transformed(lod: ir.Lod) -> float:
    """Vertex shader runs the LOD costs under meshoptimizer's FIFO cache model, drawn as the
    pack draws it (group after group): ACMR x triangles."""
    if lod.triangle_count == 0:
        return 0.0
    order = np.argsort(group_keys(lod), kind="stable")
    acmr, _ = _core.vertex_cache_stats(np.ascontiguousarray(lod.triangles[order]), lod.vertex_count)
    return float(acmr) * lod.triangle_count


@dataclasses.dataclass
class MeshOptStats:
    """Summed over every LOD of every mesh (and over LOD 0s alone)."""

    triangles: int = 0
    transformed_before: float = 0.0
    transformed_after: float = 0.0
    vertices_before: int = 0
    vertices_after: int = 0
    lod0_triangles: int = 0
    lod0_transformed_before: float = 0.0
    lod0_transformed_after: float = 0.0

    @property
    def acmr_before(self) -> float:
        return self.transformed_before / max(self.triangles, 1)

    @property
    def acmr_after(self) -> float:
        return self.transformed_after / max(self.triangles, 1)

    @property
    def lod0_acmr_before(self) -> float:
        return self.lod0_transformed_before / max(self.lod0_triangles, 1)

    @property
    def lod0_acmr_after(self) -> float:
        return self.lod0_transformed_after / max(self.lod0_triangles, 1)

    def as_dict(self) -> dict:
        d = dataclasses.asdict(self)
        d.update(acmr_before=self.acmr_before, acmr_after=self.acmr_after, lod0_acmr_before=self.lod0_acmr_before, lod0_acmr_after=self.lod0_acmr_after,
                 cache_size=int(_core.VERTEX_CACHE_SIZE))
        return d


def optimize_mesh(mesh: ir.Mesh) -> tuple[ir.Mesh, MeshOptStats]:
    """The mesh with every LOD optimised, and its share of the stage's statistics."""
    stats = MeshOptStats()
    lods = []
    for i, lod in enumerate(mesh.lods):
        new = optimize_lod(lod)
        before, after = vertices_transformed(lod), vertices_transformed(new)
        stats.triangles += lod.triangle_count
        stats.transformed_before += before
        stats.transformed_after += after
        stats.vertices_before += lod.vertex_count
        stats.vertices_after += new.vertex_count
        if i == 0:
            stats.lod0_triangles += lod.triangle_count
            stats.lod0_transformed_before += before
            stats.lod0_transformed_after += after
        lods.append(new)
    return dataclasses.replace(mesh, lods=lods), stats


def add(total: MeshOptStats, part: MeshOptStats) -> None:
    for f in dataclasses.fields(MeshOptStats):
        setattr(total, f.name, getattr(total, f.name) + getattr(part, f.name))


def optimize_scene(scene: ir.Scene) -> tuple[ir.Scene, MeshOptStats]:
    """Every mesh's LODs optimised (the pipeline's stage does this mesh by mesh, cached)."""
    total = MeshOptStats()
    meshes = []
    for mesh in scene.meshes:
        new, stats = optimize_mesh(mesh)
        add(total, stats)
        meshes.append(new)
    return dataclasses.replace(scene, meshes=meshes), total
