"""Lightmap UVs (UV2): xatlas charts at a texel density, packed into blocks per mesh, and an
atlas region for every static placement of a mesh.

    r = lightmap_uvs(lods, Uv2Settings(), instances=[Instance(mesh, world_scale, texels_per_metre_or_None), ...])
    r.lods      # per mesh: LOD 0 with uv1 (its own lightmap space) and lightmap_blocks
    r.regions   # per instance: {"page", "scale", "offset"} (pack::LightmapRegion)
    r.layout    # ir.LightmapLayout: pages, all of one size
    r.placed    # per instance: its mesh's Lod moved onto the atlas (place_on_atlas)

Every mesh input is a static mesh's LOD 0 in object space; every instance names its mesh, the
uniform scale that places it in the world (density is in world metres) and an optional density
override. Each output Lod is the input with its vertices split at chart seams (every attribute
carried through xatlas's vertex mapping; triangles keep their order and materials), a ``uv1``
attribute in its own lightmap space (texels of the page for a mesh placed once, whose region
scales by one over the page size; [0, 1] over its largest block for a mesh placed several
times), and ``lightmap_blocks`` per triangle. A mesh
placed several times keeps one set of vertices: each placement maps them onto its own texels
with a scale and an offset (Unity's lightmapScaleOffset, Godot's per-instance lightmap slice),
so every placement is baked with its own light.

How, and why this way:

1. **Charts, per mesh** (:func:`chart_mesh`). Positions are scaled to *texel units* (world metres
   x texels per metre), so one xatlas unit is one texel and per-object densities need nothing
   else. Each mesh is charted in its own ``xatlas.Atlas``: the result depends on that mesh
   alone, so it can be cached by content hash (``cache=``) and computed in parallel. xatlas's
   Python module holds the GIL and charts on one core (~5k triangles 0.2 s, 20k 1.6 s, 100k
   18 s), so big jobs run in worker processes.
2. **Blocks, per mesh** (:func:`pack_charts`): the mesh's charts go back into xatlas as UV
   meshes (``add_uv_mesh``), which packs them unscaled (texels_per_unit 1) with padding, at the
   density of the mesh's least dense placement. One block if it fits in ``max_page_size``, else
   as many as needed, each cropped to what it uses.
   xatlas's packer stretches every chart to whole-texel extents (rounding up, so up to a texel
   more: +37% density on a 2-texel chart); the stage measures each chart's true size and has it
   land on the nearest whole number instead, so density is off by at most half a texel per chart
   side (level: +0.02% on the demo level).
3. **The atlas** (:func:`lightmap_uvs`): meshes placed once go onto the pages chart by chart,
   as charts of their own (their region only scales texels to the page); every placement of a mesh placed
   several times is a rectangle (its block scaled by its density over the mesh's, so at least
   1) packed among those charts without turning; a placement of a mesh of several blocks takes
   that many pages. Every page is then cropped to the largest extent used (a multiple of 4
   texels, for block compression): pages share one size, the runtime's array texture.
4. **Verification** (``verify=True``): every page is rasterised in Rust (``_core.rasterize_uv``)
   at its resolution: no texel centre may be claimed by two charts, and no chart's conservative
   coverage (every texel it touches: what the baker bakes) may come within ``padding`` texels of
   another's. The same rasters give utilisation; densities are measured per triangle.

Padding, in texels, is the number of empty texels between the conservative coverages of any two
charts. With 2, bilinear sampling anywhere in a chart reads only that chart's texels and the
1-texel ring around them that dilation fills, and no ring texel is shared by two charts (the
Unity rule "charts >= 2 full texels apart"). The runtime's bicubic sampling (a 4x4 texel
footprint) reads 2 texels past a chart, so the default is 4: each chart's 2-texel ring is its
own. On the demo level it costs 9.8% more page texels (608x648 -> 640x676) and utilisation
0.811 -> 0.744. xatlas pads each chart on every side, so it is given half of it (rounded up),
measured to give exactly that gap.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import multiprocessing
import os
import threading
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np
import xatlas

from asset_pipeline import _core, ir
from asset_pipeline._core import CookError

NONE = 0xFFFFFFFF  # xatlas's "no chart / no atlas" (-1 as uint32), and the rasteriser's empty texel

# Bump when the meaning of a cached chart entry changes.
_CHARTS_FORMAT = 2


@dataclass(frozen=True)
class Uv2Settings:
    texels_per_metre: float = 16.0
    # Empty texels between any two charts' baked texels; 4 makes bicubic filtering (which reads 2
    # texels past a chart) plus 2 dilated rings per chart safe, 2 would do for bilinear only (see
    # the module docstring). At least 1.
    padding: int = 4
    # Largest page side in texels (a multiple of 4). A level needing more becomes several pages;
    # 2048 holds the demo level (60 m ground at 16 texels/m) on one page.
    max_page_size: int = 2048
    # xatlas brute-force packing: tries every position for each chart. 2-8 points of utilisation
    # for a little time (packing is cheap next to charting).
    brute_force: bool = True
    # xatlas ChartOptions.maxIterations: more iterations of chart growing give fewer, rounder
    # charts at proportionally more charting time; 1 is xatlas's default.
    chart_iterations: int = 1
    # Processes for charting (0 = one per core) when the meshes to chart hold at least
    # `parallel_min_triangles` triangles; smaller jobs run in-process (a worker costs ~0.3 s).
    workers: int = 0
    parallel_min_triangles: int = 20000
    # Rasterise every page and check overlaps and padding (raises CookError on failure) and
    # measure utilisation. Off only saves the rasterising time.
    verify: bool = True
    # The most lightmap texels a cook may ask for (surface area x density^2 over the static
    # meshes): 64M is 16 full 2048^2 pages, about ten times a detailed level. A density typed
    # wrong (1e6 instead of 16) fails here, with a message, instead of in xatlas or the baker.
    max_texels: int = 1 << 26

    def validate(self) -> None:
        if not (math.isfinite(self.texels_per_metre) and self.texels_per_metre > 0):
            raise CookError(f"uv2 settings: texels_per_metre must be a positive number, not {self.texels_per_metre}")
        if int(self.padding) != self.padding or self.padding < 1:
            raise CookError(f"uv2 settings: padding must be a whole number of texels >= 1, not {self.padding}")
        if int(self.max_page_size) != self.max_page_size or self.max_page_size < 16 or self.max_page_size % 4 or self.max_page_size > 16384:
            raise CookError(f"uv2 settings: max_page_size must be a multiple of 4 in 16..16384, not {self.max_page_size}")
        if self.chart_iterations < 1:
            raise CookError(f"uv2 settings: chart_iterations must be >= 1, not {self.chart_iterations}")

    @property
    def xatlas_padding(self) -> int:
        return (self.padding + 1) // 2


@dataclass
class MeshCharts:
    """One mesh cut into charts and flattened, in texel units (before packing)."""

    vmapping: np.ndarray  # (k,) uint32: input vertex of each chart vertex
    triangles: np.ndarray  # (m,) x 3 uint32 into the chart vertices; same order as the input triangles
    uv: np.ndarray  # (k, 2) float32, texel units
    chart: np.ndarray  # (m,) uint32 chart per triangle, 0..count-1, or NONE for faces xatlas ignored (no area)
    extents: np.ndarray  # (count, 2) float64: each chart's size in texels along u and v before xatlas's rounding
    count: int


@dataclass
class Packing:
    """Where every chart vertex of every mesh landed."""

    pages: list[tuple[int, int]]
    uv1: list[np.ndarray]  # per mesh (k, 2) float32 in [0, 1] of the vertex's page
    texel_uv: list[np.ndarray]  # per mesh (k, 2) float64: the same in texels of the page
    vmapping: list[np.ndarray]  # per mesh (k,) uint32 into the MeshCharts vertices
    triangles: list[np.ndarray]  # per mesh (m, 3) uint32
    page: list[np.ndarray]  # per mesh (m,) uint32 page per triangle
    chart: list[np.ndarray]  # per mesh (m,) uint32 chart id, unique over the level (NONE = no area)


# ---- 1. charts ---------------------------------------------------------------------------------


def _chart_options(settings: Uv2Settings) -> dict:
    # Defaults of xatlas otherwise (normal deviation 2, roundness 0.01, straightness 6, normal seam
    # 4, max cost 2): they cut CSG geometry along its hard edges into planar charts.
    # - fix_winding: every chart keeps the mesh's winding in UV space (no mirrored charts), as Godot.
    # - max_boundary_length (texel units): a chart's diameter is at most half its perimeter, so a
    #   chart this long around fits a page with its padding; bigger regions are cut into more
    #   charts instead of being shrunk by the packer. (Single triangles bigger than a page cannot
    #   be cut: pack_charts reports them.)
    fit = settings.max_page_size - 2 * settings.xatlas_padding - 2
    return {"fix_winding": True, "max_iterations": int(settings.chart_iterations), "max_boundary_length": float(2 * fit)}


def chart_mesh(positions_texels: np.ndarray, triangles: np.ndarray, normals: np.ndarray | None, chart_options: dict) -> MeshCharts:
    """Charts of one mesh whose positions are in texel units (a pure function of its arguments)."""
    atlas = xatlas.Atlas()
    atlas.add_mesh(positions_texels, triangles, normals=normals)
    co = xatlas.ChartOptions()
    for k, v in chart_options.items():
        setattr(co, k, v)
    po = xatlas.PackOptions()
    # Only the charts matter here; a quick pack with 1 texel between charts so that no two charts
    # share a UV position (the packing pass finds charts as connected UV islands).
    po.texels_per_unit = 1.0
    po.padding = 1
    po.bilinear = False
    po.bruteForce = False
    po.blockAlign = False  # block alignment rescales charts (measured: +5% density)
    po.resolution = 0
    atlas.generate(co, po)
    vmapping, tris, uv = atlas.get_mesh(0)
    _, chart_of_vertex = atlas.get_mesh_vertex_assignment(0)
    uv_texels = (uv.astype(np.float64) * np.array([atlas.width, atlas.height], np.float64)).astype(np.float32)
    chart = chart_of_vertex[tris[:, 0]].astype(np.uint32) if len(tris) else np.zeros(0, np.uint32)
    count = int(atlas.chart_count)
    tris = tris.astype(np.uint32)
    extents = _true_extents(uv_texels, tris, chart, count, positions_texels[vmapping].astype(np.float64))
    return MeshCharts(vmapping.astype(np.uint32), tris, uv_texels, chart, extents, count)


def _chart_bounds(uv: np.ndarray, tris: np.ndarray, chart: np.ndarray, count: int):
    """Per chart: min corner and size of its UV bounding box, and every vertex's chart (-1 if none)."""
    vchart = np.full(len(uv), -1, np.int64)
    ok_t = chart != NONE
    vchart[tris[ok_t].ravel()] = np.repeat(chart[ok_t].astype(np.int64), 3)
    ok = vchart >= 0
    lo = np.full((count, 2), np.inf)
    hi = np.full((count, 2), -np.inf)
    np.minimum.at(lo, vchart[ok], uv[ok])
    np.maximum.at(hi, vchart[ok], uv[ok])
    return lo, hi - lo, vchart


