"""The cook: source -> scene IR -> lightmap UVs -> bake -> level chunks -> LOD chains -> pack + report.

Each stage is a pure function of its inputs and settings, cached by a hash of both and the
cooker's code (cache.py). The whole cook also has a key: when the output already exists and was
made from the same key, nothing runs and no file is touched.

Stage order: lightmap UVs come before LODs, so every LOD carries LOD 0's lightmap UVs as an
attribute and one baked lightmap serves the whole chain. The bake reads only LOD 0 and writes its
pages into the pack (half-float textures) and beside it as OpenEXR files,
`<pack>.lightmap<N>.exr`. The chunk stage (chunks.py) then cuts large static meshes into level
chunks that share their mesh's baked lightmap region, so the pages are baked from whole meshes
and a border between chunks reads the same texels from both; the LOD stage comes after it, so
every chunk gets its own chain (borders locked). The textures stage then gives every material
texture its mip chain (lightmap pages keep one level).
"""

from __future__ import annotations

import collections
import dataclasses
import json
import math
import os
import re
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from asset_pipeline import ir
from asset_pipeline._core import CookError
from asset_pipeline.cache import (DEFAULT_CACHE_MAX, Hasher, StageCache, file_lock, format_size, library_version, parse_size,
                                  process_running, write_atomic)
from asset_pipeline.vertex_format import uv_precision_warnings
from asset_pipeline.gltf_import import import_gltf_scene, write_pack
from asset_pipeline.progress import Progress
from asset_pipeline.report import write_report


@dataclass
class CookSettings:
    lod: "object | None" = None  # asset_pipeline.lod.LodSettings; None = defaults
    chunk: "object | None" = None  # asset_pipeline.chunks.ChunkSettings; None = defaults
    uv2: "object | None" = None  # asset_pipeline.uv2.Uv2Settings; None = defaults (density from the level)
    bake: "object | None" = None  # asset_pipeline.bake.BakeSettings; None = defaults
    lods: bool = True
    chunks: bool = True  # cut large static meshes into level chunks (chunks.py)
    lightmap_uvs: bool = True
    # Lightmap density of static surfaces, texels per metre: overrides the level's; a glTF scene
    # without it gets Uv2Settings' default, lowered to fit AUTO_LIGHTMAP_TEXELS.
    texels_per_metre: float | None = None
    baking: bool = True  # bake lightmaps and probes (when the scene has lightmap UVs)
    mips: bool = True  # mip chains for material textures (lightmaps keep one level)
    # Block-compress material textures (compress.py: BC7 colour and data, BC5 normals, BC4
    # occlusion), each kept uncompressed where it would miss its quality bar.
    compress: bool = True
    # Per texture: glob pattern of texture names -> "auto" | "none" | "force" (compress.py).
    texture_compression: dict = field(default_factory=dict)
    mesh_opt: bool = True  # every LOD in vertex cache, overdraw and vertex fetch order (mesh_opt.py)
    mip_filter: str | None = None  # box|tent|bspline|mitchell|catmull-rom|lanczos3; None = per usage (mitchell, tent for hdr)
    force: bool = False  # ignore every cache entry and rebuild
    cache_dir: Path | None = None  # default: .cook-cache beside the output
    # The stage cache's bound in bytes: after each cook the least recently used entries go until
    # it holds at most this (cache.evict). None: $COOK_CACHE_MAX (a size: 500M, 4G, 1.5GiB), else 4 GiB.
    cache_max: int | None = None
    report: bool = True
    # Where independent work runs (executor.py): "local" (this process) or "ray" (Ray tasks on
    # the cluster at ray_address; None: as ray.init(): $RAY_ADDRESS, else a cluster `ray start`ed
    # on this machine, else a new local instance). Same bytes either way.
    # An executor.RayExecutor instance may be given instead, to share one across cooks and read
    # its counters (tasks submitted, cancelled).
    executor: "str | object" = "local"
    ray_address: str | None = None
    # The uniform sky a glTF scene is baked under, in nits (an overcast day); 0: none, so only
    # its lights and emissive surfaces light it. Levels bring their own sky.
    sky_nits: float = 1000.0
    # Read buffers, images, textures and props outside the source's folder tree (absolute paths,
    # file: URIs, `..` that leads out); off, such a path is an error.
    allow_external_uris: bool = False
    # A bake.Refinement to go on from (`cook --watch` refining a bake step by step): the bake
    # stage adds to its sums instead of tracing every sample again. Not part of any key: each
    # step's result is, to the bit, the one-shot bake of its settings.
    refine: "object | None" = None


@dataclass
class StageRecord:
    name: str
    seconds: float = 0.0
    items: int = 0
    cached: int = 0


@dataclass
class CookResult:
    summary: dict
    up_to_date: bool
    stages: list[StageRecord] = field(default_factory=list)
    report: Path | None = None
    tasks_submitted: int = 0  # tasks the executor submitted (0 for local, and for a fully cached cook)
    uv2: dict = field(default_factory=dict)  # the uv2 stage's measurements (instances, pages, utilisation)
    bake: dict = field(default_factory=dict)  # the bake's (texels, rays, seconds per page and instance)
    scene: "ir.Scene | None" = None  # the scene as written (None when up to date)
    chunks: dict = field(default_factory=dict)  # the chunk stage's (chunks.split_chunks' stats)
    mesh_opt: dict = field(default_factory=dict)  # the mesh_opt stage's (mesh_opt.MeshOptStats.as_dict)
    compress: dict = field(default_factory=dict)  # the compress stage's (compress.summarise)
    # Every file the cook read: the source, then what it names (props, buffers, images,
    # textures), resolved, in first-read order; what `cook --watch` watches.
    files: list[str] = field(default_factory=list)
    # Every stage cache file the cook loaded or stored (its entries and its output stamp): what
    # the cache's eviction after it kept.
    cache_entries: list[str] = field(default_factory=list)


def _settings_doc(obj) -> object:
    return dataclasses.asdict(obj) if dataclasses.is_dataclass(obj) else obj


