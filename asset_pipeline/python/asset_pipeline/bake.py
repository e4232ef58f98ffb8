"""The bake stage: lightmaps for the static scene and irradiance probes for dynamic objects.

``bake_level(scene, settings, progress) -> Baked`` is a pure function of the scene and settings
(the orchestrator caches it by content hash); ``attach(scene, baked)`` puts the result into the
scene for the pack writer. The path tracer is Rust (``_core.Baker``, ``cook_core::bake``); this
module gathers its inputs, batches the work for progress and Ctrl-C, and orders the clean-up.

What is baked
-------------
- **The scene**: every instance of every static mesh (LOD 0, in world space through its node) is
  an occluder and a bounce surface; its albedo is the material's base colour times the average
  of its base colour texture over the triangle's UV0 footprint (linear light), its emission the
  material's emissive (nits). Lights and the sky come from the level. Dynamic meshes (props that
  move, characters) are not in it.
- **Lightmaps**: each atlas page is rasterised conservatively in UV2 space (every texel a chart
  touches, ``uv2.rasterize_page``) at the world position and normal of its sample point (a
  static mesh placed twice shares one lightmap: its first instance is baked); each covered texel
  gets B = H/pi (nits, linear). Then ``lightmap_post.finish_page``: OIDN denoise per chart,
  dilation into the gutters, seam stitching. Pages go into the pack as half-float textures and
  beside it as OpenEXR files.
- **Probes**: a grid over the static geometry's bounds, ``probe_spacing`` metres apart (wider if
  it would exceed ``max_probes``); each holds order-2 SH of B(n) = E(n)/pi without the sun's direct
  light, and the fraction of the sun's disk it sees (``cook_core::bake::probes``). Probes inside
  solid geometry (more than ``max_backface`` of their rays hit back faces) take the mean of their
  valid neighbours, grown outward until every such probe has a value.

Determinism: a texel's random streams are keyed by (seed, page, texel index), a probe's by its
grid index, so the same seed gives the same bytes for any thread count and batch size.
Ctrl-C is honoured between batches (about a second of work each): the stage raises
``KeyboardInterrupt`` and nothing is written.

With a Ray executor (executor.py) the texels of every page are cut into tiles of
``tile_texels`` and the probes into batches of ``probe_tile``, all submitted at once as tasks
against the scene put once into the object store; rasterising the pages, the clean-up
(``finish_page``) and filling the probes inside geometry stay in the driver.
"""

from __future__ import annotations

import dataclasses
import json
import time
from dataclasses import dataclass, field

import numpy as np

from asset_pipeline import _core, ir
from asset_pipeline.lightmap_post import NONE, LightmapPostSettings, finish_page, page_seams
from asset_pipeline.uv2 import rasterize_page

PRESETS = ("draft", "medium", "high")


@dataclass(frozen=True)
class BakeSettings:
    """Settings of the bake stage (all but `threads` are part of its cache key)."""

    preset: str = "medium"  # draft | medium | high (cook_core::bake::integrator::BakeSettings::preset)
    samples: int | None = None  # paths per lightmap texel (None: the preset's)
    bounces: int | None = None  # indirect bounces (None: the preset's)
    probe_samples: int | None = None  # rays per probe (None: the preset's)
    seed: int = 0
    probe_spacing: float = 2.0  # metres between probes
    max_probes: int = 4096
    max_backface: float = 0.25  # probes seeing more back faces than this are inside geometry
    post: LightmapPostSettings = field(default_factory=LightmapPostSettings)
    batch_texels: int = 16384  # texels per call: progress and Ctrl-C granularity
    threads: int | None = None  # None: all cores (does not change the result)
    # With the Ray executor: texels per task and probes per task (neither changes the result).
    # Smaller tiles balance better across workers; each costs a round trip (see README).
    tile_texels: int = 4096
    probe_tile: int = 128

    def key_doc(self) -> dict:
        return {k: v for k, v in dataclasses.asdict(self).items() if k not in SCHEDULING}


# Settings that change how the work is cut up and where it runs, never the result: left out of
# every cache key.
SCHEDULING = ("threads", "batch_texels", "tile_texels", "probe_tile")


@dataclass
class Baked:
    pages: list[np.ndarray]  # (h, w, 3) float32 per atlas page: the finished lightmap
    probes: ir.ProbeGrid | None
    stats: dict


# ---- the scene --------------------------------------------------------------------------------