def _true_extents(uv: np.ndarray, tris: np.ndarray, chart: np.ndarray, count: int, pos: np.ndarray) -> np.ndarray:
    """xatlas's packer stretches every chart along u and v so that its extents become whole
    texels (ceil): up to a texel more, which is a large density error on small charts. Recover the
    chart's size before that stretch by fitting, per chart, the u and v scales that best restore
    its 3D edge lengths (exact for planar charts: they are isometric before the stretch)."""
    if count == 0:
        return np.zeros((0, 2))
    uv = uv.astype(np.float64)
    _, size, _ = _chart_bounds(uv, tris, chart, count)
    ok = chart != NONE
    t, c = tris[ok], chart[ok].astype(np.int64)
    # Each edge: a * du^2 + b * dv^2 = length^2, with a = 1 / su^2, b = 1 / sv^2.
    du2, dv2, l2, cc = [], [], [], []
    for i, j in ((0, 1), (1, 2), (2, 0)):
        d = uv[t[:, j]] - uv[t[:, i]]
        du2.append(d[:, 0] ** 2)
        dv2.append(d[:, 1] ** 2)
        l2.append(((pos[t[:, j]] - pos[t[:, i]]) ** 2).sum(axis=1))
        cc.append(c)
    du2, dv2, l2, cc = (np.concatenate(x) for x in (du2, dv2, l2, cc))
    acc = lambda w: np.bincount(cc, w, minlength=count)
    suu, suv, svv, ru, rv = acc(du2 * du2), acc(du2 * dv2), acc(dv2 * dv2), acc(du2 * l2), acc(dv2 * l2)
    det = suu * svv - suv * suv
    good = det > 1e-12 * np.maximum(suu * svv, 1e-300)
    a = np.where(good, (ru * svv - rv * suv) / np.where(good, det, 1), 1.0)
    b = np.where(good, (rv * suu - ru * suv) / np.where(good, det, 1), 1.0)
    su = np.where(a > 0, 1 / np.sqrt(np.where(a > 0, a, 1)), 1.0)
    sv = np.where(b > 0, 1 / np.sqrt(np.where(b > 0, b, 1)), 1.0)
    # ceil(true) == size, so the true size is in (size - 1, size].
    true = size / np.stack([su, sv], axis=1)
    return np.clip(true, np.maximum(size - 1, 0), size)


def _chart_job(args: tuple) -> tuple:
    c = chart_mesh(*args)
    return c.vmapping, c.triangles, c.uv, c.chart, c.extents, c.count


def _texel_positions(lod: ir.Lod, texels_per_unit: float) -> np.ndarray:
    p = lod.attributes["position"].astype(np.float64) * texels_per_unit
    return np.ascontiguousarray(p, dtype=np.float32)


