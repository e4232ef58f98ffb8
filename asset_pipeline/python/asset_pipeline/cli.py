"""``cook SOURCE -o OUT.pack``: the command-line front of :func:`asset_pipeline.cook`.
``cook --cache-info`` / ``cook --cache-prune`` (with ``--cache DIR`` or ``-o OUT.pack``): show or
trim the stage cache, cooking nothing.

Exit status: 0 on success, 2 on bad arguments or bad input (as argparse), 130 when interrupted.
With ``--watch`` (asset_pipeline.watch): 0 when stopped with Ctrl-C, whatever the cooks did; 2
only when it cannot start (no such source, no output directory).
Errors are one line on stderr, ``cook: error: <message>``, never a traceback.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

from asset_pipeline import CookError
from asset_pipeline.bake import LIGHTMAP_MODES, PRESETS, BakeSettings
from asset_pipeline.cache import evict, format_size, info, parse_size
from asset_pipeline.chunks import ChunkSettings
from asset_pipeline.compress import parse_overrides
from asset_pipeline.cook import cook_detailed
from asset_pipeline.executor import EXECUTORS
from asset_pipeline.pipeline import CookSettings, cache_limit


def _count(n: int, one: str, many: str) -> str:
    return f"{n} {one if n == 1 else many}"


def _whole(minimum: int):
    """argparse type: a whole number >= `minimum`, or a one-line error saying what is wrong."""
    def parse(text: str) -> int:
        try:
            n = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"'{text}' is not a whole number") from None
        if n < minimum:
            raise argparse.ArgumentTypeError(f"{n} is not {minimum} or more")
        return n

    return parse


_positive, _non_negative = _whole(1), _whole(0)


def _number(minimum: float, strict: bool):
    """argparse type: a finite number > minimum (or >= when not strict)."""
    def parse(text: str) -> float:
        try:
            x = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"'{text}' is not a number") from None
        if not (math.isfinite(x) and (x > minimum if strict else x >= minimum)):
            raise argparse.ArgumentTypeError(f"{text} is not a {'positive' if strict else 'non-negative'} number")
        return x

    return parse


_positive_number, _non_negative_number = _number(0.0, True), _number(0.0, False)


def _face_size(text: str) -> int:
    """argparse type: a reflection cube's face size, a power of two >= 8."""
    n = _positive(text)
    if n < 8 or n & (n - 1):
        raise argparse.ArgumentTypeError(f"{n} is not a power of two of 8 or more")
    return n


