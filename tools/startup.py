#!/usr/bin/env python3
"""Start-up time of the demo, launch to first frame, stage by stage (issue 24): runs
`demo PACK --headless --frames 1` several times and reports the median of each stage the demo
prints on its "start-up:" line. Given two demo binaries, runs them alternately (A B B A ...)
and prints both with their ratio, so the machine's drift falls on both alike.

    python3 tools/startup.py [--demo BIN [--demo BIN2]] [--runs N] PACK [PACK...]

A PACK given as `A.pack,B.pack` gives each binary its own pack (two builds that read different
pack versions, each with the same content cooked for it).
"""

from __future__ import annotations

import argparse
import re
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
LINE = re.compile(r"^start-up: (?P<stages>.*); launch to first frame (?P<total>[0-9.]+) ms$", re.M)


def run(demo: Path, pack: Path) -> dict[str, float]:
    with tempfile.TemporaryDirectory() as tmp:
        r = subprocess.run([str(demo), str(pack), "--headless", "--frames", "1", "--screenshot", str(Path(tmp) / "frame.png")],
                           capture_output=True, text=True, timeout=600)
    m = LINE.search(r.stdout)
    if r.returncode != 0 or m is None:
        sys.exit(f"startup: {demo} {pack} failed ({r.returncode}):\n{r.stdout}\n{r.stderr}")
    stages = {}
    for part in m["stages"].split(", "):
        name, ms, _ = part.rsplit(" ", 2)
        stages[name] = float(ms)
    stages["launch to first frame"] = float(m["total"])
    return stages


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("packs", nargs="+", help="a pack, or A.pack,B.pack: one per binary")
    ap.add_argument("--demo", action="append", type=Path, help="demo binary (twice to compare two; default target/release/demo)")
    ap.add_argument("--runs", type=int, default=5, help="launches per binary and pack (default 5)")
    args = ap.parse_args()
    demos = args.demo or [REPO / "target" / "release" / "demo"]
    for arg in args.packs:
        packs = [Path(p) for p in arg.split(",")]
        if len(packs) not in (1, len(demos)):
            ap.error(f"{arg}: give one pack, or one per --demo")
        packs = packs * len(demos) if len(packs) == 1 else packs
        runs: list[list[dict]] = [[] for _ in demos]
        for k in range(args.runs):
            order = range(len(demos)) if k % 2 == 0 else reversed(range(len(demos)))
            for d in order:
                runs[d].append(run(demos[d], packs[d]))
        sizes = ", ".join(f"{p} ({p.stat().st_size} bytes)" for p in dict.fromkeys(packs))
        print(f"\n{sizes}, median of {args.runs} launches, ms:\n")
        names = list(runs[0][0])
        head = "| stage | " + " | ".join(str(d) for d in demos) + (" | B/A |" if len(demos) == 2 else " |")
        print(head)
        print("|---" * (len(demos) + 1 + (len(demos) == 2)) + "|")
        for name in names:
            med = [statistics.median(r[name] for r in rs) for rs in runs]
            ratio = f" | {med[1] / med[0]:.2f}x" if len(demos) == 2 and med[0] > 0 else ""
            print(f"| {name} | " + " | ".join(f"{m:.1f}" for m in med) + ratio + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