def _charts_key(positions: np.ndarray, triangles: np.ndarray, normals: np.ndarray | None, options: dict) -> str:
    h = hashlib.sha256()
    h.update(f"uv2-charts {_CHARTS_FORMAT} xatlas {xatlas.__version__} {sorted(options.items())}".encode())
    for a in (positions, triangles, normals):
        if a is not None:
            h.update(f"{a.dtype}{a.shape}".encode())
            h.update(np.ascontiguousarray(a).data)
    return h.hexdigest()


def chart_meshes(jobs: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray | None]], settings: Uv2Settings, cache=None) -> list[MeshCharts]:
    """chart_mesh for every (positions_texels, triangles, normals), from `cache` where it has
    them (an object with StageCache's load/store), in worker processes when the work is big."""
    options = _chart_options(settings)
    out: list[MeshCharts | None] = [None] * len(jobs)
    keys = [_charts_key(p, t, n, options) for p, t, n in jobs] if cache is not None else [None] * len(jobs)
    todo = []
    for i, (p, t, n) in enumerate(jobs):
        if len(t) == 0:
            out[i] = MeshCharts(np.zeros(0, np.uint32), np.zeros((0, 3), np.uint32), np.zeros((0, 2), np.float32), np.zeros(0, np.uint32), np.zeros((0, 2)), 0)
            continue
        hit = cache.load("uv2-charts", keys[i]) if cache is not None else None
        if hit is not None:
            meta, arrays = hit
            out[i] = MeshCharts(*arrays, meta["count"])  # vmapping, triangles, uv, chart, extents
        else:
            todo.append(i)
    workers = settings.workers or os.cpu_count() or 1
    big = sum(len(jobs[i][1]) for i in todo) >= settings.parallel_min_triangles
    results: dict[int, tuple] = {}
    if workers > 1 and len(todo) > 1 and big:
        order = sorted(todo, key=lambda i: -len(jobs[i][1]))  # longest first
        with ProcessPoolExecutor(max_workers=min(workers, len(todo)), mp_context=_pool_context()) as pool:
            futures = {i: pool.submit(_chart_job, (*jobs[i], options)) for i in order}
            results = {i: f.result() for i, f in futures.items()}
    else:
        results = {i: _chart_job((*jobs[i], options)) for i in todo}
    for i, r in results.items():
        out[i] = MeshCharts(*r)
        if cache is not None:
            cache.store("uv2-charts", keys[i], {"count": r[5]}, list(r[:5]))
    return out  # type: ignore[return-value]


def _pool_context() -> multiprocessing.context.BaseContext:
    """The charting workers' start method. fork when this process has no other thread: the
    children need nothing re-imported (and scripts without a __main__ guard work). With other
    threads, a fork copies whatever locks they held at that moment: after Ray's client had started
    (its gRPC threads) in the same process, a forked worker hung on one, and the cook with it (a
    test-suite run). forkserver then forks from a clean single-threaded server."""
    methods = multiprocessing.get_all_start_methods()
    tasks = Path("/proc/self/task")
    threads = len(list(tasks.iterdir())) if tasks.is_dir() else threading.active_count()
    if "fork" in methods and threads == 1:
        return multiprocessing.get_context("fork")
    return multiprocessing.get_context("forkserver" if "forkserver" in methods else None)


# ---- 2. packing --------------------------------------------------------------------------------


def _uv_areas(uv: np.ndarray, tris: np.ndarray) -> np.ndarray:
    a, b, c = (uv[tris[:, k]].astype(np.float64) for k in range(3))
    return 0.5 * np.abs((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1]))