# ---- the source stage: glTF import or CSG level -----------------------------------------------


def _load_source(source: Path, settings: CookSettings) -> ir.Scene:
    if source.suffix.lower() == ".toml":
        from asset_pipeline.csg import build_level
        from asset_pipeline.level import load_level

        return build_level(load_level(source, settings.allow_external_uris))
    return import_gltf_scene(source, allow_external_uris=settings.allow_external_uris)


def _files_key(files: list[str]) -> str | None:
    """A key of the files' paths and bytes; None when one cannot be read (gone, renamed)."""
    h = Hasher("files")
    try:
        for f in files:
            h.file(Path(f))
    except OSError:
        return None
    return h.key()


def _source_key(source: Path, files: list[str] | None) -> str | None:
    """The source stage's key: every file the last import of `source` read, by content, and
    the libraries it ran (manifold3d builds levels). None when that is not known."""
    files_key = _files_key(files) if files else None
    if files_key is None:
        return None
    libraries = {"manifold3d": library_version("manifold3d")} if source.suffix.lower() == ".toml" else {}
    return Hasher("source").text(files_key).settings(libraries).key()


def _read_files(source: Path, scene: ir.Scene) -> list[str]:
    """The source and every file its import read, each once (resolved paths, first-read order)."""
    seen: dict[str, None] = {}
    for f in [source, *scene.files]:
        seen.setdefault(os.fspath(Path(f).resolve()), None)
    return list(seen)


def uniform_scale(world: np.ndarray) -> float:
    """The uniform scale of a transform (the cube root of its 3x3 determinant's size): how much
    a lightmap density in world metres is worth per object-space metre."""
    return float(abs(np.linalg.det(world[:3, :3])) ** (1.0 / 3.0)) or 1.0


def cook(source: str | os.PathLike, out: str | os.PathLike, settings: CookSettings | None = None, progress: Progress | None = None) -> CookResult:
    """Cook `source` (.gltf, .glb or a level .toml) into the pack `out` (written atomically) and
    a report beside it. Raises CookError on bad input, naming the file and the problem.
    At the end the stage cache is trimmed to its limit (settings.cache_max)."""
    settings = settings or CookSettings()
    progress = progress or Progress(enabled=False)
    try:
        cache = StageCache(cache_root(settings, Path(out)), enabled=not settings.force, max_bytes=cache_limit(settings))
        try:
            result = _cook(source, out, settings, progress, cache)
        except CookError:
            _trim(cache, progress)  # what a failed cook stored counts too
            raise
        else:
            _trim(cache, progress)
        finally:
            cache.end()
        result.cache_entries = sorted(os.fspath(p) for p in cache.used)
        return result
    except CookError as e:
        # Later stages (uv2, bake, textures) name the mesh or texture; say which file it came from.
        if os.fspath(source) not in str(e):
            raise CookError(f"{os.fspath(source)}: {e}") from None
        raise


def cache_root(settings: CookSettings, out: Path) -> Path:
    """The stage cache of a cook into `out`: settings.cache_dir, else `.cook-cache` beside it."""
    return Path(settings.cache_dir) if settings.cache_dir is not None else Path(out).parent / ".cook-cache"


def cache_limit(settings: CookSettings) -> int:
    """The stage cache's bound in bytes: settings.cache_max, else $COOK_CACHE_MAX, else 4 GiB."""
    if settings.cache_max is not None:
        if settings.cache_max < 0:
            raise CookError(f"cache_max {settings.cache_max} is negative")
        return int(settings.cache_max)
    text = os.environ.get("COOK_CACHE_MAX", "").strip()
    if not text:
        return DEFAULT_CACHE_MAX
    try:
        return parse_size(text)
    except ValueError as e:
        raise CookError(f"COOK_CACHE_MAX: {e}") from None


def _trim(cache: StageCache, progress: Progress) -> None:
    """Evict the least recently used entries down to the cache's limit; say what went, and when
    what is in use alone is over the limit (kept: not an error)."""
    try:
        e = cache.trim()
    except OSError as err:  # a cache we may not write: the cook itself went well
        progress.warning(f"stage cache {cache.root}: not trimmed: {err}")
        return
    if e.removed:
        progress.line(f"cache: removed {e.removed} least recently used entr{'y' if e.removed == 1 else 'ies'} ({format_size(e.freed)}); "
                      f"{format_size(e.total)} of {format_size(e.limit)} in {cache.root}")
    if e.total > e.limit:
        others = f" and {e.cooks} other running cook{'s' if e.cooks != 1 else ''}" if e.cooks else ""
        progress.warning(f"stage cache {cache.root}: the entries this cook{others} use{'s' if not others else ''} ({format_size(e.in_use)}) are more than "
                         f"its limit ({format_size(e.limit)}, --cache-max); kept them")


def _recorded_output(out: Path, stamp: Path, source_key: str | None, settings_doc: dict, settings: CookSettings) -> dict | None:
    """The record of `out` (its summary) when it is what this cook would write: it exists, it
    is the file made from this key, and nothing is forced; else None."""
    if settings.force or source_key is None or not out.exists() or not stamp.exists():
        return None
    try:
        recorded = json.loads(stamp.read_text())
        if recorded["key"] == _cook_key(source_key, settings_doc, settings) and all(_unchanged(Path(f), size, mtime) for f, size, mtime in recorded["files"]):
            return recorded
    except (OSError, ValueError, KeyError):
        pass
    return None


def is_up_to_date(source: str | os.PathLike, out: str | os.PathLike, settings: CookSettings | None = None) -> bool:
    """Whether `cook(source, out, settings)` would find `out` up to date (and do nothing)."""
    settings = settings or CookSettings()
    source, out = Path(source), Path(out)
    if not source.is_file():
        return False
    cache = StageCache(cache_root(settings, out), enabled=not settings.force)
    settings_doc = _key_settings(settings)
    _, source_key = _known_source(source, settings, cache)
    return _recorded_output(out, _stamp(cache, out), source_key, settings_doc, settings) is not None


