"""Benchmark of the baker's BVH (not a test): closest-hit rays/s of ``_core.trace_rays`` against
Embree (PyPI ``embreex``) on the same incoherent rays, in the same run.

    .venv/bin/python tools/bench_bvh.py [--rays N] [--threads T] [--repeat R]
    .venv/bin/python tools/bench_bvh.py --raw scene.bin        # trace a raw scene + rays
    .venv/bin/python tools/bench_bvh.py --raw build/anchor.raw --embree build/embree_rays
    .venv/bin/python tools/bench_bvh.py --write-raw scene.bin  # dump the demo rays as raw

With `--embree BIN` (the anchor's raw Embree 3 program, ../shared/bench/embree_rays.c, built as
its README says) and `--raw`, that program traces the same file in the same run, alternating
with ours round by round (ours, Embree, ours, Embree ...) at 1 thread and at T threads, and the
ratios printed are thread for thread (ours on 1 thread against Embree on 1, T against T). Our BVH
build runs on as many threads as our rays; Embree's build always uses its own pool (every core),
so the build is compared for ours on 1 and on T threads.

Scene: the demo level (content/levels/temple.toml) built by the CSG stage, LOD 0 of every mesh
concatenated. Rays: points uniform by area on the surfaces, directions cosine-distributed around
each triangle's normal (the baker's hemisphere rays: incoherent), origins nudged off the surface;
t from 0 to inf, closest hit. Times exclude the BVH build (reported separately) and are the best
of R. Embree's Python binding traces on one thread; ours is shown at 1 and T threads.

Raw format (little-endian): u32 nv, nt, nr; f32 vertices [nv][3]; u32 triangles [nt][3];
f32 ray origins [nr][3]; f32 unit ray directions [nr][3].
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from asset_pipeline import _core

ROOT = Path(__file__).resolve().parent.parent


def demo_scene() -> tuple[np.ndarray, np.ndarray]:
    from asset_pipeline.csg import build_level
    from asset_pipeline.level import load_level

    scene = build_level(load_level(ROOT / "content/levels/temple.toml"))
    pos, tri, base = [], [], 0
    for m in scene.meshes:
        lod = m.lods[0]
        p = np.asarray(lod.attributes["position"], np.float32)
        pos.append(p)
        tri.append(np.asarray(lod.triangles, np.uint32).reshape(-1, 3) + base)
        base += len(p)
    return np.ascontiguousarray(np.concatenate(pos)), np.ascontiguousarray(np.concatenate(tri))


def surface_rays(pos: np.ndarray, tri: np.ndarray, n: int, seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    a, b, c = (pos[tri[:, k]].astype(np.float64) for k in range(3))
    cr = np.cross(b - a, c - a)
    area = 0.5 * np.linalg.norm(cr, axis=1)
    keep = area > 0
    t = rng.choice(np.flatnonzero(keep), size=n, p=area[keep] / area[keep].sum())
    u1, u2 = rng.random(n), rng.random(n)
    beta = 1 - np.sqrt(1 - u1)
    gamma = (1 - beta) * u2
    p = a[t] + beta[:, None] * (b[t] - a[t]) + gamma[:, None] * (c[t] - a[t])
    nrm = cr[t] / np.linalg.norm(cr[t], axis=1, keepdims=True)
    # Cosine-weighted around the normal (notes §6), in a frame built from it.
    phi, r2 = 2 * np.pi * rng.random(n), rng.random(n)
    local = np.stack([np.sqrt(r2) * np.cos(phi), np.sqrt(r2) * np.sin(phi), np.sqrt(1 - r2)], axis=1)
    helper = np.where(np.abs(nrm[:, :1]) > 0.9, [[0.0, 1.0, 0.0]], [[1.0, 0.0, 0.0]])
    tu = np.cross(helper, nrm)
    tu /= np.linalg.norm(tu, axis=1, keepdims=True)
    tv = np.cross(nrm, tu)
    d = local[:, :1] * tu + local[:, 1:2] * tv + local[:, 2:] * nrm
    o = p + nrm * 1e-4 * (1 + np.abs(p).max(axis=1, keepdims=True))
    return np.ascontiguousarray(o, np.float32), np.ascontiguousarray(d, np.float32)


def write_raw(path: Path, pos, tri, o, d) -> None:
    with open(path, "wb") as f:
        f.write(np.array([len(pos), len(tri), len(o)], "<u4").tobytes())
        for arr, dt in ((pos, "<f4"), (tri, "<u4"), (o, "<f4"), (d, "<f4")):
            f.write(np.ascontiguousarray(arr, dt).tobytes())


def read_raw(path: Path):
    buf = Path(path).read_bytes()
    nv, nt, nr = np.frombuffer(buf, "<u4", 3)
    off = 12
    out = []
    for count, dt in ((nv, "<f4"), (nt, "<u4"), (nr, "<f4"), (nr, "<f4")):
        a = np.frombuffer(buf, dt, int(count) * 3, off).reshape(-1, 3)
        off += a.nbytes
        out.append(np.ascontiguousarray(a.astype(a.dtype.newbyteorder("="))))
    if off != len(buf):
        sys.exit(f"{path}: {len(buf)} bytes, expected {off} for nv={nv} nt={nt} nr={nr}")
    return out


def best_of(repeat: int, f):
    best, out = float("inf"), None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = f()
        best = min(best, time.perf_counter() - t0)
    return best, out


EMBREE_LINE = re.compile(r"build (?P<build>[0-9.]+)s\s+(?P<threads>\d+) threads\s+(?P<rate>[0-9.]+) Mrays/s\s+hit (?P<hit>[0-9.]+)")


def embree_run(binary: Path, raw: Path, threads: int) -> tuple[float, float, float]:
    """One run of the anchor's Embree program: (best Mrays/s of its passes, its build seconds,
    hit fraction)."""
    r = subprocess.run([str(binary), str(raw), str(threads)], capture_output=True, text=True, check=True)
    runs = [m.groupdict() for m in EMBREE_LINE.finditer(r.stdout)]
    if not runs:
        sys.exit(f"{binary}: no 'Mrays/s' line in its output:\n{r.stdout}{r.stderr}")
    return max(float(x["rate"]) for x in runs), min(float(x["build"]) for x in runs), float(runs[0]["hit"])


def compare_with_embree(binary: Path, raw: Path, pos, tri, o, d, threads: int, rounds: int) -> None:
    """Ours and the anchor's Embree alternately, `rounds` rounds per thread count; best of each.
    Our BVH build runs on the same number of threads as our rays; Embree's build always uses its
    own thread pool (every core), so the build ratio is printed for ours on 1 and on T threads."""
    n = len(o)
    print(f"{'':30s} {'threads':>7s} {'Mrays/s (best)':>15s} {'per round':>22s} {'hit fraction':>13s}")
    builds: dict[int, list[float]] = {}
    ebuilds: list[float] = []
    for th in sorted({1, threads}):
        ours, theirs, hit = [], [], 0.0
        for _ in range(rounds):
            t0 = time.perf_counter()
            _core.trace_rays(pos, tri, o[:1], d[:1], threads=th)
            build = time.perf_counter() - t0
            builds.setdefault(th, []).append(build)
            t0 = time.perf_counter()
            tt, tid = _core.trace_rays(pos, tri, o, d, threads=th)
            ours.append(n / max(time.perf_counter() - t0 - build, 1e-9) / 1e6)
            rate, ebuild, hit = embree_run(binary, raw, th)
            theirs.append(rate)
            ebuilds.append(ebuild)
        ours_hit = float((tid != 0xFFFFFFFF).mean())
        print(f"{'ours':30s} {th:7d} {max(ours):15.2f} {', '.join(f'{x:.2f}' for x in ours):>22s} {ours_hit:13.4f}")
        print(f"{'Embree 3 (anchor, C)':30s} {th:7d} {max(theirs):15.2f} {', '.join(f'{x:.2f}' for x in theirs):>22s} {hit:13.4f}")
        print(f"ours / Embree, {th} thread(s): {max(ours) / max(theirs):.2f}x (best of {rounds} each; per round "
              f"{', '.join(f'{a / b:.2f}' for a, b in zip(ours, theirs))})")
    eb = min(ebuilds)
    cores = os.cpu_count()
    for th, b in sorted(builds.items()):
        print(f"BVH build: ours {min(b) * 1e3:.1f} ms on {th} thread(s), Embree {eb * 1e3:.1f} ms (its pool: {cores} threads): "
              f"ours / Embree {min(b) / eb:.2f}x")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rays", type=int, default=2_000_000)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--raw", type=Path, help="trace this raw scene + rays instead of the demo")
    ap.add_argument("--write-raw", type=Path, help="write the demo scene and rays here and stop")
    ap.add_argument("--embree", type=Path, help="the anchor's Embree 3 program (../shared/bench/embree_rays.c, built); needs --raw")
    args = ap.parse_args()
    if args.embree is not None and args.raw is None:
        ap.error("--embree traces a raw file: give --raw too")
    if args.embree is not None and not args.embree.exists():
        ap.error(f"{args.embree} does not exist: build it as ../shared/bench/README.md says")

    if args.raw:
        pos, tri, o, d = read_raw(args.raw)
        src = str(args.raw)
    else:
        pos, tri = demo_scene()
        o, d = surface_rays(pos, tri, args.rays)
        src = "content/levels/temple.toml"
        if args.write_raw:
            write_raw(args.write_raw, pos, tri, o, d)
            print(f"wrote {args.write_raw}: {len(pos)} vertices, {len(tri)} triangles, {len(o)} rays")
            return
    print(f"{src}: {len(tri)} triangles, {len(o)} rays (closest hit, t in (0, inf))")
    if args.embree is not None:
        compare_with_embree(args.embree, args.raw, pos, tri, o, d, args.threads, args.repeat)
        return
    n = len(o)
    # The build (on the same threads as the rays) is timed on a tiny ray set; tracing time =
    # total - build.
    rows = []
    for th in sorted({1, args.threads}):
        build, _ = best_of(args.repeat, lambda: _core.trace_rays(pos, tri, o[:1], d[:1], threads=th))
        t, (tt, tid) = best_of(args.repeat, lambda: _core.trace_rays(pos, tri, o, d, threads=th))
        rows.append((f"ours, {th} thread(s)", n / max(t - build, 1e-9), (tid != 0xFFFFFFFF).mean(), tt))
        print(f"ours: BVH build {build * 1e3:.1f} ms on {th} thread(s)")
    try:
        from embreex import rtcore_scene as rtcs
        from embreex.mesh_construction import TriangleMesh

        t0 = time.perf_counter()
        scene = rtcs.EmbreeScene()
        TriangleMesh(scene, pos, tri.astype(np.int32))
        scene.run(o[:1], d[:1])  # commits (builds) the scene
        print(f"embreex: scene build {(time.perf_counter() - t0) * 1e3:.1f} ms")
        t, res = best_of(args.repeat, lambda: scene.run(o, d, output=1))
        rows.append(("embreex (Embree), 1 thread", n / t, (res["primID"] >= 0).mean(), np.where(res["primID"] >= 0, res["tfar"], np.inf)))
    except ImportError as e:
        print(f"embreex not available: {e}")
    print(f"{'':30s} {'Mrays/s':>9s} {'hit fraction':>13s}")
    for name, rate, hit, _ in rows:
        print(f"{name:30s} {rate / 1e6:9.2f} {hit:13.4f}")
    if len(rows) > 2:
        ours, emb = rows[-2], rows[-1]
        tt, te = ours[3], emb[3]
        both = np.isfinite(tt) & np.isfinite(te)
        agree = np.isclose(tt[both], te[both], rtol=1e-4, atol=1e-5).mean() if both.any() else 1.0
        print(f"hits agree (same t within 1e-4) on {agree:.4%} of rays both hit; "
              f"hit/miss differs on {(np.isfinite(tt) != np.isfinite(te)).mean():.4%}")
        # Thread for thread: embreex traces on one thread, so it is compared with ours on one.
        print(f"ours (1 thread) / embreex (1 thread): {rows[0][1] / emb[1]:.2f}x")


if __name__ == "__main__":
    main()