def world_transforms(scene: ir.Scene) -> list[np.ndarray]:
    """4x4 world matrix (row-major, column vectors) of every node."""
    world: list[np.ndarray] = []
    for n in scene.nodes:
        local = np.array(n.local, dtype=np.float64).reshape(4, 4).T  # column-major -> row-major
        world.append(world[n.parent] @ local if n.parent is not None else local)
    return world


@dataclass
class StaticScene:
    """The static geometry as the baker sees it."""

    positions: np.ndarray  # (n, 3) float32, world space, all instances
    triangles: np.ndarray  # (m, 3) uint32
    albedo: np.ndarray  # (m, 3) float32
    emission: np.ndarray  # (m, 3) float32, nits
    # Per static mesh (scene order): its LOD 0 and the world positions / normals of its first
    # instance (what its lightmap texels are baked at), or None if no node places it.
    meshes: list[int]
    lods: list[ir.Lod]
    world_positions: list[np.ndarray]
    world_normals: list[np.ndarray]


def static_scene(scene: ir.Scene) -> StaticScene:
    world = world_transforms(scene)
    pos, tri, alb, emi = [], [], [], []
    first: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    base = 0
    for node, w in zip(scene.nodes, world):
        if node.mesh is None or not scene.meshes[node.mesh].static:
            continue
        lod = scene.meshes[node.mesh].lods[0]
        p = lod.attributes["position"].astype(np.float64) @ w[:3, :3].T + w[:3, 3]
        nrm = lod.attributes.get("normal")
        if nrm is not None:
            # Normals go through the inverse transpose; renormalised.
            nrm = nrm.astype(np.float64) @ np.linalg.inv(w[:3, :3])
            nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-30)
        first.setdefault(node.mesh, (p.astype(np.float32), None if nrm is None else nrm.astype(np.float32)))
        t = lod.triangles.astype(np.int64)
        if np.linalg.det(w[:3, :3]) < 0:
            t = t[:, ::-1]  # a mirroring transform flips the winding: keep fronts outward
        pos.append(p.astype(np.float32))
        tri.append(t + base)
        base += len(p)
        a, e = triangle_materials(scene, lod)
        alb.append(a)
        emi.append(e)
    cat = lambda xs, shape, dt: np.ascontiguousarray(np.concatenate(xs) if xs else np.zeros(shape, dt), dt)
    meshes = sorted(first)
    return StaticScene(
        positions=cat(pos, (0, 3), np.float32),
        triangles=cat(tri, (0, 3), np.uint32),
        albedo=cat(alb, (0, 3), np.float32),
        emission=cat(emi, (0, 3), np.float32),
        meshes=meshes,
        lods=[scene.meshes[i].lods[0] for i in meshes],
        world_positions=[first[i][0] for i in meshes],
        world_normals=[first[i][1] for i in meshes],
    )


def triangle_materials(scene: ir.Scene, lod: ir.Lod) -> tuple[np.ndarray, np.ndarray]:
    """Per triangle: albedo (base colour x the texture's mean over the triangle's UV0 footprint,
    linear) and emission (nits)."""
    mats = scene.materials
    base = np.array([m.base_color[:3] for m in mats], np.float64).reshape(-1, 3)
    emissive = np.array([m.emissive for m in mats], np.float64).reshape(-1, 3)
    albedo = base[lod.materials]
    uv = lod.attributes.get("uv0")
    for mi, m in enumerate(mats):
        if m.base_color_texture is None or uv is None:
            continue
        sel = np.flatnonzero(lod.materials == mi)
        if len(sel):
            tex = scene.textures[m.base_color_texture]
            albedo[sel] *= _footprint_means(tex, uv[lod.triangles[sel]])
    return np.clip(albedo, 0.0, 1.0).astype(np.float32), emissive[lod.materials].astype(np.float32)


def _linear_texels(tex: ir.Texture) -> np.ndarray:
    img = np.asarray(tex.mips[0])[..., :3].astype(np.float64)
    if tex.format == "Rgba16Float":
        return img
    img /= 255.0
    if tex.format == "Rgba8Srgb":
        img = np.where(img <= 0.04045, img / 12.92, ((img + 0.055) / 1.055) ** 2.4)
    return img