def _key_settings(settings: CookSettings) -> dict:
    """The settings that shape the output (the cook key's): where and how finely the work runs
    does not change the bytes, so it is left out."""
    from asset_pipeline.bake import SCHEDULING

    doc = {f.name: _settings_doc(getattr(settings, f.name)) for f in dataclasses.fields(settings)
           if f.name not in ("force", "cache_dir", "cache_max", "report", "executor", "ray_address", "refine")}
    if isinstance(doc.get("bake"), dict):
        for k in SCHEDULING:
            doc["bake"].pop(k, None)
    return doc


def _known_source(source: Path, settings: CookSettings, cache: StageCache) -> tuple[list[str] | None, str | None]:
    """The files the last import of `source` read (stage "source-deps") and the source stage's
    key over their bytes; (None, None) when not known."""
    deps_key = _deps_key(source, settings)
    deps = cache.load("source-deps", deps_key)
    files = deps[0]["files"] if deps is not None else None
    return files, _source_key(source, files)


def _deps_key(source: Path, settings: CookSettings) -> str:
    return Hasher("source-deps").text(os.fspath(source.resolve())).settings(settings.allow_external_uris).key()


def _stamp(cache: StageCache, out: Path) -> Path:
    """Where the record of the cook that wrote `out` is kept."""
    return cache.root / "outputs" / (Hasher("output").text(os.fspath(out.resolve())).key()[:24] + ".json")


def _cook(source, out, settings: CookSettings, progress: Progress, cache: StageCache) -> CookResult:
    source, out = Path(source), Path(out)
    if not source.is_file():
        raise CookError(f"{source}: no such file")
    if not out.parent.is_dir():
        raise CookError(f"{out}: output directory '{out.parent}' does not exist")
    if settings.chunks:
        from asset_pipeline.chunks import ChunkSettings

        (settings.chunk or ChunkSettings()).check()  # a bad setting fails before any work
    stages: list[StageRecord] = []

    from asset_pipeline.executor import make_executor

    executor = make_executor(settings.executor, settings.ray_address)
    settings_doc = _key_settings(settings)
    # What a cook reads is known only once it has read it (a level names textures and props, a
    # prop its buffers and images), so the files the last import of this source read are kept
    # (stage "source-deps"); the source stage's key covers all of their bytes. An edit to any of
    # them, or a new file the edit names, changes the key.
    deps_key = _deps_key(source, settings)
    files, source_key = _known_source(source, settings, cache)
    stamp = _stamp(cache, out)

    # Up to date: the output exists, is the file this key produced, and nothing is forced.
    recorded = _recorded_output(out, stamp, source_key, settings_doc, settings)
    cache.use(stamp)  # read, or about to be written: not for this cook's eviction
    if recorded is not None:
        return CookResult(summary=recorded["summary"], up_to_date=True, files=list(files))
    # This cook runs: from now on the entries it uses are kept from other cooks' eviction.
    cache.begin()

    if executor is not None:
        # Connect now, so a bad address fails before minutes of work rather than after.
        executor.connect()

    # Stage 1: source -> scene.
    rec = StageRecord("import" if source.suffix.lower() != ".toml" else "level")
    t0 = time.perf_counter()
    with progress.stage(rec.name, 1) as bar:
        hit = cache.load("source", source_key) if source_key is not None else None
        if hit is not None:
            scene = ir.from_wire(hit[0]["scene"], hit[1])
            scene.files = list(files)
            rec.cached = 1
        else:
            scene = _load_source(source, settings)
            scene.files = files = _read_files(source, scene)
            cache.store("source-deps", deps_key, {"files": files}, [])
            source_key = _source_key(source, files)
            if source_key is not None:
                text, arrays = ir.to_wire(scene)
                cache.store("source", source_key, {"scene": text}, arrays)
        bar.advance()
    rec.items, rec.seconds = 1, time.perf_counter() - t0
    stages.append(rec)
    if settings.compress:
        _check_compression_overrides(scene, settings)  # before any long stage runs
    for w in scene.warnings:
        progress.warning(w)
    if source.suffix.lower() != ".toml" and settings.sky_nits > 0:
        # glTF has no sky: a scene is baked under a uniform white one, as a viewer shows a model
        # under its environment; without any, a model with no lights would bake black.
        scene = dataclasses.replace(scene, sky=ir.Sky(color=(1.0, 1.0, 1.0), intensity=float(settings.sky_nits)))

    uv2_stats: dict = {}
    if settings.lightmap_uvs and scene.static_nodes():
        scene, uv2_stats, rec = _uv2_stage(scene, settings, cache, progress)
        stages.append(rec)
    bake_stats: dict = {}
    if settings.baking and scene.lightmap is not None and scene.lightmap.pages:
        scene, bake_stats, rec = _bake_stage(scene, settings, cache, progress, executor)
        stages.append(rec)
    atlas_scene = scene  # the static instances as the atlas was laid out and baked (the report's previews)
    chunk_stats: dict = {}
    if settings.chunks and scene.static_nodes():
        scene, chunk_stats, rec = _chunks_stage(scene, settings, cache, progress)
        stages.append(rec)
    if settings.lods:
        scene, rec = _lod_stage(scene, settings, cache, progress, executor, locked=frozenset(chunk_stats.get("chunk_meshes", ())))
        stages.append(rec)
    mesh_opt_stats: dict = {}
    if settings.mesh_opt and scene.meshes:
        scene, mesh_opt_stats, rec = _mesh_opt_stage(scene, cache, progress)
        stages.append(rec)

    if settings.mips and scene.textures:
        scene, rec = _textures_stage(scene, settings, cache, progress, executor)
        stages.append(rec)
    compress_stats: dict = {}
    baked_scene = scene  # the lightmap EXRs are written from the pages as baked, uncompressed
    if settings.compress and (scene.textures or scene.reflection_cubes is not None):
        scene, compress_stats, rec = _compress_stage(scene, settings, cache, progress)
        stages.append(rec)

    # What the pack's 16-bit texture coordinates cannot hold within a quarter texel: said, and
    # kept with the scene's other warnings.
    precision = uv_precision_warnings(scene)
    for w in precision:
        progress.warning(w)
    if precision:
        scene = dataclasses.replace(scene, warnings=[*scene.warnings, *precision])

    rec = StageRecord("write", items=1)
    # Cooks of one output write one at a time, each its pack, lightmaps, report and then its
    # stamp: the stamp always records the files its own cook wrote.
    with _output_lock(stamp):
        t0 = time.perf_counter()
        _remove_stale_temporaries(out)
        cache.remove_stale_temporaries()
        with progress.stage("write", 1) as bar:
            # Lightmap files first, then the pack: each is written whole and renamed into place.
            exrs = _write_exrs(baked_scene, out)
            summary = write_pack(scene, out)
            bar.advance()
        rec.seconds = time.perf_counter() - t0
        stages.append(rec)

        report = None
        if settings.report:
            report = write_report(out, scene, summary, stages, uv2_stats, bake_stats, exrs, chunk_stats, atlas_scene, mesh_opt_stats, compress_stats)
        outputs = [[os.fspath(f), f.stat().st_size, f.stat().st_mtime_ns] for f in [out, *exrs]]
        record = json.dumps({"key": _cook_key(source_key, settings_doc, settings), "files": outputs, "summary": summary}).encode()
        write_atomic(stamp, lambda f: f.write(record))
    return CookResult(summary=summary, up_to_date=False, stages=stages, report=report,
                      tasks_submitted=executor.submitted if executor is not None else 0, uv2=uv2_stats, bake=bake_stats, scene=scene,
                      chunks=chunk_stats, mesh_opt=mesh_opt_stats, compress=compress_stats, files=list(files))