def _local_charts(c: MeshCharts, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """The mesh's chart UVs prepared for packing, and the scale (u, v) each chart will end up at.

    Each chart is scaled about its own corner (charts stay where charting put them, apart: the
    packer finds charts as UV islands by position) so that its extents are just below the whole
    number of texels nearest to its true size (at least 1); the packer stretches every chart up
    to whole texels (ceil), which then lands exactly there. Rounding instead of xatlas's ceil
    halves the density error of small charts."""
    uv = c.uv.astype(np.float64)
    lo, size, vchart = _chart_bounds(uv, c.triangles, c.chart, c.count)
    ok = vchart >= 0
    if not ok.any():
        return c.uv, np.ones((c.count, 2))
    target = np.maximum(1.0, np.round(c.extents))
    final = np.where(size > 0, target / np.where(size > 0, size, 1), 1.0)  # scale from charting's UVs to the packed ones
    prepared = np.where(size > 0, (target - 2 * tol) / np.where(size > 0, size, 1), 1.0)
    out = uv.copy()
    out[ok] = lo[vchart[ok]] + (uv[ok] - lo[vchart[ok]]) * prepared[vchart[ok]]
    return out.astype(np.float32), final


def _pack_once(charts: Sequence[MeshCharts], settings: Uv2Settings, resolution: int, rotate: bool = True):
    atlas = xatlas.Atlas()
    present = [i for i, c in enumerate(charts) if len(c.triangles)]
    scales = {}
    # The xatlas module keeps pointers to the arrays it is given until generate(), without a
    # reference: they must outlive it, or a freed array's memory becomes another mesh's UVs.
    alive = []
    for i in present:
        c = charts[i]
        # Chart UVs are f32 in charting's atlas: allow a few ulps of its largest coordinate.
        tol = max(1e-3, 4 * float(np.spacing(np.float32(max(1.0, float(np.abs(c.uv).max(initial=1.0)))))))
        uv, scales[i] = _local_charts(c, tol)
        alive.append((np.ascontiguousarray(uv), np.ascontiguousarray(c.triangles)))
        atlas.add_uv_mesh(*alive[-1])
    po = xatlas.PackOptions()
    po.texels_per_unit = 1.0  # UVs are already texels: pack without rescaling
    po.padding = settings.xatlas_padding
    po.bilinear = True
    po.bruteForce = bool(settings.brute_force)
    po.blockAlign = False
    po.rotate_charts = rotate  # quarter turns while placing
    po.rotate_charts_to_axis = False  # charting already did; a new axis would change the extents
    po.resolution = resolution
    atlas.generate(xatlas.ChartOptions(), po)
    del alive
    return atlas, present, scales


def pack_charts(charts: Sequence[MeshCharts], settings: Uv2Settings, names: Sequence[str] | None = None, align: int = 4,
                rotate: bool = True) -> Packing:
    """Pack every mesh's charts into pages (one if they fit in max_page_size), each cropped to
    the texels it uses rounded up to a multiple of `align`; `rotate` allows quarter turns."""
    names = list(names) if names is not None else [f"static mesh {i}" for i in range(len(charts))]
    expected = sum(c.count for c in charts)
    if expected == 0:
        # Nothing with area: every triangle on one minimal page at UV (0, 0).
        pages = [(4, 4)] if any(len(c.triangles) for c in charts) else []
        return Packing(pages, [np.zeros((len(c.uv), 2), np.float32) for c in charts], [np.zeros((len(c.uv), 2)) for c in charts],
                       [np.arange(len(c.uv), dtype=np.uint32) for c in charts],
                       [c.triangles for c in charts], [np.zeros(len(c.triangles), np.uint32) for c in charts],
                       [np.full(len(c.triangles), NONE, np.uint32) for c in charts])
    # Pages of max_page_size, each cropped afterwards to what it uses. (Packing into one page of
    # unbounded size gives the same layout when it fits, more slowly: xatlas grows it as it goes.)
    atlas, present, scales = _pack_once(charts, settings, settings.max_page_size, rotate)
    if atlas.chart_count != expected:
        raise CookError(f"uv2: packing found {atlas.chart_count} charts where charting made {expected} (xatlas)")
    size = np.array([atlas.width, atlas.height], np.float64)
    texel_uv, vmaps, tris, pages, chart_ids = [], [], [], [], []
    for i, c in enumerate(charts):
        if i not in present:
            texel_uv.append(np.zeros((0, 2)))
            vmaps.append(np.zeros(0, np.uint32))
            tris.append(np.zeros((0, 3), np.uint32))
            pages.append(np.zeros(0, np.uint32))
            chart_ids.append(np.zeros(0, np.uint32))
            continue
        k = present.index(i)
        vm, ix, uv = atlas.get_mesh(k)
        atlas_of, chart_of = atlas.get_mesh_vertex_assignment(k)
        vm, ix = vm.astype(np.uint32), ix.astype(np.uint32)
        if ix.shape != c.triangles.shape or not np.array_equal(vm[ix], c.triangles):
            raise CookError(f"uv2: {names[i]}: xatlas changed the triangles while packing")
        t = uv.astype(np.float64) * size
        ch = chart_of[ix[:, 0]].astype(np.uint32)
        pg = atlas_of[ix[:, 0]].astype(np.uint32)
        ignored = ch == NONE
        # The packer moves and rotates charts and scales them as _local_charts planned, no more (it
        # shrinks charts larger than a page): compare each chart's UV area before and after.
        before = np.bincount(c.chart[~ignored], _uv_areas(c.uv, c.triangles)[~ignored], minlength=c.count) * scales[i].prod(axis=1)
        after = np.zeros(c.count)
        np.add.at(after, c.chart[~ignored], _uv_areas(t, ix)[~ignored])
        bad = np.flatnonzero(np.abs(after - before) > 1e-3 * before + 1e-2)
        if len(bad):
            j = int(bad[0])
            lo = c.uv[c.triangles[c.chart == j].ravel()]
            w, h = np.ptp(lo, axis=0)
            raise CookError(
                f"uv2: {names[i]}: a chart of {w:.0f} x {h:.0f} texels does not fit a {settings.max_page_size}-texel page "
                f"with padding; raise max_page_size or lower texels_per_metre (a single triangle this big cannot be split)"
            )
        # Faces xatlas ignored (no area) get page 0; their vertices sit on one point.
        pg[ignored] = 0
        texel_uv.append(t)
        vmaps.append(vm)
        tris.append(ix)
        pages.append(pg)
        chart_ids.append(ch)
    # Crop every page to the texels its charts touch, rounded up to a multiple of `align`.
    n_pages = max(1, int(atlas.atlas_count))
    extent = np.ones((n_pages, 2))
    for t, ix, pg in zip(texel_uv, tris, pages):
        if len(ix):
            corners = t[ix].reshape(-1, 2)
            np.maximum.at(extent, np.repeat(pg, 3), np.floor(corners) + 1)
    up = lambda x: int(min(settings.max_page_size, align * math.ceil(x / align)))
    sizes = [(up(w), up(h)) for w, h in extent]
    uv1 = []
    for t, vm, ix, pg in zip(texel_uv, vmaps, tris, pages):
        vertex_page = np.zeros(len(t), np.uint32)
        vertex_page[ix.ravel()] = np.repeat(pg, 3)
        uv1.append((t / np.array(sizes, np.float64)[vertex_page]).astype(np.float32) if len(t) else np.zeros((0, 2), np.float32))
    return Packing(sizes, uv1, texel_uv, vmaps, tris, pages, chart_ids)


# A group's charts, with the packer's padding around each (``_footprint``, which overestimates
# what the packer needs), cover at most this much of a page. Measured on the scale benchmark's
# levels: at 0.9 the 300k level's charts stay one group on one page (utilisation 0.626, as packed
# whole), the 1M level's make 3 groups on 3 pages in 35 s (utilisation 0.49: the last page
# partly used); at 1.2 a group overflows its page and its last charts scan the full page for a
# place: over ten minutes again.
_GROUP_FILL = 0.9
# Fewer charts than this are packed all at once (grouping costs utilisation: the demo level on
# 512-texel pages, 0.63 -> 0.53): under it, brute-force packing takes seconds.
_GROUP_MIN_CHARTS = 5000


def _footprint(c: MeshCharts, settings: Uv2Settings) -> float:
    """Texels the packer needs for a mesh's charts: each chart's whole-texel extent with its
    padding on every side."""
    if c.count == 0:
        return 0.0
    pad = 2 * settings.xatlas_padding + 1
    e = np.ceil(np.asarray(c.extents, np.float64)) + pad
    return float((e[:, 0] * e[:, 1]).sum())


def _pack_job(args: tuple) -> Packing:
    return pack_charts(*args)


def pack_groups(charts: Sequence[MeshCharts], settings: Uv2Settings, names: Sequence[str], rotate: bool = True) -> Packing:
    """pack_charts for a level's worth of meshes: consecutive meshes in groups of about a page
    each (``_GROUP_FILL``), each group packed into pages of its own, the groups in worker
    processes. Brute-force packing tries every position of a page for every chart, so one packing
    of all of a big level's charts costs charts x pages x page area: the 1M-triangle benchmark
    level spent over ten minutes in it on one core. Per group it is a page's worth of charts
    against one page, and the groups run in parallel. The groups depend only on the meshes and
    their order; a level that fits on one page, or of fewer than ``_GROUP_MIN_CHARTS`` charts,
    is packed whole as before."""
    page = float(settings.max_page_size) ** 2 * _GROUP_FILL
    groups: list[list[int]] = []
    used = page
    for i, c in enumerate(charts):
        need = _footprint(c, settings)
        if not groups or used + need > page:
            groups.append([])
            used = 0.0
        groups[-1].append(i)
        used += need
    if len(groups) <= 1 or sum(c.count for c in charts) < _GROUP_MIN_CHARTS:
        return pack_charts(charts, settings, names, rotate=rotate)
    jobs = [([charts[i] for i in g], settings, [names[i] for i in g], 4, rotate) for g in groups]
    workers = min(settings.workers or os.cpu_count() or 1, len(jobs))
    if workers > 1:
        with ProcessPoolExecutor(max_workers=workers, mp_context=_pool_context()) as pool:
            parts = list(pool.map(_pack_job, jobs))
    else:
        parts = [_pack_job(j) for j in jobs]
    # One packing: pages one after another, chart ids numbered on over the groups.
    out = Packing([], [], [], [], [], [], [])
    first_chart = 0
    for g, part in zip(groups, parts):
        first_page = len(out.pages)
        out.pages.extend(part.pages)
        out.uv1.extend(part.uv1)
        out.texel_uv.extend(part.texel_uv)
        out.vmapping.extend(part.vmapping)
        out.triangles.extend(part.triangles)
        out.page.extend(pg + np.uint32(first_page) for pg in part.page)
        out.chart.extend(np.where(ch == NONE, ch, ch + np.uint32(first_chart)).astype(np.uint32) for ch in part.chart)
        first_chart += sum(charts[i].count for i in g)
    return out


# ---- the stage ---------------------------------------------------------------------------------


def _world_areas(lod: ir.Lod, scale: float) -> np.ndarray:
    p = lod.attributes["position"].astype(np.float64) * scale
    t = lod.triangles
    return 0.5 * np.linalg.norm(np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]]), axis=1)