def _footprint_means(tex: ir.Texture, uv: np.ndarray) -> np.ndarray:
    """Mean linear colour of the texture over each triangle's UV bounding box ((k, 3, 2) UVs),
    texel-aligned, wrapping like a repeating sampler (a box a whole repeat wide or more covers the
    texture). A summed-area table makes each box four lookups."""
    img = _linear_texels(tex)
    h, w, _ = img.shape
    sat = np.zeros((h + 1, w + 1, 3))
    sat[1:, 1:] = img.cumsum(0).cumsum(1)
    lo, hi = uv.min(axis=1), uv.max(axis=1)  # (k, 2)

    def spans(a, b, size):
        start = np.floor(a * size).astype(np.int64)
        width = np.clip(np.ceil(b * size).astype(np.int64) - start, 1, size)
        start %= size
        first_end = np.minimum(start + width, size)
        return start, first_end, width - (first_end - start)  # [start, first_end) then [0, rest)

    def box(y0, y1, x0, x1):
        return sat[y1, x1] - sat[y0, x1] - sat[y1, x0] + sat[y0, x0]

    xs, xe, xr = spans(lo[:, 0], hi[:, 0], w)
    # glTF's UV origin is the image's top-left corner: rows go down with v.
    ys, ye, yr = spans(lo[:, 1], hi[:, 1], h)
    zero = np.zeros_like(xs)
    total = box(ys, ye, xs, xe) + box(ys, ye, zero, xr) + box(zero, yr, xs, xe) + box(zero, yr, zero, xr)
    count = ((xe - xs) + xr) * ((ye - ys) + yr)
    return total / count[:, None]


def _lights_json(scene: ir.Scene) -> str:
    return json.dumps([dataclasses.asdict(l) for l in scene.lights])


def _sky(scene: ir.Scene):
    if scene.sky is None:
        return None
    return tuple(float(c) * float(scene.sky.intensity) for c in scene.sky.color)


# ---- lightmaps ----------------------------------------------------------------------------------


def _texel_ids(page: int, flat: np.ndarray) -> np.ndarray:
    return (np.uint64(page) << np.uint64(40)) | flat.astype(np.uint64)


def bake_level(scene: ir.Scene, settings: BakeSettings | None = None, progress=None, executor=None) -> Baked:
    """`executor`: None bakes in this process; a RayExecutor bakes tiles as Ray tasks (same bytes)."""
    s = settings or BakeSettings()
    if s.preset not in PRESETS:
        raise ValueError(f"bake: unknown preset '{s.preset}' ({', '.join(PRESETS)})")
    layout = scene.lightmap
    st = static_scene(scene)
    stats: dict = {"preset": s.preset, "static_triangles": int(len(st.triangles))}
    if len(st.triangles) == 0:
        return Baked(pages=[], probes=None, stats=stats)
    kw = dict(preset=s.preset, seed=int(s.seed), bounces=s.bounces, threads=s.threads)
    inputs = []  # per page: (w, h, chart, covered, points, normals, ids)
    for page, (w, h) in enumerate(layout.pages if layout else []):
        r = rasterize_page(st.lods, layout, page, positions=st.world_positions, normals=st.world_normals)
        chart = r["chart"]
        covered = np.flatnonzero(chart.ravel() != NONE)
        points = np.ascontiguousarray(r["position"].reshape(-1, 3)[covered])
        normals = np.ascontiguousarray(r["normal"].reshape(-1, 3)[covered])
        inputs.append((w, h, chart, covered, points, normals, _texel_ids(page, covered)))
    probe_points, probe_layout = _probe_points(st, s)

    if executor is None:
        t0 = time.perf_counter()
        baker = _core.Baker(st.positions, st.triangles, st.albedo, st.emission, _lights_json(scene), _sky(scene))
        stats["bvh_seconds"] = time.perf_counter() - t0
        traced = [_bake_page_local(baker, page, inp, s, kw, progress) for page, inp in enumerate(inputs)]
        t_probes = time.perf_counter()
        probe_out = _bake_probes_local(baker, probe_points, s, progress, kw)
        probe_seconds = time.perf_counter() - t_probes
    else:
        traced, probe_out, probe_seconds = _bake_on_ray(executor, scene, st, inputs, probe_points, s, kw, progress, stats)

    pages: list[np.ndarray] = []
    rays_total, texels_total, bake_seconds = 0, 0, 0.0
    page_stats = []
    for page, ((w, h, chart, covered, *_), (raw, rays, seconds)) in enumerate(zip(inputs, traced)):
        seams = page_seams(st.lods, layout, page, positions=st.world_positions, normals=st.world_normals,
                           min_normal_cos=s.post.seam_min_normal_cos) if s.post.stitch else None
        t_post = time.perf_counter()
        done = finish_page(raw.reshape(h, w, 3), chart, seams=seams, settings=s.post)
        pages.append(done.image)
        page_stats.append({"page": page, "texels": int(len(covered)), "rays": int(rays), "seconds": seconds,
                           "post_seconds": time.perf_counter() - t_post, "denoised": bool(done.info.get("denoise", {}).get("denoised", False))})
        rays_total += rays
        texels_total += len(covered)
        bake_seconds += seconds
    stats.update(pages=page_stats, texels=int(texels_total), rays=int(rays_total), lightmap_seconds=bake_seconds,
                 rays_per_s=rays_total / bake_seconds if bake_seconds > 0 else 0.0)

    probes, probe_stats = _finish_probes(probe_layout, probe_out, s)
    stats["probes"] = probe_stats
    stats["probe_seconds"] = probe_seconds
    return Baked(pages=pages, probes=probes, stats=stats)