def _output_lock(stamp: Path):
    """The lock of one output's files (beside its stamp, `outputs/<hash>.lock`; empty, never
    counted as an entry)."""
    stamp.parent.mkdir(parents=True, exist_ok=True)
    return file_lock(stamp.with_suffix(".lock"))


# Temporary files of this output's pack, lightmaps and report, named by the writers (pack crate:
# `.<name>.tmp-<pid>-<n>`; exr_io and cache.write_atomic, the report's writer: `.<name>.<pid>.tmp`;
# `.<name>.tmp` is what reports were written through before).
_TEMPORARY = re.compile(r"^\.(?P<name>.+?)(\.tmp-(?P<pid>\d+)-\d+|\.(?P<pid2>\d+)\.tmp|\.tmp)$")


def _remove_stale_temporaries(out: Path) -> None:
    """A cook killed while writing (SIGKILL, power loss) leaves its temporary files beside the
    output; they are hidden and never read, but would pile up. Remove those of this output whose
    writer is no longer running."""
    mine = (out.name, out.with_suffix(".report.md").name)
    for f in out.parent.glob(f".{out.stem}*"):
        m = _TEMPORARY.match(f.name)
        if m is None or not (m["name"] in mine or (m["name"].startswith(f"{out.stem}.lightmap") and m["name"].endswith(".exr"))):
            continue
        pid = m["pid"] or m["pid2"]
        if pid is not None and int(pid) != os.getpid() and process_running(int(pid)):
            continue
        try:
            f.unlink()
        except OSError:
            pass


# Libraries whose code shapes a stage's output (each stage's key holds its own; the whole cook's
# key holds them all, so an upgrade is never "up to date").
STAGE_LIBRARIES = ("manifold3d", "xatlas", "fast-simplification", "pyoidn")


def _cook_key(source_key: str | None, settings_doc: dict, settings: CookSettings) -> str:
    from asset_pipeline.bake import BakeSettings
    from asset_pipeline.lightmap_post import denoiser

    # Whether the denoiser would run (pyoidn installed and loading) changes the bake's result.
    denoise = settings.baking and (settings.bake or BakeSettings()).post.denoise
    return (Hasher("cook").text(str(source_key)).settings(settings_doc).settings([library_version(n) for n in STAGE_LIBRARIES])
            .text(denoiser() if denoise else "no denoising").key())


def _unchanged(path: Path, size: int, mtime_ns: int) -> bool:
    try:
        st = path.stat()
    except OSError:
        return False
    return st.st_size == size and st.st_mtime_ns == mtime_ns


def lightmap_paths(out: Path, pages: int) -> list[Path]:
    """Where the baked pages of the pack `out` are written as OpenEXR: `<out stem>.lightmap<N>.exr`."""
    return [out.with_name(f"{out.stem}.lightmap{p}.exr") for p in range(pages)]


def _write_exrs(scene: ir.Scene, out: Path) -> list[Path]:
    """Each baked page as the bake made it (`scene` before the compress stage): B as RGB; a
    directional page's b0 as RGB (what viewers show), the sun's visibility (the direction
    texture's alpha / 255) as "sun.Y" and its bytes / 255, (128 + 127 t) / 255, as
    "direction.X/Y/Z" (bake.LIGHTMAP_MODES)."""
    from asset_pipeline import _core
    from asset_pipeline.lightmap_post import write_exr

    if scene.lightmap is None or not scene.lightmap.textures:
        return []
    paths = lightmap_paths(out, len(scene.lightmap.textures))
    directions = scene.lightmap.directions or [None] * len(paths)
    for path, t, d in zip(paths, scene.lightmap.textures, directions):
        page = np.asarray(scene.textures[t].mips[0], np.float32)
        if d is None:
            write_exr(path, page[..., :3])
            continue
        direction = np.asarray(scene.textures[d].mips[0], np.float32) / 255.0
        channels = [(c, np.ascontiguousarray(page[..., k])) for k, c in enumerate("RGB")] + [("sun.Y", np.ascontiguousarray(direction[..., 3]))]
        channels += [(f"direction.{a}", np.ascontiguousarray(direction[..., k])) for k, a in enumerate("XYZ")]
        _core.write_exr_channels(path, channels)
    return paths


# ---- lightmap UVs -------------------------------------------------------------------------------


