"""Benchmark of mip generation (not a test): run it by hand, it prints a table.

    .venv/bin/python tools/bench_mips.py [--size 4096] [--rounds 5] [--threads N]

1. Throughput: the full chain (down to 1x1) of a size x size RGBA8 sRGB texture with the cooker's
   default colour path (``_core.mip_chain(level0, "color")``: sRGB -> linear, premultiply,
   Mitchell-Netravali, un-premultiply, encode, round once) against Pillow's LANCZOS halving chain
   (``im.resize((w // 2, h // 2), LANCZOS)`` level on level: 8-bit, gamma-naive, premultiplied
   RGBa internally, single-threaded) in the same run. Rounds alternate the two; the ratio is the
   median of the per-round ratios (the shared machine's noise spoils ratios of bests). Pillow
   runs on one thread, so the ratio of record is ours on one thread against it (thread for
   thread); ours on every core is printed separately. Without ``--threads`` the script runs both
   (each in a child process: RAYON_NUM_THREADS fixes the pool at start); with it, that one.
2. Aliasing: the notes' zone plate (notes/textures.md §1.13 test 4, N=512, one grey channel as
   linear data, clamped edges) through levels 1-3 of each chain: alias RMS where the local
   frequency lies in [0.3, 0.5] cycles per texel of the level before (ideal: flat 0.5) and
   passband RMS error where it is <= 0.1; gates 0.05 and 0.06.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

import numpy as np


def test_texture(n: int) -> np.ndarray:
    """Photograph-like content: smooth gradients, edges and noise, opaque with a few holes."""
    y, x = np.mgrid[0:n, 0:n].astype(np.float32) / n
    rng = np.random.default_rng(1)
    r = 0.5 + 0.4 * np.sin(13 * x + 3 * y)
    g = 0.5 + 0.4 * np.cos(7 * y * x * 9)
    b = ((x * 16).astype(int) + (y * 16).astype(int)) % 2 * 0.6 + 0.2
    rgb = np.stack([r, g, b], -1) + rng.normal(0, 0.05, (n, n, 3)).astype(np.float32)
    a = np.where((x - 0.5) ** 2 + (y - 0.5) ** 2 < 0.02, 0.0, 1.0)[..., None]
    return np.ascontiguousarray((np.clip(np.concatenate([rgb, a], -1), 0, 1) * 255 + 0.5).astype(np.uint8))


def pillow_chain(level0: np.ndarray) -> list[np.ndarray]:
    from PIL import Image

    im = Image.fromarray(level0, "RGBA")
    out = []
    while im.width > 1 or im.height > 1:
        im = im.resize((max(1, im.width // 2), max(1, im.height // 2)), Image.LANCZOS)
        out.append(np.asarray(im))
    return out


def zone_plate(n: int) -> tuple[np.ndarray, callable]:
    f = lambda x, y: 0.5 + 0.5 * np.cos(np.pi * (x * x + y * y) / (2 * n))
    y, x = np.mgrid[0:n, 0:n].astype(np.float64)
    v = np.round(f(x, y) * 255).astype(np.uint8)
    return np.ascontiguousarray(np.stack([v, v, v, np.full_like(v, 255)], -1)), f


def alias_numbers(levels: list[np.ndarray], n: int, f) -> list[tuple[float, float]]:
    out = []
    for k, lv in enumerate(levels[:3], start=1):
        step = 2.0 ** k
        h, w = lv.shape[:2]
        i, j = np.mgrid[0:h, 0:w].astype(np.float64)
        x, y = step * (j + 0.5) - 0.5, step * (i + 0.5) - 0.5
        freq = np.sqrt(x * x + y * y) / (2 * n) * step / 2
        v = lv[..., 0].astype(np.float64) / 255
        band = (freq >= 0.3) & (freq <= 0.5)
        pass_ = freq <= 0.1
        out.append((float(np.sqrt(np.mean((v[band] - 0.5) ** 2))), float(np.sqrt(np.mean((v[pass_] - f(x, y)[pass_]) ** 2)))))
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", type=int, default=4096)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--threads", type=int, help="threads for the cooker (RAYON_NUM_THREADS); default: 1, then every core")
    ap.add_argument("--throughput-only", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if not args.threads:
        both_thread_counts(args)
    else:
        os.environ["RAYON_NUM_THREADS"] = str(args.threads)
        throughput(args)
    if not args.throughput_only:
        aliasing()
    return 0


def throughput(args) -> None:
    import PIL

    from asset_pipeline._core import mip_chain

    level0 = test_texture(args.size)
    texels = sum(max(1, args.size >> k) ** 2 for k in range(1, args.size.bit_length()))
    ours_t, pil_t, ratios = [], [], []
    mip_chain(level0[:256, :256].copy(), "color")  # warm the tables and the thread pool
    for r in range(args.rounds):
        t = time.perf_counter()
        ours = mip_chain(level0, "color")
        a = time.perf_counter() - t
        t = time.perf_counter()
        pil = pillow_chain(level0)
        b = time.perf_counter() - t
        assert [l.shape for l in ours] == [l.shape for l in pil]
        ours_t.append(a)
        pil_t.append(b)
        ratios.append(b / a)
        print(f"round {r + 1}: ours {a * 1e3:7.1f} ms   Pillow LANCZOS {b * 1e3:7.1f} ms   ratio {b / a:5.2f}x", flush=True)
    threads = args.threads
    print(f"\n{args.size}x{args.size} RGBA8 sRGB, full chain ({len(ours)} levels below 0, {texels / 1e6:.2f} M output texels); "
          f"cooker threads {threads}, Pillow {PIL.__version__} 1 thread")
    print(f"ours (mitchell, linear light)  median {statistics.median(ours_t) * 1e3:7.1f} ms  {texels / statistics.median(ours_t) / 1e6:6.1f} Mtexel/s")
    print(f"Pillow LANCZOS halving chain   median {statistics.median(pil_t) * 1e3:7.1f} ms  {texels / statistics.median(pil_t) / 1e6:6.1f} Mtexel/s")
    print(f"throughput ratio (median of per-round ratios): ours on {threads} thread(s) {statistics.median(ratios):.2f}x Pillow on 1")


def aliasing() -> None:
    from asset_pipeline._core import mip_chain

    n = 512
    zp, f = zone_plate(n)
    rows = [
        ("ours mitchell (default)", mip_chain(zp, "data", edge="clamp")),
        ("ours box", mip_chain(zp, "data", filter="box", edge="clamp")),
        ("Pillow LANCZOS", pillow_chain(zp)),
    ]
    print(f"\nzone plate N={n} (gates: alias RMS <= 0.05, pass RMS <= 0.06)")
    print(f"{'':26} " + "  ".join(f"L{k} alias  L{k} pass" for k in (1, 2, 3)))
    for name, levels in rows:
        nums = alias_numbers(levels, n, f)
        print(f"{name:26} " + "  ".join(f"{a:8.4f} {p:8.4f}" for a, p in nums))


def both_thread_counts(args) -> None:
    """Runs the throughput part on 1 thread and on every core (child processes); prints the
    thread-for-thread ratio and the all-core one apart."""
    import re
    import subprocess

    found = {}
    for th in sorted({1, os.cpu_count() or 1}):
        cmd = [sys.executable, __file__, "--size", str(args.size), "--rounds", str(args.rounds), "--threads", str(th), "--throughput-only"]
        out = subprocess.run(cmd, capture_output=True, text=True, check=True).stdout
        print(out, end="")
        m = re.search(r"ours on \d+ thread\(s\) ([0-9.]+)x", out)
        found[th] = float(m.group(1)) if m else float("nan")
    print("\nthread for thread: ours on 1 thread / Pillow on 1 = " + f"{found[1]:.2f}x (goal >= 2x)")
    for th, r in found.items():
        if th != 1:
            print(f"all cores: ours on {th} threads / Pillow on 1 = {r:.2f}x (not thread for thread)")


if __name__ == "__main__":
    sys.exit(main())