def _bake_page_local(baker, page: int, inp, s: BakeSettings, kw: dict, progress):
    """One page's covered texels in batches: (raw (h*w, 3), rays, seconds)."""
    w, h, _, covered, points, normals, ids = inp
    raw = np.zeros((h * w, 3), np.float32)
    rays, t_page = 0, time.perf_counter()
    with _stage(progress, f"bake p{page}", len(covered)) as bar:
        for a in range(0, len(covered), s.batch_texels):
            b = min(a + s.batch_texels, len(covered))
            out, n = baker.bake_points(points[a:b], normals[a:b], ids[a:b], samples=s.samples, **kw)
            raw[covered[a:b]] = out
            rays += n
            seconds = time.perf_counter() - t_page
            bar.note(f"{rays / max(seconds, 1e-9) / 1e6:.2f} Mrays/s")
            bar.advance(b - a)
    return raw, rays, time.perf_counter() - t_page


def _bake_on_ray(executor, scene: ir.Scene, st: StaticScene, inputs, probe_points: np.ndarray, s: BakeSettings, kw: dict, progress, stats: dict):
    """Every page's texels in tiles and the probes in batches as Ray tasks, submitted together so
    the cluster stays busy across page boundaries. Returns what the local path returns."""
    from asset_pipeline import executor as ex

    # The scene goes into the object store once; tasks carry the reference boxed in a list (a
    # bare ObjectRef argument would be fetched and deserialised for every task).
    ref = executor.put((st.positions, st.triangles, st.albedo, st.emission, _lights_json(scene), _sky(scene)))
    boxed = [ref]
    key = ref.hex()
    task_kw = {**kw, "threads": 1}  # one CPU per task (executor.RayExecutor._task)
    tiles, probe_batches = [], []
    for page, (_, _, _, covered, points, normals, ids) in enumerate(inputs):
        for a in range(0, len(covered), s.tile_texels):
            b = min(a + s.tile_texels, len(covered))
            tiles.append((page, a, b, (key, boxed, points[a:b], normals[a:b], ids[a:b], {**task_kw, "samples": s.samples})))
    ids = np.arange(len(probe_points), dtype=np.uint64)
    for a in range(0, len(probe_points), s.probe_tile):
        b = min(a + s.probe_tile, len(probe_points))
        probe_batches.append((a, b, (key, boxed, probe_points[a:b], ids[a:b], {**task_kw, "probe_samples": s.probe_samples})))

    total = len(tiles) + len(probe_batches)
    rays = [0]
    workers: set = set()
    builds = [0]
    t0 = time.perf_counter()
    with _stage(progress, "bake tiles", total) as bar:
        def done(result):
            rays[0] += result[-4]
            workers.add(result[-3])
            builds[0] += bool(result[-2])
            bar.note(f"{rays[0] / max(time.perf_counter() - t0, 1e-9) / 1e6:.2f} Mrays/s on {len(workers)} worker(s)")
            bar.advance()

        # Both kinds are submitted before waiting on either, so they share the cluster.
        calls = [(ex.bake_tile, t[3]) for t in tiles] + [(ex.bake_probe_batch, p[2]) for p in probe_batches]
        results = executor.run(calls, on_done=lambda i, r: done(r))
    tile_results, probe_results = results[:len(tiles)], results[len(tiles):]
    wall = time.perf_counter() - t0

    traced = []
    for page, (w, h, _, covered, *_) in enumerate(inputs):
        raw = np.zeros((h * w, 3), np.float32)
        page_rays, page_seconds = 0, 0.0
        for (p, a, b, _), (out, n, _, _, seconds) in zip(tiles, tile_results):
            if p == page:
                raw[covered[a:b]] = out
                page_rays += n
                page_seconds += seconds
        traced.append((raw, page_rays, page_seconds))  # seconds: summed over the page's tasks
    n = len(probe_points)
    sh, sun, back = np.zeros((n, 9, 3), np.float32), np.ones(n, np.float32), np.zeros(n, np.float32)
    probe_rays, probe_seconds = 0, 0.0
    for (a, b, _), (bsh, bsun, bback, r, _, _, seconds) in zip(probe_batches, probe_results):
        sh[a:b], sun[a:b], back[a:b] = bsh, bsun, bback
        probe_rays += r
        probe_seconds += seconds
    stats["ray"] = {"tiles": len(tiles), "probe_batches": len(probe_batches), "tile_texels": s.tile_texels, "probe_tile": s.probe_tile,
                    "workers": len(workers), "scene_builds": builds[0], "wall_seconds": wall,
                    "task_seconds": sum(t[2] for t in traced) + probe_seconds,
                    "rays_per_s": rays[0] / wall if wall > 0 else 0.0}
    return traced, (sh, sun, back, probe_rays), probe_seconds