# The most lightmap texels a scene without a density of its own (a glTF scene cooked without
# --texels-per-metre) gets: a 2048^2 page. Its density is lowered to fit, so any model cooks;
# levels and explicit densities keep theirs (and the uv2 stage's hard limit).
AUTO_LIGHTMAP_TEXELS = 1 << 22


def _uv2_settings(scene: ir.Scene, settings: CookSettings, instances) -> tuple[object, str | None]:
    """The uv2 settings of this cook and a warning when the density was lowered: --texels-per-metre,
    else the level's density, else the default lowered to AUTO_LIGHTMAP_TEXELS."""
    from asset_pipeline.uv2 import Uv2Settings

    uv2 = settings.uv2 or Uv2Settings()
    if settings.texels_per_metre is not None:
        return dataclasses.replace(uv2, texels_per_metre=float(settings.texels_per_metre)), None
    if settings.uv2 is not None:
        return uv2, None
    if scene.lightmap is not None:
        return dataclasses.replace(uv2, texels_per_metre=float(scene.lightmap.texels_per_metre)), None
    from asset_pipeline.uv2 import _world_areas

    area_texels = sum(float(_world_areas(scene.meshes[i.mesh_index].base, 1.0).sum()) * ((i.texels_per_metre or uv2.texels_per_metre) * i.scale) ** 2
                      for i in instances)
    if area_texels <= AUTO_LIGHTMAP_TEXELS:
        return uv2, None
    tpm = uv2.texels_per_metre * math.sqrt(AUTO_LIGHTMAP_TEXELS / area_texels)
    return (dataclasses.replace(uv2, texels_per_metre=tpm),
            f"lightmap density lowered from {uv2.texels_per_metre:g} to {tpm:.3g} texels per metre to keep the scene's static "
            f"surfaces within {AUTO_LIGHTMAP_TEXELS} texels (--texels-per-metre sets it)")


@dataclass
class _Placement:
    node: int
    mesh_index: int  # into scene.meshes
    scale: float
    texels_per_metre: float | None


def _placements(scene: ir.Scene) -> list[_Placement]:
    """Every static instance: its node, mesh, world scale and the mesh's density override."""
    world = scene.world_matrices()
    return [_Placement(n, scene.nodes[n].mesh, uniform_scale(world[n]), scene.meshes[scene.nodes[n].mesh].texels_per_metre)
            for n in scene.static_nodes()]


def _lightmap_inputs(scene: ir.Scene, placements: list[_Placement]):
    """lightmap_uvs's arguments for the scene: (static mesh indices, their LOD 0s, instances, names, instance names)."""
    from asset_pipeline.uv2 import Instance

    static_meshes = scene.static_meshes()
    local = {m: k for k, m in enumerate(static_meshes)}
    instances = [Instance(local[p.mesh_index], p.scale, p.texels_per_metre) for p in placements]
    return (static_meshes, [scene.meshes[m].base for m in static_meshes], instances, [scene.meshes[m].name for m in static_meshes],
            [scene.nodes[p.node].name for p in placements])


def _with_lightmaps(scene: ir.Scene, static_meshes: list[int], placements: list[_Placement], lods, regions, layout) -> ir.Scene:
    meshes = list(scene.meshes)
    for m, lod in zip(static_meshes, lods):
        meshes[m] = dataclasses.replace(meshes[m], lods=[lod])
    nodes = list(scene.nodes)
    for p, region in zip(placements, regions):
        nodes[p.node] = dataclasses.replace(nodes[p.node], lightmap=region)
    return dataclasses.replace(scene, meshes=meshes, nodes=nodes, lightmap=layout)


def with_lightmap_uvs(scene: ir.Scene, uv2=None) -> tuple[ir.Scene, dict]:
    """The uv2 stage without its cache (for tools and tests): the scene with lightmap UVs on its
    static meshes and a region on every static instance, and the stage's measurements. `uv2`:
    Uv2Settings (default: at the scene's density)."""
    from asset_pipeline.uv2 import Uv2Settings, lightmap_uvs

    placements = _placements(scene)
    uv2 = uv2 or Uv2Settings(**({"texels_per_metre": scene.lightmap.texels_per_metre} if scene.lightmap else {}))
    static_meshes, lods, instances, names, instance_names = _lightmap_inputs(scene, placements)
    r = lightmap_uvs(lods, uv2, instances=instances, names=names, instance_names=instance_names)
    return _with_lightmaps(scene, static_meshes, placements, r.lods, r.regions, r.layout), r.stats


def _uv2_stage(scene: ir.Scene, settings: CookSettings, cache: StageCache, progress: Progress):
    from asset_pipeline.uv2 import lightmap_uvs

    placements = _placements(scene)
    uv2, lowered = _uv2_settings(scene, settings, placements)
    static_meshes, lods, instances, names, instance_names = _lightmap_inputs(scene, placements)
    key = Hasher("uv2").settings(_settings_doc(uv2)).settings([dataclasses.asdict(i) for i in instances]).text(library_version("xatlas"))
    for base in lods:
        for name in sorted(base.attributes):
            key.text(name).array(base.attributes[name])
        key.array(base.triangles).array(base.materials)
    key = key.key()

    rec = StageRecord("uv2", items=len(instances))
    t0 = time.perf_counter()
    with progress.stage("uv2", len(instances)) as bar:
        hit = cache.load("uv2", key)
        if hit is not None:
            meta, arrays = hit
            new_lods = ir.lods_from_wire(meta["lods"], arrays)
            regions = meta["regions"]
            layout = ir.LightmapLayout(meta["layout"]["texels_per_metre"], [tuple(p) for p in meta["layout"]["pages"]], meta["layout"]["padding"])
            stats = meta["stats"]
            rec.cached = len(instances)
        else:
            # The per-mesh chart cache lets an edit to one mesh re-chart only that mesh.
            r = lightmap_uvs(lods, uv2, instances=instances, names=names, instance_names=instance_names, cache=cache)
            new_lods, regions, layout, stats = r.lods, r.regions, r.layout, r.stats
            docs, arrays = ir.lods_to_wire(new_lods)
            cache.store("uv2", key, {"lods": docs, "regions": regions, "layout": dataclasses.asdict(layout), "stats": stats}, arrays)
        bar.advance(len(instances))
    scene = _with_lightmaps(scene, static_meshes, placements, new_lods, regions, layout)
    new = ([lowered] if lowered else []) + list(stats.get("warnings", []))
    for w in new:
        progress.warning(w)
    rec.seconds = time.perf_counter() - t0
    return dataclasses.replace(scene, warnings=[*scene.warnings, *new]), stats, rec


