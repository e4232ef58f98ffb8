#!/usr/bin/env python3
"""Interleaved A/B of two `bench` binaries: scenario by scenario, A then B then B then A ... for
`--rounds` rounds, so the machine's drift (another job, the clock, the cache) falls on both
alike. Whichever binary ran first in a pair was faster in both of two back-to-back `--all` runs
on the shared 2-core machine, which made those comparisons useless.

    tools/bench_ab.py BENCH_A BENCH_B [--rounds 3] [--frames 20] [--warmup 3] [--scenarios a,b]
                      [--b-args "--no-variants"]

Prints, per scenario, the median over rounds of each binary's p50 CPU frame time, the ratio
B/A, the spread of the per-round ratios, and the counters that differ (exact counters: a
difference means the two did different work); with `--passes`, also each pass's median p50
GPU ms for A and B (`pass_gpu_ms` in bench's JSON). Exit status 0, 2 on bad arguments.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_report import SCENARIO_ORDER  # noqa: E402


def run(binary: Path, scenario: str, out: Path, frames: int, warmup: int, extra: list[str]) -> dict:
    out.mkdir(parents=True, exist_ok=True)
    subprocess.run([str(binary), "--scenario", scenario, "--frames", str(frames), "--warmup", str(warmup), "--json-dir", str(out), "--quiet", *extra],
                   check=True, stdout=subprocess.DEVNULL)
    return json.loads((out / f"{scenario}.json").read_text())


def main(argv: list[str]) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("a", type=Path)
    p.add_argument("b", type=Path)
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--frames", type=int, default=20)
    p.add_argument("--warmup", type=int, default=3)
    p.add_argument("--scenarios", default=",".join(SCENARIO_ORDER))
    p.add_argument("--a-args", default="", help="extra arguments for A (split on spaces)")
    p.add_argument("--b-args", default="", help="extra arguments for B, e.g. --no-variants against a build without them")
    p.add_argument("--passes", action="store_true", help="also print each pass's median p50 GPU ms for A and B")
    args = p.parse_args(argv)
    for b in (args.a, args.b):
        if not b.is_file():
            print(f"bench_ab: {b}: no such binary", file=sys.stderr)
            return 2
    rows, pass_rows = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for scenario in args.scenarios.split(","):
            p50 = {"A": [], "B": []}
            passes: dict = {"A": {}, "B": {}}
            counters = {}
            for r in range(args.rounds):
                # ABBA: each binary runs first in half of the pairs.
                order = ("A", "B") if r % 2 == 0 else ("B", "A")
                for who in order:
                    binary, extra = (args.a, args.a_args) if who == "A" else (args.b, args.b_args)
                    doc = run(binary, scenario, Path(tmp) / f"{who}{r}", args.frames, args.warmup, extra.split())
                    p50[who].append(doc["cpu_frame_ms"]["p50"])
                    for name, t in doc.get("pass_gpu_ms", {}).items():
                        passes[who].setdefault(name, []).append(t["p50"])
                    counters[who] = doc.get("counters", {})
            ratios = [b / a for a, b in zip(p50["A"], p50["B"])]
            ma, mb = statistics.median(p50["A"]), statistics.median(p50["B"])
            differ = sorted(k for k in set(counters["A"]) | set(counters["B"]) if counters["A"].get(k) != counters["B"].get(k))
            rows.append((scenario, ma, mb, mb / ma, min(ratios), max(ratios), ", ".join(differ) or "same"))
            if args.passes:
                names = sorted(set(passes["A"]) | set(passes["B"]))
                med = lambda who, n: statistics.median(passes[who][n]) if n in passes[who] else 0.0
                shown = [n for n in names if max(med("A", n), med("B", n)) >= 0.05]
                pass_rows.append((scenario, [(n, med("A", n), med("B", n)) for n in shown]))
            print(f"{scenario}: A {ma:.2f} ms, B {mb:.2f} ms, B/A {mb / ma:.3f} (rounds {min(ratios):.2f}-{max(ratios):.2f})", file=sys.stderr)
    print(f"A = {args.a}, B = {args.b}; {args.rounds} rounds (ABBA), {args.frames} frames after {args.warmup} warm-up\n")
    print("| scenario | A p50 ms (median) | B p50 ms (median) | B/A | per-round B/A | counters that differ |")
    print("|---|---|---|---|---|---|")
    for s, ma, mb, r, lo, hi, d in rows:
        print(f"| {s} | {ma:.2f} | {mb:.2f} | {r:.3f}x | {lo:.2f}-{hi:.2f} | {d} |")
    for s, cells in pass_rows:
        print(f"\n{s}, GPU ms per pass (median of the rounds' p50):\n")
        print("| pass | A | B |\n|---|---|---|")
        for n, a, b in cells:
            print(f"| {n} | {a:.2f} | {b:.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