# ---- probes -------------------------------------------------------------------------------------


def probe_grid(positions: np.ndarray, spacing: float, max_probes: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(origin, spacing, counts) of a grid covering the bounds of `positions`, cells of about
    `spacing` metres (widened until at most `max_probes`), probes at cell centres."""
    lo, hi = positions.min(axis=0).astype(np.float64), positions.max(axis=0).astype(np.float64)
    extent = np.maximum(hi - lo, 1e-3)
    step = float(spacing)
    while True:
        counts = np.maximum(np.ceil(extent / step).astype(np.int64), 1)
        if counts.prod() <= max_probes:
            break
        step *= 1.05
    cell = extent / counts
    return lo + 0.5 * cell, cell, counts


def _probe_points(st: StaticScene, s: BakeSettings):
    """The probe positions (float32 (n, 3), probe = i + nx (j + ny k)) and the grid (origin, cell, counts)."""
    origin, cell, counts = probe_grid(st.positions, s.probe_spacing, s.max_probes)
    nx, ny, nz = (int(c) for c in counts)
    k, j, i = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
    idx = np.stack([i.ravel(), j.ravel(), k.ravel()], 1)
    return np.ascontiguousarray((origin + idx * cell).astype(np.float32)), (origin, cell, counts)


def _bake_probes_local(baker, points: np.ndarray, s: BakeSettings, progress, kw):
    """(sh, sun visibility, backface, rays) of every probe, in batches."""
    ids = np.arange(len(points), dtype=np.uint64)
    sh = np.zeros((len(points), 9, 3), np.float32)
    sun = np.ones(len(points), np.float32)
    back = np.zeros(len(points), np.float32)
    batch = max(1, s.batch_texels // 64)
    rays = 0
    with _stage(progress, "probes", len(points)) as bar:
        for a in range(0, len(points), batch):
            b = min(a + batch, len(points))
            sh[a:b], sun[a:b], back[a:b], n = baker.bake_probes(points[a:b], ids[a:b], probe_samples=s.probe_samples, **kw)
            rays += n
            bar.advance(b - a)
    return sh, sun, back, rays


def _finish_probes(grid, traced, s: BakeSettings) -> tuple[ir.ProbeGrid, dict]:
    (origin, cell, counts), (sh, sun, back, rays) = grid, traced
    nx, ny, nz = (int(c) for c in counts)
    count = len(back)
    inside = back > s.max_backface
    sh, sun = _fill_invalid(sh.reshape(nz, ny, nx, 27), sun.reshape(nz, ny, nx), inside.reshape(nz, ny, nx))
    grid = ir.ProbeGrid(origin=tuple(float(x) for x in origin), spacing=tuple(float(x) for x in cell), counts=(nx, ny, nz),
                        sh=np.ascontiguousarray(sh.reshape(-1, 9, 3)), sun_visibility=np.ascontiguousarray(sun.reshape(-1)))
    return grid, {"count": int(count), "counts": [nx, ny, nz], "spacing": [float(x) for x in cell],
                  "inside_geometry": int(inside.sum()), "rays": int(rays)}


def _fill_invalid(sh: np.ndarray, sun: np.ndarray, invalid: np.ndarray):
    """Give each invalid probe the mean of its valid face neighbours, ring by ring outward, so
    values spread from open space into walls (where a dynamic object near a wall samples them)."""
    sh, sun, valid = sh.copy(), sun.copy(), ~invalid
    if not valid.any():
        return np.zeros_like(sh), np.ones_like(sun)
    while not valid.all():
        acc_sh, acc_sun, cnt = np.zeros_like(sh), np.zeros_like(sun), np.zeros(sun.shape)
        for axis in range(3):
            for shift in (1, -1):
                v = np.roll(valid, shift, axis)
                # np.roll wraps around: cut the wrapped slab.
                edge = [slice(None)] * 3
                edge[axis] = slice(0, 1) if shift == 1 else slice(-1, None)
                v[tuple(edge)] = False
                acc_sh += np.where(v[..., None], np.roll(sh, shift, axis), 0.0)
                acc_sun += np.where(v, np.roll(sun, shift, axis), 0.0)
                cnt += v
        grow = ~valid & (cnt > 0)
        sh[grow] = acc_sh[grow] / cnt[grow][:, None]
        sun[grow] = acc_sun[grow] / cnt[grow]
        valid = valid | grow
    return sh, sun


# ---- into the scene -----------------------------------------------------------------------------


def attach(scene: ir.Scene, baked: Baked) -> ir.Scene:
    """The scene with the baked pages as Rgba16Float textures (referenced by its lightmap
    layout) and the probes."""
    textures = list(scene.textures)
    ids = []
    for page, img in enumerate(baked.pages):
        h, w, _ = img.shape
        rgba = np.concatenate([img, np.ones((h, w, 1), np.float32)], axis=2)
        ids.append(len(textures))
        textures.append(ir.Texture(name=f"lightmap{page}", width=w, height=h, format="Rgba16Float",
                                   mips=[np.ascontiguousarray(np.clip(rgba, 0.0, 65504.0).astype(np.float16))]))
    layout = None if scene.lightmap is None else dataclasses.replace(scene.lightmap, textures=ids)
    return dataclasses.replace(scene, textures=textures, lightmap=layout, probes=baked.probes)


class _NoBar:
    def advance(self, n: int = 1) -> None:
        pass

    def note(self, text: str) -> None:
        pass


def _stage(progress, name: str, total: int):
    if progress is None:
        from contextlib import nullcontext

        return nullcontext(_NoBar())
    return progress.stage(name, total)


def describe(stats: dict) -> list[str]:
    """Report lines for the bake."""
    lines = [f"Preset {stats.get('preset')}; {stats.get('static_triangles', 0)} static triangles."]
    if stats.get("texels"):
        lines.append(f"Lightmaps: {stats['texels']} texels, {stats['rays'] / 1e6:.1f} M rays in {stats['lightmap_seconds']:.1f} s "
                     f"({stats['rays_per_s'] / 1e6:.2f} M rays/s).")
        for p in stats.get("pages", []):
            lines.append(f"- page {p['page']}: {p['texels']} texels, {p['rays'] / 1e6:.1f} M rays, {p['seconds']:.1f} s bake + "
                         f"{p['post_seconds']:.1f} s clean-up{' (denoised)' if p['denoised'] else ''}")
    r = stats.get("ray")
    if r:
        lines.append(f"On Ray: {r['tiles']} tiles of {r['tile_texels']} texels and {r['probe_batches']} probe batches of {r['probe_tile']} "
                     f"on {r['workers']} worker(s) (scene built {r['scene_builds']} time(s)), {r['wall_seconds']:.1f} s wall, "
                     f"{r['rays_per_s'] / 1e6:.2f} M rays/s across the cluster; per-page seconds are summed over tasks.")
    pr = stats.get("probes")
    if pr:
        lines.append(f"Probes: {pr['count']} ({' x '.join(str(c) for c in pr['counts'])}, cells "
                     f"{' x '.join(f'{x:.2f}' for x in pr['spacing'])} m), {pr['inside_geometry']} inside geometry (filled from "
                     f"neighbours), {pr['rays'] / 1e6:.1f} M rays in {stats.get('probe_seconds', 0.0):.1f} s.")
    return lines