# ---- level chunks -------------------------------------------------------------------------------


def _chunks_stage(scene: ir.Scene, settings: CookSettings, cache: StageCache, progress: Progress):
    """Large static meshes cut into chunks (chunks.split_chunks); each mesh's partition is cached
    by its positions, triangles, size in its units and the settings."""
    from asset_pipeline.chunks import ChunkSettings, candidates, split_chunks

    chunk_settings = settings.chunk or ChunkSettings()
    t0 = time.perf_counter()
    with progress.stage("chunks", len(candidates(scene, chunk_settings))) as bar:
        scene, stats = split_chunks(scene, chunk_settings, cache=cache, advance=bar.advance)
    rec = StageRecord("chunks", seconds=time.perf_counter() - t0, items=stats["items"], cached=stats["cached"])
    return scene, stats, rec


# ---- LOD chains ---------------------------------------------------------------------------------


def _hash_lod(key: Hasher, lod: ir.Lod) -> Hasher:
    """A LOD's geometry into a stage key: every attribute by name, triangles, their materials and
    lightmap blocks, morph deltas."""
    for name in sorted(lod.attributes):
        key.text(name).array(lod.attributes[name])
    key.array(lod.triangles).array(lod.materials).array(lod.lightmap_blocks)
    return key.array(lod.morph_positions).array(lod.morph_normals)


# Meshes whose LOD chains may be carried and measured at once while the next one is simplified.
# A small mesh's levels are made in a moment and then measured while this thread would wait;
# with several in flight both cores stay busy. tools/bench_cook_scale.py's 100k level (145
# meshes, --quality draft, 2 threads): the stage 1.41-1.46 s one at a time; 1.32 s with 1 in
# flight, 1.28 with 2, 1.06 with 3, 0.99-1.15 with 4, 1.03 with 8, 1.01 with 16. Each holds a
# thread and its mesh's levels until finished.
LODS_IN_FLIGHT = 4


def _lod_stage(scene: ir.Scene, settings: CookSettings, cache: StageCache, progress: Progress, executor=None, locked=frozenset()):
    """`locked`: meshes simplified with their open borders kept (level chunks, chunks.py)."""
    from asset_pipeline.executor import lod_chain
    from asset_pipeline.lod import LodSettings, start_lods

    lod_settings = settings.lod or LodSettings()
    doc = {"settings": _settings_doc(lod_settings), "fast-simplification": library_version("fast-simplification")}
    # Level chunks keep every border vertex at every level, so neighbours' borders meet at any LODs.
    chunk_settings = dataclasses.replace(lod_settings, lock_borders=True)
    chunk_doc = {**doc, "settings": _settings_doc(chunk_settings)}
    rec = StageRecord("lod", items=len(scene.meshes))
    t0 = time.perf_counter()
    # Per mesh: its LODs below LOD 0, and its cache key.
    chains: list = [None] * len(scene.meshes)
    keys: list = [None] * len(scene.meshes)
    with progress.stage("lod", len(scene.meshes)) as bar:
        todo = []
        # Meshes whose levels are made and still being carried and measured on their chain's
        # thread (lod.start_lods): this thread simplifies the next mesh meanwhile. Finished in
        # order, so the cache sees the same stores as one mesh at a time.
        pending: collections.deque = collections.deque()

        def settings_of(i: int) -> LodSettings:
            return chunk_settings if i in locked else lod_settings

        def made(i: int, chain: list) -> None:
            """Mesh i's chain is made (here or by a Ray task): keep and cache it."""
            chains[i] = chain
            docs, arrays = ir.lods_to_wire(chain)
            cache.store("lod", keys[i], {"lods": docs}, arrays)
            bar.advance()

        def finish_oldest():
            i, started = pending.popleft()
            made(i, started.finish())

        for i, m in enumerate(scene.meshes):
            base = m.base
            key = _hash_lod(Hasher("lod").settings(chunk_doc if i in locked else doc), base).key()
            keys[i] = key
            hit = cache.load("lod", key)
            if hit is not None:
                chains[i] = ir.lods_from_wire(hit[0]["lods"], hit[1])
                rec.cached += 1
                bar.advance()
            elif executor is None:
                if len(pending) >= LODS_IN_FLIGHT:
                    finish_oldest()
                pending.append((i, start_lods(base, settings_of(i))))
            else:
                todo.append(i)
        while pending:
            finish_oldest()

        if todo:  # the meshes not in the cache, one Ray task each
            executor.run([(lod_chain, (scene.meshes[i].base, settings_of(i))) for i in todo], on_done=lambda j, chain: made(todo[j], chain))
    meshes = [dataclasses.replace(m, lods=[m.base, *chain]) for m, chain in zip(scene.meshes, chains)]
    rec.seconds = time.perf_counter() - t0
    return dataclasses.replace(scene, meshes=meshes), rec


