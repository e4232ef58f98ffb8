"""Benchmark of the iteration loop (not a test): how long from saving a level edit to the demo
showing it, with `cook --watch` and `demo --watch --headless` running side by side as a
designer runs them.

    .venv/bin/python tools/bench_loop.py [--level content/levels/temple.toml] [--quality draft] [--edits 3]

The level's folder is copied to a temporary one (the edits never touch the project's content);
a first cook there fills the stage cache (not timed: a designer's loop starts from a cooked
level). Then both watchers start; each edit changes one material's base colour in the copy,
and the script records, from the watchers' output lines, when the cooker noticed it, when each
bake step's pack was written (a sixteenth, a quarter, all of the target's samples) and when the
demo printed `reloaded` for each. Printed per edit, then the medians.
"""

from __future__ import annotations

import argparse
import os
import queue
import re
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
COOK = ROOT / ".venv" / "bin" / "cook"
DEMO = ROOT / "target" / "release" / "demo"


class Lines:
    """A child's stdout and stderr lines with the time each arrived."""

    def __init__(self, cmd: list[str], cwd: Path):
        self.proc = subprocess.Popen(cmd, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, bufsize=1)
        self.q: queue.Queue = queue.Queue()
        for stream in (self.proc.stdout, self.proc.stderr):
            threading.Thread(target=self._pump, args=(stream,), daemon=True).start()

    def _pump(self, stream) -> None:
        for line in stream:
            self.q.put((time.monotonic(), line.rstrip("\n")))

    def until(self, pattern: str, timeout: float = 600) -> tuple[float, str]:
        deadline = time.monotonic() + timeout
        while True:
            try:
                t, line = self.q.get(timeout=max(0.0, deadline - time.monotonic()))
            except queue.Empty:
                sys.exit(f"bench_loop: no line matching '{pattern}' within {timeout} s")
            if re.search(pattern, line):
                return t, line

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        self.proc.wait(timeout=120)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--level", type=Path, default=ROOT / "content" / "levels" / "temple.toml")
    ap.add_argument("--quality", default="draft")
    ap.add_argument("--edits", type=int, default=3)
    ap.add_argument("--material", default="plaster", help="the material whose base_color each edit changes")
    args = ap.parse_args()
    for tool in (COOK, DEMO):
        if not tool.exists():
            sys.exit(f"bench_loop: {tool} is missing (make build / make cooker)")
    with tempfile.TemporaryDirectory(prefix="bench_loop_") as tmp:
        work = Path(tmp) / "level"
        shutil.copytree(args.level.resolve().parent, work)
        level = work / args.level.name
        pack = Path(tmp) / "level.pack"
        text = level.read_text()
        block = re.search(rf'\[\[materials\]\]\s*\nname = "{re.escape(args.material)}"\n(?:(?!\[\[).*\n)*?base_color = \[[^\]]*\]', text)
        if block is None:
            sys.exit(f"bench_loop: no material '{args.material}' with a base_color in {args.level}")
        t0 = time.monotonic()
        r = subprocess.run([str(COOK), str(level), "-o", str(pack), "--quality", args.quality, "-q"], capture_output=True, text=True)
        if r.returncode != 0:
            sys.exit(f"bench_loop: the first cook failed: {r.stderr.strip()}")
        print(f"first cook (fills the cache, not counted): {time.monotonic() - t0:.1f} s")
        cook = Lines([str(COOK), str(level), "-o", str(pack), "--quality", args.quality, "-q", "--watch"], cwd=Path(tmp))
        demo = Lines([str(DEMO), str(pack), "--headless", "--watch", "--flight", "0", "--screenshot", str(Path(tmp) / "shot.png")], cwd=Path(tmp))
        rows = []
        try:
            cook.until(r"^cook: watching")
            demo.until(r"^watching ")
            for e in range(args.edits):
                colour = [0.3 + 0.2 * ((e + k) % 3) for k in range(3)]
                edited = text[:block.start()] + re.sub(r"base_color = \[[^\]]*\]", f"base_color = {colour}", block.group(0)) + text[block.end():]
                t_save = time.monotonic()
                level.write_text(edited)
                t_seen = cook.until(r"^cook: changed")[0]
                steps, shown = [], []
                while True:
                    t, line = cook.until(r"^cook: (wrote|watching)")
                    if line.startswith("cook: watching"):
                        break
                    steps.append((int(re.search(r"bake (\d+) samples", line).group(1)), t - t_save))
                for _ in steps:
                    shown.append(demo.until(r"^reloaded ")[0] - t_save)
                rows.append((t_seen - t_save, steps, shown))
                print(f"edit {e + 1}: noticed after {t_seen - t_save:.2f} s; "
                      + "; ".join(f"{n} samples/texel written at {w:.1f} s, shown at {s:.1f} s" for (n, w), s in zip(steps, shown)))
        finally:
            cook.stop()
            demo.stop()
    first = [r[2][0] for r in rows]
    last = [r[2][-1] for r in rows]
    print(f"median over {len(rows)} edits: saved -> demo shows the first (draft) bake step {statistics.median(first):.1f} s, "
          f"the finished bake {statistics.median(last):.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