def triangle_densities(lod: ir.Lod, scale: float, pages: Sequence[tuple[int, int]]) -> tuple[np.ndarray, np.ndarray]:
    """Per triangle of a placed Lod (``place_on_atlas``: uv1 on its page, ``lightmap_blocks`` the
    pages): measured texels per metre sqrt(UV area in texels^2 / world area in m^2), and the
    world area (the weight). Triangles without world area get density 0 and weight 0."""
    size = np.array(pages, np.float64).reshape(-1, 2)[lod.lightmap_blocks]
    uv = lod.attributes["uv1"].astype(np.float64)
    t = lod.triangles
    a, b, c = (uv[t[:, k]] * size for k in range(3))
    uv_area = 0.5 * np.abs((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1]))
    world = _world_areas(lod, scale)
    tiny = world <= 1e-12 * max(1.0, float(world.max(initial=0.0)))
    d = np.where(tiny, 0.0, np.sqrt(uv_area / np.where(tiny, 1.0, world)))
    return d, np.where(tiny, 0.0, world)


@dataclass
class Instance:
    """One static placement of a mesh: which mesh, the uniform scale that places it in the world
    (density is in world metres) and an optional density override (texels per metre)."""

    mesh: int
    scale: float = 1.0
    texels_per_metre: float | None = None


@dataclass
class Uv2Result:
    lods: list[ir.Lod]  # per mesh: LOD 0 with uv1 in its own lightmap space and lightmap_blocks
    regions: list[dict]  # per instance: pack::LightmapRegion {"page", "scale", "offset"}
    layout: ir.LightmapLayout
    stats: dict
    instances: list[Instance] = field(default_factory=list)

    @property
    def placed(self) -> list[ir.Lod]:
        """Per instance: its mesh's Lod on the atlas (``place_on_atlas``)."""
        return [place_on_atlas(self.lods[i.mesh], r) for i, r in zip(self.instances, self.regions)]


def _instances(meshes, instances) -> tuple[list[ir.Lod], list[Instance]]:
    """(lods, instances) from lightmap_uvs's arguments: without `instances`, `meshes` holds
    ``(lod, world_scale)`` or ``(lod, world_scale, texels_per_metre)``, each placed once."""
    if instances is None:
        lods, instances = [], []
        for i, m in enumerate(meshes):
            lods.append(m[0])
            instances.append(Instance(i, *m[1:]))
    else:
        lods, instances = list(meshes), [i if isinstance(i, Instance) else Instance(*i) for i in instances]
    for k, inst in enumerate(instances):
        if not 0 <= inst.mesh < len(lods):
            raise CookError(f"uv2: instance {k}: mesh {inst.mesh} does not exist")
        if not (math.isfinite(inst.scale) and inst.scale > 0):
            raise CookError(f"uv2: instance {k}: world scale must be positive, not {inst.scale}")
        tpm = inst.texels_per_metre
        if tpm is not None and not (math.isfinite(tpm) and tpm > 0):
            raise CookError(f"uv2: instance {k}: texels_per_metre must be positive, not {tpm}")
    return lods, instances


# Two scales within this of each other are the same density (float noise from transforms).
_SAME_SCALE = 1e-6


def _rectangle(w: int, h: int) -> MeshCharts:
    """A w x h texel rectangle as one chart for the packer: a placement's block of charts, which
    must move as one piece."""
    uv = np.array([[0, 0], [w, 0], [w, h], [0, h]], np.float32)
    return MeshCharts(np.arange(4, dtype=np.uint32), np.array([[0, 1, 2], [0, 2, 3]], np.uint32), uv,
                      np.zeros(2, np.uint32), np.array([[w, h]], np.float64), 1)