def _mesh_opt_stage(scene: ir.Scene, cache: StageCache, progress: Progress):
    """Cache, overdraw and fetch order for every LOD of every mesh (mesh_opt.py), one cache
    entry per mesh (its LODs and their statistics)."""
    from asset_pipeline.mesh_opt import MeshOptStats, add, optimize_mesh

    rec = StageRecord("mesh_opt", items=len(scene.meshes))
    t0 = time.perf_counter()
    total = MeshOptStats()
    meshes = []
    with progress.stage("mesh_opt", len(scene.meshes)) as bar:
        for m in scene.meshes:
            key = Hasher("mesh_opt")
            for lod in m.lods:
                _hash_lod(key, lod).text(repr(lod.error))
            key = key.key()
            hit = cache.load("mesh_opt", key)
            if hit is not None:
                new = dataclasses.replace(m, lods=ir.lods_from_wire(hit[0]["lods"], hit[1]))
                stats = MeshOptStats(**hit[0]["stats"])
                rec.cached += 1
            else:
                new, stats = optimize_mesh(m)
                docs, arrays = ir.lods_to_wire(new.lods)
                cache.store("mesh_opt", key, {"lods": docs, "stats": dataclasses.asdict(stats)}, arrays)
            add(total, stats)
            meshes.append(new)
            bar.advance()
    rec.seconds = time.perf_counter() - t0
    return dataclasses.replace(scene, meshes=meshes), total.as_dict(), rec


# ---- compress -------------------------------------------------------------------------------------


def _check_compression_overrides(scene: ir.Scene, settings: CookSettings) -> None:
    """Each override names a mode that exists and matches a texture of the source: a pattern that
    matches nothing is a typo the user should hear about, not a setting silently ignored."""
    from asset_pipeline import compress

    overrides = dict(settings.texture_compression or {})
    bad = [m for m in overrides.values() if m not in compress.MODES]
    if bad:
        raise CookError(f"{scene.source}: texture compression mode '{bad[0]}' is not one of {', '.join(compress.MODES)}")
    missing = compress.unmatched(scene, overrides, baking=settings.baking and bool(scene.static_meshes()))
    if missing:
        names = ", ".join(f"'{t.name}'" for t in scene.textures[:8]) + (" ..." if len(scene.textures) > 8 else "")
        raise CookError(f"{scene.source}: texture compression override '{missing[0]}' matches no texture (textures: {names or 'none'})")


def _compress_stage(scene: ir.Scene, settings: CookSettings, cache: StageCache, progress: Progress):
    """Block compression of every texture's levels and every reflection probe's cube
    (compress.py's rules), one cache entry per texture or cube (its blocks and record); overrides
    were checked after the import."""
    from asset_pipeline import compress

    overrides = dict(settings.texture_compression or {})
    classes = compress.texture_classes(scene)
    rc = scene.reflection_cubes if scene.reflection_cubes is not None and scene.reflection_cubes.format == "Rgba16Float" else None
    cubes = [] if rc is None else list(zip(scene.reflection_probes, rc.cubes))
    rec = StageRecord("compress", items=len(classes) + len(cubes))
    t0 = time.perf_counter()
    textures = list(scene.textures)
    records = []
    with progress.stage("compress", len(classes) + len(cubes)) as bar:
        for i, cls in classes.items():
            t = textures[i]
            mode = compress.mode_of(t.name, overrides)
            key = Hasher("compress").settings({"class": cls, "mode": mode, "format": t.format, "size": [t.width, t.height]})
            for m in t.mips:
                key.array(m)
            key = key.key()
            hit = cache.load("compress", key)
            if hit is not None:
                record = hit[0]
                if "kept" not in record:
                    textures[i] = dataclasses.replace(t, format=record["format"], mips=list(hit[1]))
                rec.cached += 1
            else:
                new, record = compress.compress_texture(t, cls, mode)
                cache.store("compress", key, record, list(new.mips) if "kept" not in record else [])
                textures[i] = new
            records.append(record)
            bar.advance()
        compress.keep_sets_whole(scene, textures, records, dict(zip(classes, range(len(records)))))
        # The cubes are one cube-map array at run time: all BC6H, or all as baked.
        packed = []
        for probe, cube in cubes:
            name = compress.cube_name(probe)
            mode = compress.mode_of(name, overrides)
            key = Hasher("compress cube").settings({"mode": mode, "face_size": rc.face_size, "levels": rc.levels}).array(cube).key()
            hit = cache.load("compress", key)
            if hit is not None:
                record, data = hit[0], (hit[1][0] if hit[1] else None)
                rec.cached += 1
            else:
                data, record = compress.compress_cube(rc, cube, name, mode)
                cache.store("compress", key, record, [data] if data is not None else [])
            packed.append(data)
            records.append(record)
            bar.advance()
    if cubes and all(d is not None for d in packed):
        scene = dataclasses.replace(scene, reflection_cubes=dataclasses.replace(rc, cubes=packed, format="Bc6hUfloat"))
    elif cubes:
        # The cubes stay as baked (`packed` is dropped): their records say so.
        compress.keep_set_whole(records[-len(cubes):], [rc.format] * len(cubes))
    rec.seconds = time.perf_counter() - t0
    return dataclasses.replace(scene, textures=textures), compress.summarise(records), rec


# ---- bake -----------------------------------------------------------------------------------------


def _bake_key(scene: ir.Scene, bake_settings) -> str:
    """Everything the bake reads (bake.key_inputs: the static instances where they stand, their
    regions, the materials' baked fields and the textures they read, lights, sky, the atlas, the
    reflection probes' capture points), the settings and the denoiser."""
    from asset_pipeline.bake import key_inputs
    from asset_pipeline.lightmap_post import denoiser

    # The denoiser that will run (its version), or none: a bake made without it is not the one
    # made with it, and installing it must not leave the cache serving the noisy one.
    doc = bake_settings.key_doc()
    if not scene.reflection_probes:
        # Without reflection probes their settings change nothing: a level without any keeps its bake.
        doc = {k: v for k, v in doc.items() if not k.startswith("reflection_")}
    key = Hasher("bake").settings(doc).text(denoiser() if bake_settings.post.denoise else "denoise off")
    doc, arrays = key_inputs(scene)
    key.settings(doc)
    for a in arrays:
        key.array(a)
    return key.key()