def _size(text: str) -> int:
    """argparse type: a size in bytes (cache.parse_size: 500M, 4G, 1.5GiB, plain bytes)."""
    try:
        return parse_size(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


USAGE = """cook SOURCE -o OUT.pack [options]
       cook --cache-info | --cache-prune (--cache DIR | -o OUT.pack) [--cache-max SIZE]"""


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="cook", usage=USAGE, description="Cook a glTF 2.0 file (.gltf/.glb) or a CSG level (.toml) into a pack.")
    # Both are required for a cook (checked below): --cache-info and --cache-prune take neither.
    parser.add_argument("source", nargs="?", help="the .gltf, .glb or level .toml to cook")
    parser.add_argument("-o", "--out", metavar="OUT.pack", help="where to write the pack (its directory must exist)")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress output")
    parser.add_argument("--force", action="store_true", help="ignore cached stage results and rebuild everything")
    parser.add_argument("--watch", action="store_true",
                        help="after cooking, watch every file the cook read and cook again when one changes (through the stage cache: only "
                             "what the change affects runs again); a failed cook keeps the last good pack; Ctrl-C stops")
    parser.add_argument("--no-lods", action="store_true", help="skip the LOD stage")
    parser.add_argument("--no-lightmap-uvs", action="store_true", help="skip the lightmap UV stage")
    parser.add_argument("--no-chunks", action="store_true", help="do not cut large static meshes into level chunks")
    parser.add_argument("--chunk-size", type=_positive_number, metavar="METRES",
                        help=f"level chunks: cut static meshes of {ChunkSettings.min_mesh_triangles} triangles or more into pieces "
                             f"about this size (default {ChunkSettings.size:g})")
    parser.add_argument("--chunk-triangles", type=_positive, metavar="N",
                        help=f"level chunks: cut pieces further until each has at most N triangles (default {ChunkSettings.max_triangles})")
    parser.add_argument("--texels-per-metre", type=_positive_number, metavar="N",
                        help="lightmap density of static surfaces (default: the level's; for a glTF scene 16, lowered to fit a 2048x2048 page)")
    parser.add_argument("--no-report", action="store_true", help="do not write OUT.report.md")
    parser.add_argument("--allow-external-uris", action="store_true",
                        help="let the source read files outside its folder tree (absolute paths, file: URIs, '..' leading out); "
                             "off, such a path is an error")
    parser.add_argument("--no-mesh-opt", action="store_true",
                        help="keep every LOD's triangles and vertices in the order they were made (no vertex cache, overdraw and fetch ordering)")
    parser.add_argument("--no-mips", action="store_true", help="skip the textures stage (textures keep one level)")
    parser.add_argument("--no-compress", action="store_true",
                        help="store material textures uncompressed (RGBA8; normal maps RGBA16) instead of BC7, BC5 and BC4")
    parser.add_argument("--texture-compression", action="append", metavar="PATTERN=MODE",
                        help="per texture, by a glob of its name: auto (compress unless it misses its quality bar; the default), "
                             "none (keep uncompressed) or force (compress whatever the quality); may repeat, the last match wins")
    parser.add_argument("--mip-filter", choices=["box", "tent", "bspline", "mitchell", "catmull-rom", "lanczos3"],
                        help="mip filter for every texture (default: mitchell; tent for HDR, which accepts only box, tent or bspline)")
    cache = parser.add_argument_group("stage cache")
    cache.add_argument("--cache", type=Path, metavar="DIR", help="stage cache directory (default: .cook-cache beside the output)")
    cache.add_argument("--cache-max", type=_size, metavar="SIZE",
                       help="bound of the stage cache: after each cook the least recently used entries are removed until it holds at most "
                            "this; K, M, G, T are powers of 1000, Ki, Mi, Gi, Ti of 1024 (500M, 4G, 1.5GiB; "
                            "default: $COOK_CACHE_MAX, else 4GiB). Entries a running cook uses are kept")
    maintenance = cache.add_mutually_exclusive_group()
    maintenance.add_argument("--cache-info", action="store_true",
                             help="print the stage cache's size, limit, entries and size per stage, oldest and newest use, and exit")
    maintenance.add_argument("--cache-prune", action="store_true", help="trim the stage cache to --cache-max now, and exit")
    bake = parser.add_argument_group("baking (lightmaps, probes and reflection probes, for levels with lightmap UVs)")
    bake.add_argument("--no-bake", action="store_true", help="skip the bake stage")
    bake.add_argument("--sky-nits", type=_non_negative_number, default=CookSettings.sky_nits, metavar="NITS",
                      help=f"a glTF scene's uniform white sky, in nits (default {CookSettings.sky_nits:g}, an overcast day; 0: none); levels bring their own")
    bake.add_argument("--quality", choices=PRESETS, default="medium", help="bake preset: samples and bounces (default: medium)")
    bake.add_argument("--lightmap-mode", choices=LIGHTMAP_MODES, default=BakeSettings.lightmap_mode,
                      help="irradiance: one RGB lightmap, the sun in it (8 bytes a texel); directional: its direction too, for normal "
                           f"maps, and the sun lit at run time (12 bytes a texel) (default: {BakeSettings.lightmap_mode})")
    bake.add_argument("--samples", type=_positive, metavar="N", help="paths per lightmap texel (overrides the preset)")
    bake.add_argument("--bounces", type=_non_negative, metavar="N", help="indirect bounces (overrides the preset)")
    bake.add_argument("--probe-samples", type=_positive, metavar="N", help="rays per light probe (overrides the preset)")
    bake.add_argument("--reflection-face", type=_face_size, metavar="N",
                      help="reflection probes' cube face size in texels, a power of two >= 8 (overrides the preset's: draft 64, medium and high 128)")
    bake.add_argument("--reflection-samples", type=_positive, metavar="N",
                      help="capture samples per reflection probe texel (overrides the preset's: draft 16, medium 32, high 128)")
    bake.add_argument("--seed", type=_non_negative, default=0, help="random seed: the same seed gives the same bytes")
    bake.add_argument("--threads", type=_positive, metavar="N", help="bake threads (default: all cores; the result is the same)")
    scale = parser.add_argument_group("scale-out (the same bytes wherever the work runs)")
    scale.add_argument("--executor", choices=EXECUTORS, default="local",
                       help="where independent work runs: this process (local, default) or Ray tasks (ray)")
    scale.add_argument("--ray-address", metavar="HOST:PORT",
                       help="the Ray head's address (as `ray start --head` prints; default: $RAY_ADDRESS, else a cluster started on this machine, else a new local instance)")
    scale.add_argument("--tile-texels", type=_positive, metavar="N", default=BakeSettings.tile_texels,
                       help=f"lightmap texels per Ray task (default: {BakeSettings.tile_texels})")
    args = parser.parse_args(argv)
    try:
        limit = cache_limit(CookSettings(cache_max=args.cache_max))  # $COOK_CACHE_MAX read once, here
    except CookError as e:
        print(f"cook: error: {e}", file=sys.stderr)
        return 2
    if args.cache_info or args.cache_prune:
        return _cache_command(parser, args, limit)
    missing = [name for name, value in (("source", args.source), ("-o/--out", args.out)) if value is None]
    if missing:
        parser.error(f"the following arguments are required: {', '.join(missing)}")
    if args.watch and args.force:
        parser.error("--watch and --force: a forced cook would rerun every stage on every save (drop --force)")
    if args.ray_address is not None and args.executor != "ray":
        parser.error("--ray-address needs --executor ray")
    if args.no_chunks and (args.chunk_size is not None or args.chunk_triangles is not None):
        parser.error("--chunk-size and --chunk-triangles need level chunks (drop --no-chunks)")
    try:
        texture_compression = parse_overrides(args.texture_compression)
    except ValueError as e:
        parser.error(str(e))
    if args.no_compress and texture_compression:
        parser.error("--texture-compression needs compression (drop --no-compress)")
    chunk_options = {k: v for k, v in (("size", args.chunk_size), ("max_triangles", args.chunk_triangles)) if v is not None}
    chunk = ChunkSettings(**chunk_options) if chunk_options else None
    bake_settings = BakeSettings(preset=args.quality, lightmap_mode=args.lightmap_mode, samples=args.samples, bounces=args.bounces, probe_samples=args.probe_samples,
                                 reflection_face=args.reflection_face, reflection_samples=args.reflection_samples, seed=args.seed, threads=args.threads, tile_texels=args.tile_texels)
    executor = args.executor
    if executor == "ray":
        # A process that exits on Ctrl-C leaves its tasks to the cluster (see RayExecutor).
        from asset_pipeline.executor import RayExecutor
        executor = RayExecutor(args.ray_address, cancel_on_interrupt=False)
    settings = CookSettings(force=args.force, cache_dir=args.cache, cache_max=limit, lods=not args.no_lods, chunks=not args.no_chunks, chunk=chunk,
                            bake=bake_settings, baking=not args.no_bake,
                            lightmap_uvs=not args.no_lightmap_uvs, texels_per_metre=args.texels_per_metre, report=not args.no_report,
                            mips=not args.no_mips, mesh_opt=not args.no_mesh_opt, compress=not args.no_compress,
                            texture_compression=texture_compression, mip_filter=args.mip_filter, executor=executor, ray_address=args.ray_address,
                            allow_external_uris=args.allow_external_uris, sky_nits=args.sky_nits)
    if args.watch:
        from asset_pipeline.watch import run as watch

        return watch(args.source, args.out, settings, progress=not args.quiet)
    try:
        result = cook_detailed(args.source, args.out, progress=not args.quiet, settings=settings)
    except CookError as e:
        print(f"cook: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("cook: interrupted; nothing written", file=sys.stderr)
        if "ray" in sys.modules:
            # The outputs are already as they were (the pipeline's clean-up ran). Leave now, the
            # tasks still pending (not cancelled: see RayExecutor): the cluster drops a dead
            # driver's tasks on its own, and Ray's exit path is not needed.
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(130)
        return 130
    s = result.summary
    if result.up_to_date:
        print(f"cook: {args.out} is up to date")
    else:
        print(f"cook: wrote {args.out}: {_count(s['meshes'], 'mesh', 'meshes')}, {_count(s['triangles'], 'triangle', 'triangles')}, "
              f"{_count(s['textures'], 'texture', 'textures')}, {s['bytes']} bytes"
              + (f" ({_count(result.tasks_submitted, 'Ray task', 'Ray tasks')})" if args.executor == "ray" else ""))
    return 0


def _cache_command(parser: argparse.ArgumentParser, args, limit: int) -> int:
    """--cache-info or --cache-prune: the cache named by --cache, else the one beside -o's pack."""
    flag = "--cache-info" if args.cache_info else "--cache-prune"
    if args.source is not None or args.watch:
        parser.error(f"{flag} cooks nothing: drop {'SOURCE' if args.source is not None else '--watch'}")
    if args.cache is None and args.out is None:
        parser.error(f"{flag} needs the cache: --cache DIR, or -o OUT.pack for the .cook-cache beside it")
    root = args.cache if args.cache is not None else Path(args.out).parent / ".cook-cache"
    if not root.is_dir():
        print(f"cook: error: {flag}: no stage cache at '{root}' ({'not a directory' if root.exists() else 'no such directory'})", file=sys.stderr)
        return 2
    if args.cache_prune:
        e = evict(root, limit)
        print(f"cook: pruned {root}: removed {_count(e.removed, 'entry', 'entries')} ({format_size(e.freed)}); "
              f"{format_size(e.total)} in {_count(e.entries, 'entry', 'entries')} left, limit {format_size(limit)}")
        if e.total > limit:
            print(f"cook: warning: {_count(e.cooks, 'running cook uses', 'running cooks use')} {format_size(e.in_use)} of it: kept", file=sys.stderr)
        return 0
    i = info(root)
    when = lambda ns: "-" if ns is None else time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(ns / 1e9))
    print(f"stage cache: {i.root}")
    print(f"size: {format_size(i.total)} in {_count(i.entries, 'entry', 'entries')} (limit {format_size(limit)})")
    for stage, (n, size) in i.stages.items():
        print(f"  {stage:<12} {n:>6} {'entry' if n == 1 else 'entries':<7} {format_size(size):>10}")
    print(f"oldest use: {when(i.oldest_ns)}")
    print(f"newest use: {when(i.newest_ns)}")
    print(f"running cooks: {i.cooks}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