def lightmap_uvs(meshes, settings: Uv2Settings | None = None, *, instances=None, names: Sequence[str] | None = None,
                 instance_names: Sequence[str] | None = None, cache=None) -> Uv2Result:
    """Lightmap UVs for static meshes and an atlas region for every static placement of them.

    ``meshes``: the static meshes' LOD 0 (object space); ``instances``: ``Instance``s (or
    ``(mesh, world_scale, texels_per_metre or None)`` tuples) placing them. Without
    ``instances``, ``meshes`` holds ``(lod, world_scale[, texels_per_metre])``, each placed once.

    A mesh placed once has its charts packed with every other such mesh's, straight onto the
    atlas pages (its uv1 in page texels, its region scaling them to the page, its blocks the pages
    it lands on): the tightest
    packing. A mesh placed several times has its charts packed into blocks of its own once, at
    the density of its least dense placement, and each placement gets a rectangle of atlas
    texels per block, scaled by its density over that one (>= 1: a placement twice as large
    gets twice the texels per side), so one set of vertices serves every placement through a
    scale and an offset (pack::LightmapRegion). Those rectangles are packed together with the
    single meshes' charts as charts that do not turn. Blocks drawn at more than one scale keep
    2 more texels of padding between their charts: scaled by a non-integer factor, a chart's
    edges land inside texels, and conservative coverage can grow by a texel on each side. A
    placement of a mesh with several blocks takes whole pages of its own (block b on page + b).
    Every page is finally cropped to one size (the runtime's array texture).

    ``names`` / ``instance_names`` label meshes and instances in messages; ``cache``
    (StageCache-like) keeps charts per mesh."""
    settings = settings or Uv2Settings()
    settings.validate()
    lods, instances = _instances(meshes, instances)
    names = list(names) if names is not None else [f"static mesh {i}" for i in range(len(lods))]
    instance_names = list(instance_names) if instance_names is not None else [names[i.mesh] for i in instances]
    density = [(i.texels_per_metre or settings.texels_per_metre) * i.scale for i in instances]  # texels per object unit
    placements = {m: [k for k, i in enumerate(instances) if i.mesh == m] for m in range(len(lods))}
    reference = {m: min(density[k] for k in ks) for m, ks in placements.items() if ks}
    texels = 0.0
    for k, inst in enumerate(instances):
        texels += float(_world_areas(lods[inst.mesh], 1.0).sum()) * density[k] ** 2
        if texels > settings.max_texels:
            raise CookError(f"uv2: {instance_names[k]}: the static meshes so far need about {texels:.3g} lightmap texels at "
                            f"{inst.texels_per_metre or settings.texels_per_metre:g} texels per metre, more than the cooker's limit of "
                            f"{settings.max_texels}; lower texels_per_metre")
    used = sorted(reference)
    jobs = []
    for m in used:
        lods[m].validate(names[m])
        if not np.isfinite(lods[m].attributes["position"]).all():
            raise CookError(f"uv2: {names[m]}: a vertex position is not finite")
        normals = lods[m].attributes.get("normal")
        jobs.append((_texel_positions(lods[m], reference[m]), np.ascontiguousarray(lods[m].triangles, np.uint32),
                     None if normals is None else np.ascontiguousarray(normals, np.float32)))
    charts = dict(zip(used, chart_meshes(jobs, settings, cache)))
    single = [m for m in used if len(placements[m]) == 1]
    shared = [m for m in used if len(placements[m]) > 1]

    out_lods: list[ir.Lod] = list(lods)
    mesh_charts: dict[int, np.ndarray] = {}

    def finish(m: int, vmapping: np.ndarray, uv1: np.ndarray, triangles: np.ndarray, blocks: np.ndarray, chart: np.ndarray) -> None:
        c = charts[m]
        vm = c.vmapping[vmapping] if len(c.vmapping) else np.zeros(0, np.uint32)
        attrs = {k: np.ascontiguousarray(v[vm]) for k, v in lods[m].attributes.items() if k != "uv1"}
        attrs["uv1"] = uv1.astype(np.float32) if len(uv1) else np.zeros((0, 2), np.float32)
        out_lods[m] = ir.Lod(attributes=attrs, triangles=triangles, materials=lods[m].materials.copy(), lightmap_blocks=blocks, error=lods[m].error)
        out_lods[m].validate(names[m])
        mesh_charts[m] = chart

    # Meshes placed several times: their blocks, at their reference density.
    blocks: dict[int, Packing] = {}
    for m in shared:
        scaled = any(density[k] > reference[m] * (1 + _SAME_SCALE) for k in placements[m])
        # Small enough that a block fits a page as a rectangle among charts, with the packer's
        # padding around it (as a chart does, _chart_options).
        room = 4 * ((settings.max_page_size - 2 * settings.xatlas_padding - 2) // 4)
        mesh_settings = dataclasses.replace(settings, padding=settings.padding + 2 if scaled else settings.padding, max_page_size=room)
        blocks[m] = pack_charts([charts[m]], mesh_settings, [names[m]], align=1)
    norm = {m: np.array([max(w for w, _ in b.pages), max(h for _, h in b.pages)], np.float64) for m, b in blocks.items()}
    for m, b in blocks.items():
        finish(m, b.vmapping[0], b.texel_uv[0] / norm[m], b.triangles[0], b.page[0], b.chart[0])

    # Every placement of a shared mesh: the scale of its blocks (lowered to fit a page if need be).
    warnings: list[str] = []
    factor = [1.0] * len(instances)
    for m in shared:
        biggest = max(max(w, h) for w, h in blocks[m].pages)
        room = settings.max_page_size if len(blocks[m].pages) > 1 else settings.max_page_size - 2 * settings.xatlas_padding - 2
        for k in placements[m]:
            f = density[k] / reference[m]
            f = 1.0 if f <= 1 + _SAME_SCALE else f
            if math.ceil(f * biggest - 1e-9) > room:
                fit = max(1.0, room / biggest)
                warnings.append(f"{instance_names[k]}: lightmap density lowered from {density[k] / instances[k].scale:g} to "
                                f"{fit * reference[m] / instances[k].scale:.3g} texels per metre to fit a {settings.max_page_size}-texel page")
                f = fit
            factor[k] = f
    size = lambda k, w, h: (math.ceil(factor[k] * w - 1e-9), math.ceil(factor[k] * h - 1e-9))

    # One packing of the single meshes' charts and the rectangles of single-block placements.
    rects = [k for m in shared if len(blocks[m].pages) == 1 for k in placements[m]]
    entries = [charts[m] for m in single] + [_rectangle(*size(k, *blocks[instances[k].mesh].pages[0])) for k in rects]
    region: list[dict | None] = [None] * len(instances)
    extent = np.ones(2)
    n_pages = 0
    if entries:
        entry_names = [names[m] for m in single] + [instance_names[k] for k in rects]
        pk = pack_groups(entries, settings, entry_names, rotate=not rects)
        n_pages = len(pk.pages)
        for e, t in enumerate(pk.texel_uv):
            if len(t):
                extent = np.maximum(extent, np.floor(t[pk.triangles[e]].reshape(-1, 2).max(axis=0)) + 1)
        for e, m in enumerate(single):
            finish(m, pk.vmapping[e], pk.texel_uv[e], pk.triangles[e], pk.page[e], pk.chart[e])
            region[placements[m][0]] = {"page": 0, "scale": None, "offset": [0.0, 0.0]}  # uv1 in page texels
        for e, k in enumerate(rects, start=len(single)):
            t = pk.texel_uv[e]
            # The packer places a chart's corner half a texel in (its bilinear border); the block's
            # texels start on the texel boundary below, inside what the packer reserved.
            lo = np.floor(t.min(axis=0))
            if not (np.allclose(t[0], t.min(axis=0)) and np.allclose(t[2], t.max(axis=0))):
                raise CookError(f"uv2: {instance_names[k]}: the packer turned its lightmap block (xatlas)")
            region[k] = {"page": int(pk.page[e][0]), "scale": factor[k] * norm[instances[k].mesh], "offset": lo}
    # Placements of meshes of several blocks: whole pages of their own.
    for m in shared:
        if len(blocks[m].pages) > 1:
            for k in placements[m]:
                region[k] = {"page": n_pages, "scale": factor[k] * norm[m], "offset": np.zeros(2)}
                for w, h in blocks[m].pages:
                    extent = np.maximum(extent, size(k, w, h))
                n_pages += len(blocks[m].pages)
    page_size = tuple(int(min(settings.max_page_size, 4 * math.ceil(e / 4))) for e in extent)
    regions = []
    for k, r in enumerate(region):
        # A mesh placed once keeps its uv1 in page texels and gets scale 1 / page size: the page's
        # crop (which any mesh's edit can change) then leaves its uv1, and its LOD chain that
        # carries them, as they were.
        scale = np.ones(2) if r["scale"] is None else np.asarray(r["scale"], np.float64)
        regions.append({"page": int(r["page"]), "scale": [float(x) for x in scale / page_size],
                        "offset": [float(x) for x in np.asarray(r["offset"], np.float64) / page_size]})
    layout = ir.LightmapLayout(texels_per_metre=float(settings.texels_per_metre), pages=[page_size] * n_pages, padding=int(settings.padding))
    result = Uv2Result(out_lods, regions, layout, {}, instances)
    result.stats = _stats(result, charts, mesh_charts, settings, names, instance_names, warnings)
    return result


def _stats(r: Uv2Result, charts, mesh_charts, settings: Uv2Settings, names, instance_names, warnings) -> dict:
    per_instance = []
    sum_w = sum_wd = sum_wr = 0.0
    chart_ids, base = [], 0
    placed = r.placed
    for k, (inst, lod) in enumerate(zip(r.instances, placed)):
        want = inst.texels_per_metre or settings.texels_per_metre
        d, w = triangle_densities(lod, inst.scale, r.layout.pages)
        mw = float(w.sum())
        measured = float((w * d).sum() / mw) if mw > 0 else 0.0
        sum_w += mw
        sum_wd += float((w * d).sum())
        sum_wr += float((w * d).sum()) / want
        ids = mesh_charts[inst.mesh]
        chart_ids.append(np.where(ids == NONE, NONE, ids + np.uint32(base)).astype(np.uint32))
        base += charts[inst.mesh].count
        region = r.regions[k]
        per_instance.append({
            "name": instance_names[k],
            "mesh": names[inst.mesh],
            "charts": int(charts[inst.mesh].count),
            "texels_per_metre": float(want),
            "measured_texels_per_metre": round(measured, 4),
            "density_ratio": round(measured / want, 4) if mw > 0 else None,
            "pages": sorted({int(p) for p in np.unique(lod.lightmap_blocks)}),
            "region": region,
        })
    stats = {
        "texels_per_metre": float(settings.texels_per_metre),
        "measured_texels_per_metre": round(sum_wd / sum_w, 4) if sum_w else 0.0,
        "density_ratio": round(sum_wr / sum_w, 4) if sum_w else 0.0,
        "padding": int(settings.padding),
        "pages": len(r.layout.pages),
        "page_sizes": [list(p) for p in r.layout.pages],
        "charts": int(base),
        "meshes": len({i.mesh for i in r.instances}),
        "instances": per_instance,
        "warnings": warnings,
    }
    if settings.verify:
        stats.update(verify_layout(placed, r.layout, chart_ids=chart_ids, names=instance_names))
        for inst, texels in zip(per_instance, stats.pop("lod_texels_baked")):
            inst["texels"] = texels
    return stats


# ---- rasterising pages (verification, previews, the baker) ---------------------------------------


def place_on_atlas(lod: ir.Lod, region: dict) -> ir.Lod:
    """A static instance's view of its mesh's lightmap: ``lod`` (with ``uv1`` in the mesh's own
    lightmap space and ``lightmap_blocks``) with ``uv1`` moved into its atlas region
    (``uv1 * scale + offset``, pack::LightmapRegion) and ``lightmap_blocks`` replaced by the pages
    they land on (``region["page"] + block``). What rasterising, verifying and baking a page read."""
    uv = lod.attributes["uv1"].astype(np.float64) * np.asarray(region["scale"], np.float64) + np.asarray(region["offset"], np.float64)
    pages = (lod.lightmap_blocks + np.uint32(region["page"])).astype(np.uint32)
    return ir.Lod(attributes={**lod.attributes, "uv1": uv.astype(np.float32)}, triangles=lod.triangles, materials=lod.materials,
                  lightmap_blocks=pages, error=lod.error)


def _charts_from_uv(uv: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """Chart per triangle from a page's UV mesh: triangles joined through vertices at the same UV."""
    if len(tris) == 0:
        return np.zeros(0, np.uint32)
    bits = np.ascontiguousarray(uv, np.float32).view(np.uint32).astype(np.uint64)
    key = (bits[:, 0] << np.uint64(32)) | bits[:, 1]
    _, vid = np.unique(key, return_inverse=True)
    t = np.ascontiguousarray(vid.reshape(-1)[tris].astype(np.uint32))
    return _core.triangle_components(t, int(vid.max()) + 1)


def page_mesh(lods: Sequence[ir.Lod], page: int, chart_ids: Sequence[np.ndarray] | None = None,
              positions: Sequence[np.ndarray] | None = None, normals: Sequence[np.ndarray | None] | None = None) -> dict:
    """The triangles of every Lod on one page, concatenated: ``uv`` (n, 2), ``triangles`` (m, 3),
    ``chart`` (m,) (from ``chart_ids`` per Lod, else recovered from the UV topology), ``mesh`` and
    ``mesh_triangle`` (m,) (which Lod and which of its triangles each is), and with
    ``positions``/``normals`` per Lod (default: each Lod's own) ``position`` / ``normal``."""
    uvs, tris, charts, mesh, mtri, pos, nrm = [], [], [], [], [], [], []
    base = 0
    chart_base = 0
    for i, lod in enumerate(lods):
        sel = np.flatnonzero(lod.lightmap_blocks == page)
        if len(sel) == 0:
            continue
        t = lod.triangles[sel]
        used, local = np.unique(t, return_inverse=True)
        uv = lod.attributes["uv1"][used]
        uvs.append(uv)
        tris.append(local.reshape(-1, 3).astype(np.uint32) + base)
        if chart_ids is not None:
            ch = chart_ids[i][sel]
        else:
            ch = _charts_from_uv(uv, local.reshape(-1, 3)) + chart_base
            chart_base = int(ch.max()) + 1
        charts.append(ch.astype(np.uint32))
        mesh.append(np.full(len(sel), i, np.uint32))
        mtri.append(sel.astype(np.uint32))
        p = lod.attributes["position"] if positions is None else positions[i]
        pos.append(np.asarray(p, np.float32)[used])
        n = lod.attributes.get("normal") if normals is None else normals[i]
        nrm.append(None if n is None else np.asarray(n, np.float32)[used])
        base += len(used)
    cat = lambda xs, shape, dt: np.ascontiguousarray(np.concatenate(xs) if xs else np.zeros(shape, dt), dt)
    out = {
        "uv": cat(uvs, (0, 2), np.float32),
        "triangles": cat(tris, (0, 3), np.uint32),
        "chart": cat(charts, (0,), np.uint32),
        "mesh": cat(mesh, (0,), np.uint32),
        "mesh_triangle": cat(mtri, (0,), np.uint32),
        "position": cat(pos, (0, 3), np.float32),
    }
    out["normal"] = cat(nrm, (0, 3), np.float32) if nrm and all(n is not None for n in nrm) else None
    return out


def rasterize_page(lods: Sequence[ir.Lod], layout: ir.LightmapLayout, page: int, *, conservative: bool = True,
                   surface: bool = True, chart_ids=None, positions=None, normals=None) -> dict:
    """Rasterise one page: the arrays of ``_core.rasterize_uv`` ((h, w) ``triangle``, ``chart``,
    ``charts_here``, (h, w, 3) ``barycentric``, and with ``surface`` the interpolated
    ``position`` and unit ``normal``), plus ``mesh`` / ``mesh_triangle`` to turn a texel's
    ``triangle`` into (Lod index, triangle of that Lod). For the baker: conservative coverage
    (every texel a chart touches), with world-space ``positions`` / ``normals`` per Lod if the
    Lods are not in world space."""
    w, h = layout.pages[page]
    m = page_mesh(lods, page, chart_ids, positions, normals)
    kw = {"positions": m["position"], "normals": m["normal"]} if surface else {}
    r = _core.rasterize_uv(m["uv"], m["triangles"], m["chart"], int(w), int(h), conservative, **kw)
    r["mesh"] = m["mesh"]
    r["mesh_triangle"] = m["mesh_triangle"]
    return r


def verify_layout(lods: Sequence[ir.Lod], layout: ir.LightmapLayout, *, chart_ids=None, names=None, raise_on_error: bool = True) -> dict:
    """Rasterise every page and check: no texel centre claimed by two charts, and every chart's
    conservative coverage at least ``padding`` empty texels from any other chart's. Returns
    utilisation (texel centres covered / page texels; ``utilisation_baked`` counts every texel
    the baker bakes) per page and overall, and what was found."""
    pad = int(layout.padding)
    limit = min(pad + 2, 250)
    centre_total = baked_total = area_total = 0
    overlapping = too_close = 0
    per_lod = np.zeros(len(lods), np.int64)
    min_gap = None
    page_util, page_baked = [], []
    for p, (w, h) in enumerate(layout.pages):
        m = page_mesh(lods, p, chart_ids)
        centre = _core.rasterize_uv(m["uv"], m["triangles"], m["chart"], int(w), int(h), False)
        baked = _core.rasterize_uv(m["uv"], m["triangles"], m["chart"], int(w), int(h), True)
        sep = _core.chart_separation(baked["chart"], baked["charts_here"], limit)
        covered = sep != 255
        tri = baked["triangle"][baked["charts_here"] > 0]
        per_lod += np.bincount(m["mesh"][tri], minlength=len(lods))
        n_centre = int((centre["charts_here"] > 0).sum())
        n_baked = int(covered.sum())
        overlapping += int((centre["charts_here"] > 1).sum())
        too_close += int((sep[covered] <= pad).sum())
        if covered.any():
            g = int(sep[covered].min()) - 1  # empty texels between the two closest charts
            if g < limit:
                min_gap = g if min_gap is None else min(min_gap, g)
        centre_total += n_centre
        baked_total += n_baked
        area_total += int(w) * int(h)
        page_util.append(round(n_centre / (w * h), 4))
        page_baked.append(round(n_baked / (w * h), 4))
    if raise_on_error and (overlapping or too_close):
        raise CookError(f"uv2: lightmap layout broken: {overlapping} texels claimed by two charts, "
                        f"{too_close} texels closer than {pad} texels to another chart")
    return {
        "utilisation": round(centre_total / area_total, 4) if area_total else 0.0,
        "utilisation_baked": round(baked_total / area_total, 4) if area_total else 0.0,
        "page_utilisation": page_util,
        "page_utilisation_baked": page_baked,
        "texels": int(area_total),
        "texels_baked": int(baked_total),
        "overlapping_texels": int(overlapping),
        "texels_within_padding": int(too_close),
        "min_chart_gap_texels": min_gap,
        "lod_texels_baked": [int(x) for x in per_lod],  # texels the baker bakes, per Lod given
    }


# ---- previews ----------------------------------------------------------------------------------

_BACKGROUND = np.array([24, 24, 28, 255], np.uint8)
_OVERLAP = np.array([255, 0, 0, 255], np.uint8)
_TOO_CLOSE = np.array([255, 0, 255, 255], np.uint8)


def _palette(ids: np.ndarray) -> np.ndarray:
    """A stable, distinct-ish colour per chart id (integer hash -> pastel RGB)."""
    x = ids.astype(np.uint64) * np.uint64(0x9E3779B97F4A7C15) + np.uint64(0x632BE59BD9B4E019)
    x ^= x >> np.uint64(29)
    rgb = np.stack([(x >> np.uint64(s)) & np.uint64(0xFF) for s in (0, 8, 16)], -1).astype(np.uint16)
    return (rgb // 2 + 100).astype(np.uint8)


def preview_image(lods: Sequence[ir.Lod], layout: ir.LightmapLayout, page: int, chart_ids=None) -> np.ndarray:
    """(h, w, 4) uint8 picture of one page: a colour per chart; texels the baker bakes but whose
    centre no chart contains (chart edges) darker; overlaps red; texels within the padding of
    another chart magenta."""
    w, h = layout.pages[page]
    m = page_mesh(lods, page, chart_ids)
    centre = _core.rasterize_uv(m["uv"], m["triangles"], m["chart"], int(w), int(h), False)
    baked = _core.rasterize_uv(m["uv"], m["triangles"], m["chart"], int(w), int(h), True)
    sep = _core.chart_separation(baked["chart"], baked["charts_here"], min(int(layout.padding) + 1, 250))
    img = np.empty((h, w, 4), np.uint8)
    img[:] = _BACKGROUND
    edge = baked["charts_here"] > 0
    img[edge, :3] = _palette(baked["chart"][edge]) // 2 + 20
    img[edge, 3] = 255
    inner = centre["charts_here"] > 0
    img[inner, :3] = _palette(centre["chart"][inner])
    img[(sep != 255) & (sep <= layout.padding)] = _TOO_CLOSE
    img[centre["charts_here"] > 1] = _OVERLAP
    return img


def placed_lods(scene: ir.Scene) -> list[ir.Lod]:
    """Every static instance with a lightmap region: its mesh's LOD 0 on the atlas, node order."""
    return [place_on_atlas(scene.meshes[n.mesh].lods[0], n.lightmap) for n in scene.nodes
            if n.lightmap is not None and n.mesh is not None]


def write_previews(scene: ir.Scene, folder: str | os.PathLike, min_size: int = 512) -> list[Path]:
    """One PNG per lightmap page of `scene` (static instances' LOD 0) in `folder`; small pages are
    enlarged by a whole factor (nearest texel) to at least `min_size` pixels. Returns the paths."""
    if scene.lightmap is None:
        return []
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    lods = placed_lods(scene)
    paths = []
    for p, (w, h) in enumerate(scene.lightmap.pages):
        img = preview_image(lods, scene.lightmap, p)
        k = max(1, -(-min_size // max(w, h)))
        if k > 1:
            img = np.repeat(np.repeat(img, k, axis=0), k, axis=1)
        path = folder / f"uv2_page{p}.png"
        _core.encode_png(path, np.ascontiguousarray(img))
        paths.append(path)
    return paths


__all__ = [
    "Uv2Settings", "MeshCharts", "Packing", "Instance", "Uv2Result", "lightmap_uvs", "place_on_atlas", "placed_lods", "chart_mesh", "chart_meshes", "pack_charts",
    "triangle_densities", "page_mesh", "rasterize_page", "verify_layout", "preview_image", "write_previews",
]