def _bake_stage(scene: ir.Scene, settings: CookSettings, cache: StageCache, progress: Progress, executor=None):
    from asset_pipeline.bake import BakeSettings, Baked, attach, bake_level

    bake_settings = settings.bake or BakeSettings()
    key = _bake_key(scene, bake_settings)
    pages = len(scene.lightmap.pages)
    rec = StageRecord("bake", items=pages)
    t0 = time.perf_counter()
    hit = cache.load("bake", key)
    if hit is not None:
        meta, arrays = hit
        probes = None
        at = pages  # arrays: the pages, the probes' SH and sun visibility, the reflection cubes
        if meta["probes"] is not None:
            pr = meta["probes"]
            probes = ir.ProbeGrid(tuple(pr["origin"]), tuple(pr["spacing"]), tuple(pr["counts"]), arrays[at], arrays[at + 1])
            at += 2
        reflections = None
        if meta.get("reflections") is not None:
            rc = meta["reflections"]
            reflections = ir.ReflectionCubes(rc["face_size"], rc["levels"], list(arrays[at:at + rc["count"]]))
        baked = Baked(pages=arrays[:pages], probes=probes, stats=meta["stats"], reflections=reflections)
        rec.cached = pages
        progress.line(f"bake: {pages} page(s) from the cache")
    else:
        refine = settings.refine if executor is None else None
        if refine is not None:
            # The sums go on across steps whose settings differ only in their sample counts.
            refine.begin(_bake_key(scene, dataclasses.replace(bake_settings, samples=-1, reflection_samples=-1)))
        baked = bake_level(scene, bake_settings, progress, executor, refine=refine)
        arrays = list(baked.pages)
        probes = None
        if baked.probes is not None:
            p = baked.probes
            probes = {"origin": list(p.origin), "spacing": list(p.spacing), "counts": list(p.counts)}
            arrays += [p.sh, p.sun_visibility]
        reflections = None
        if baked.reflections is not None:
            r = baked.reflections
            reflections = {"face_size": r.face_size, "levels": r.levels, "count": len(r.cubes)}
            arrays += list(r.cubes)
        cache.store("bake", key, {"probes": probes, "reflections": reflections, "stats": baked.stats}, arrays)
    rec.seconds = time.perf_counter() - t0
    return attach(scene, baked), baked.stats, rec


# ---- textures -------------------------------------------------------------------------------------


def _alpha_cutoffs(scene: ir.Scene) -> dict[int, float]:
    """Base colour textures of alpha-tested (Mask) materials -> the cutoff whose coverage their
    levels keep (the lowest, when materials share a texture with different cutoffs)."""
    cutoffs: dict[int, float] = {}
    for m in scene.materials:
        if m.alpha_mode == "Mask" and m.base_color_texture is not None:
            t = m.base_color_texture
            cutoffs[t] = min(cutoffs.get(t, 1.0), float(m.alpha_cutoff))
    return cutoffs


# pack::Wrap -> cook_core::mips::Edge.
_EDGE_OF_WRAP = {"repeat": "wrap", "clamp": "clamp", "mirror": "mirror"}


def _textures_stage(scene: ir.Scene, settings: CookSettings, cache: StageCache, progress: Progress, executor=None):
    """Every material texture gets its full mip chain by its usage (cook_core::mips): colour in
    linear light with premultiplied alpha, data per channel, normals renormalised and stored
    16-bit at every level (level 0 re-encoded: 8 bits cannot hold a unit vector), HDR with a
    non-negative kernel; alpha-tested base colours keep their coverage. Levels filter across the
    edges as the texture's sampler reads past them (repeat, clamp, mirror); a texture read
    without mipmaps keeps one level. Lightmap pages (and a directional page's direction texture)
    are left at one level: they are magnified, and their chart gutters would bleed neighbouring
    charts into level 1 and below.
    Textures that arrive with more than one level keep theirs."""
    from asset_pipeline.executor import texture_levels

    skip = scene.baked_textures()
    cutoffs = _alpha_cutoffs(scene)
    # A texture its sampler reads without mipmaps (glTF's NEAREST or LINEAR minification) keeps one level.
    todo = [i for i, t in enumerate(scene.textures)
            if i not in skip and len(t.mips) == 1 and max(t.width, t.height) > 1 and t.sampling["mipmap_filter"] is not None]
    rec = StageRecord("textures", items=len(todo))
    t0 = time.perf_counter()
    textures = list(scene.textures)
    with progress.stage("textures", len(todo)) as bar:
        def finish(i, key, levels, cached):
            t = textures[i]
            if not cached:
                status, levels = levels
                if status != "ok":
                    raise CookError(f"{scene.source}: texture {i} '{t.name}': {levels}")
                if t.usage == "hdr":
                    levels = [l.view(np.float16) for l in levels]
                cache.store("textures", key, {}, levels)
            # Normal maps come back whole (level 0 re-encoded 16-bit), the rest as levels 1..
            if t.usage == "normal":
                textures[i] = dataclasses.replace(t, format="Rgba16Unorm", mips=list(levels))
            else:
                textures[i] = dataclasses.replace(t, mips=[t.mips[0], *levels])
            bar.advance()

        remote = []  # (texture, key, args) not in the cache, for the Ray executor
        for i in todo:
            t = textures[i]
            # Levels filter across the edges the way the sampler reads past them.
            edge = ",".join(_EDGE_OF_WRAP[t.sampling[axis]] for axis in ("wrap_s", "wrap_t"))
            job = {"usage": t.usage, "filter": settings.mip_filter, "edge": edge, "alpha_cutoff": cutoffs.get(i)}
            key = Hasher("textures").settings(job).array(t.mips[0]).key()
            hit = cache.load("textures", key)
            if hit is not None:
                rec.cached += 1
                finish(i, key, hit[1], True)
                continue
            level0 = np.ascontiguousarray(t.mips[0].view(np.uint16) if t.usage == "hdr" else t.mips[0])
            args = (level0, t.usage, t.usage == "normal", job)
            if executor is None:
                finish(i, key, texture_levels(*args), False)
            else:
                remote.append((i, key, args))
        if remote:  # one Ray task per texture
            executor.run([(texture_levels, args) for _, _, args in remote],
                         on_done=lambda j, r: finish(remote[j][0], remote[j][1], r, False))
    rec.seconds = time.perf_counter() - t0
    return dataclasses.replace(scene, textures=textures), rec
