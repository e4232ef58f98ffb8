"""Benchmark of the bake on Ray against the local bake (not a test), on this machine.

    .venv/bin/python tools/bench_ray.py [--preset high] [--samples N] [--workers 1,2] [--tiles 1024,4096,16384]

Builds the demo level and its lightmap UVs (not timed). Then, for each worker count k: the local
bake on k threads, and the Ray bake on a loopback cluster started here with k worker processes
(one head node, k CPUs; one CPU per task) for each tile size. Compared: the tracing wall time
(lightmap tiles + probes; the clean-up after it runs in the driver either way and is left out)
and the whole ``bake_level``. The overhead is Ray's tracing time over the local one, minus 1;
the report ends with the smallest tile size whose overhead stays under 10%. Since two runs on a
shared machine can differ by more than that, each Ray run also prints the share of its workers'
time spent outside tasks (scheduling, transfers, the last tiles' tail), from one run.

Every Ray bake is checked to give the local bake's pages and probes bit for bit. Worker start-up
(process spawn, imports) is paid by a warm-up bake first and printed separately.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
# Loopback only: keep Ray from rewriting 127.0.0.1 to the machine's address (see tests/test_ray.py).
os.environ.setdefault("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER", "0")

import numpy as np  # noqa: E402

from asset_pipeline import bake  # noqa: E402
from asset_pipeline.executor import RayExecutor  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_bake import level_with_uv2  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent


def trace_seconds(stats: dict) -> float:
    if "ray" in stats:
        return stats["ray"]["wall_seconds"]
    return stats["lightmap_seconds"] + stats["probe_seconds"]


def same(a: bake.Baked, b: bake.Baked) -> bool:
    return (all(np.array_equal(x, y) for x, y in zip(a.pages, b.pages)) and len(a.pages) == len(b.pages)
            and np.array_equal(a.probes.sh, b.probes.sh) and np.array_equal(a.probes.sun_visibility, b.probes.sun_visibility))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--level", type=Path, default=ROOT / "content/levels/temple.toml")
    ap.add_argument("--preset", default="high", choices=bake.PRESETS)
    ap.add_argument("--samples", type=int, help="paths per texel (overrides the preset, for a shorter run)")
    ap.add_argument("--probe-samples", type=int, help="rays per probe (overrides the preset)")
    ap.add_argument("--workers", default="1,2", help="worker process counts, comma-separated")
    ap.add_argument("--tiles", default="1024,4096,16384", help="tile sizes (texels per task), comma-separated")
    args = ap.parse_args()

    import ray
    from ray.cluster_utils import Cluster

    scene = level_with_uv2(args.level)
    texels = sum(w * h for w, h in scene.lightmap.pages)
    print(f"level {args.level.name}: {len(scene.lightmap.pages)} page(s) ({texels} texels incl. empty); preset {args.preset}"
          f"{f', {args.samples} samples' if args.samples else ''}; machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.2f}")
    rows = []
    for k in (int(x) for x in args.workers.split(",")):
        base = bake.BakeSettings(preset=args.preset, samples=args.samples, probe_samples=args.probe_samples, threads=k)
        t = time.perf_counter()
        local = bake.bake_level(scene, base)
        local_total = time.perf_counter() - t
        local_trace = trace_seconds(local.stats)
        rays = local.stats["rays"] + local.stats["probes"]["rays"]
        print(f"\n{k} worker(s): local on {k} thread(s): tracing {local_trace:.2f} s, bake_level {local_total:.2f} s, "
              f"{local.stats['texels']} texels, {rays / 1e6:.1f} M rays ({rays / local_trace / k / 1e6:.2f} M rays/s per thread)")
        cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": k, "node_ip_address": "127.0.0.1", "include_dashboard": False,
                                                                "object_store_memory": 200 * 1024 * 1024})
        try:
            ray.init(address=cluster.address, log_to_driver=False)
            t = time.perf_counter()
            bake.bake_level(scene, bake.BakeSettings(preset="draft", samples=1, probe_samples=1), executor=RayExecutor())
            print(f"  warm-up (worker start-up, a 1-sample bake): {time.perf_counter() - t:.2f} s")
            for tile in (int(x) for x in args.tiles.split(",")):
                s = bake.BakeSettings(preset=args.preset, samples=args.samples, probe_samples=args.probe_samples, tile_texels=tile,
                                      probe_tile=max(16, tile // 32))
                ex = RayExecutor()
                t = time.perf_counter()
                got = bake.bake_level(scene, s, executor=ex)
                total = time.perf_counter() - t
                r = got.stats["ray"]
                overhead = r["wall_seconds"] / local_trace - 1.0
                # Less sensitive to other load on the machine than the ratio of two runs: the share
                # of the workers' wall time spent outside the tasks (scheduling, transfers, the tail).
                idle = 1.0 - r["task_seconds"] / (r["wall_seconds"] * k)
                rows.append((k, tile, overhead))
                # Rays per second of task time: the workers' tracing speed itself, apart from what
                # scheduling costs (compare with the local bake's per thread).
                in_task = (got.stats["rays"] + got.stats["probes"]["rays"]) / r["task_seconds"]
                print(f"  tile {tile:>6}: {r['tiles']:>4} tiles + {r['probe_batches']} probe batches, tracing {r['wall_seconds']:.2f} s "
                      f"({r['rays_per_s'] / 1e6:.2f} M rays/s; {in_task / 1e6:.2f} per worker in tasks), bake_level {total:.2f} s; "
                      f"overhead {overhead * 100:+.1f}%, workers idle {idle * 100:.1f}%; "
                      f"scene built {r['scene_builds']}x on {r['workers']} worker(s); identical: {same(got, local)}")
        finally:
            ray.shutdown()
            cluster.shutdown()
    print()
    for k in sorted({r[0] for r in rows}):
        ok = [tile for kk, tile, o in rows if kk == k and o < 0.10]
        print(f"{k} worker(s): smallest tile size with overhead under 10%: {min(ok) if ok else 'none of those tried'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
