"""Atomic outputs: a cook killed with SIGKILL at any point leaves the previous pack whole.

A small level (CSG, lightmap UVs, a draft bake, procedural textures with mips) is cooked once to
learn its stages and their times; then, 20 times, a forced cook that would write different bytes
(another bake seed) is killed inside a chosen stage: once in each stage and after the last, the
rest in and after the write (where the pack is renamed into place). A kill waits for the cook's line saying the stage before
it ended (the event), then a seeded random part of the stage's measured time, so where it lands
does not depend on the machine's speed or load. Every time the pack on disk
must be either the previous pack, byte for byte, or the complete new one (the kill landed after
the rename), and must load; anything else left beside it must be a hidden temporary file that no
one would take for a pack; and the next cook must succeed with exactly the expected bytes (so a
half-written cache entry cannot leak into it) and clear the dead cook's temporary files, beside
the pack and in the stage cache.
"""

from __future__ import annotations

import os
import random
import re
import signal
import subprocess
import time
from pathlib import Path

import pytest

import asset_pipeline
from conftest import COOK

LEVEL = """
[level]
name = "atomic"
texels_per_metre = 6

[[materials]]
name = "stone"
texture = { procedural = "bricks", size = 64, seed = 3 }

[[materials]]
name = "plaster"
base_color = [0.8, 0.78, 0.7]

[[brushes]]
name = "floor"
kind = "box"
size = [8, 0.5, 8]
material = "stone"

[[brushes]]
name = "hut"
kind = "box"
size = [3, 3, 3]
translation = [0, 1.7, 0]
material = "stone"

[[brushes]]
name = "room"
kind = "box"
size = [2.4, 2.4, 2.4]
translation = [0, 1.7, 0]
material = "plaster"

[[brushes]]
name = "door"
kind = "box"
size = [0.8, 1.6, 1]
translation = [0, 1.2, 1.3]
material = "plaster"

[[objects]]
name = "ground"
op = "union"
operands = ["floor"]

[[objects]]
name = "house"
op = "difference"
operands = ["hut", "room", "door"]

[[lights]]
name = "sun"
kind = "sun"
intensity = 50000
direction = [-0.4, -1, -0.3]
"""

KILLS = 20
ENV = {**os.environ, "OMP_NUM_THREADS": "1"}


def cook(src: Path, out: Path, seed: int, *extra: str, quiet: bool = True) -> subprocess.Popen:
    """A cook; not quiet, it prints a line to stderr as each stage ends."""
    return subprocess.Popen([str(COOK), str(src), "-o", str(out), *(["-q"] if quiet else []), "--quality", "draft", "--seed", str(seed), *extra],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV)


def finish(p: subprocess.Popen) -> str:
    stdout, stderr = p.communicate(timeout=300)
    assert p.returncode == 0, stderr
    return stderr


# The line the cook prints as each stage ends (stderr not a terminal): "cook: bake p0: 9176/9176 in 0.08 s, ...".
STAGE_LINE = re.compile(r"^cook: ([\w ]+): \d+/\d+ in ([\d.]+) s")


def stages(stderr: str) -> list[tuple[str, float]]:
    return [(m[1], float(m[2])) for m in map(STAGE_LINE.match, stderr.splitlines()) if m]


def wait_for_stage_end(p: subprocess.Popen, stage: str) -> list[str]:
    """Read the cook's stderr until the line saying `stage` ended (or the end of the output, if the
    cook ended or failed first); returns the lines read."""
    lines = []
    for line in p.stderr:
        lines.append(line)
        m = STAGE_LINE.match(line)
        if m and m[1] == stage:
            break
    return lines


def loads(pack: Path) -> None:
    asset_pipeline._core.read_pack_manifest(pack)  # raises CookError on any damage
    assert asset_pipeline.read_pack_summary(pack)["meshes"] == 2


def test_sigkill_during_cook_keeps_the_previous_pack(tmp_path):
    src = tmp_path / "atomic.toml"
    src.write_text(LEVEL)
    # The two packs a cook here can produce: bake seed 0 and bake seed 1 (in a separate
    # directory, with its own cache). The second cook is forced, to time a cook that does all
    # the work.
    ref = tmp_path / "ref"
    ref.mkdir()
    finish(cook(src, ref / "one.pack", 1))
    order = stages(finish(cook(src, ref / "one.pack", 1, "--force", quiet=False)))
    names = [n for n, _ in order]
    assert names[-1] == "write" and len(names) >= 5, order
    packs = {0: None, 1: (ref / "one.pack").read_bytes()}

    out_dir = tmp_path / "out"
    out_dir.mkdir()
    out = out_dir / "atomic.pack"
    finish(cook(src, out, 0))
    packs[0] = out.read_bytes()
    assert packs[0] != packs[1], "the seed does not change the bake; the test could not tell the packs apart"
    expected_files = {"atomic.pack", "atomic.report.md", "atomic.lightmap0.exr", ".cook-cache"}
    settled = {p.name for p in out_dir.iterdir()}
    assert expected_files <= settled, settled

    rng = random.Random(20261123)
    # One kill in each stage (the first one from the start: the imports and the level stage) and
    # one after the write (the report and the cache's entries are written then, and the pack is
    # the new one); the others alternately in the write and after it.
    order.append(("after the write", order[-1][1]))
    targets = list(range(len(order)))
    targets += [len(order) - 2 + k % 2 for k in range(KILLS - len(targets))]
    current, outcomes = 0, {"old": 0, "new": 0}
    for k, i in enumerate(targets):
        seed = 1 - current  # a cook whose pack differs from the one on disk
        stage, seconds = order[i]
        into = rng.random() * seconds  # this far into the stage, by its measured time
        p = cook(src, out, seed, "--force", quiet=False)
        if i > 0:
            wait_for_stage_end(p, order[i - 1][0])
        time.sleep(into)
        p.send_signal(signal.SIGKILL)
        p.communicate(timeout=60)
        assert p.returncode in (-signal.SIGKILL, 0), (k, p.returncode)
        where = f"kill {k} in stage {stage}, {into * 1000:.0f} ms into it"

        got = out.read_bytes()
        assert got in (packs[current], packs[seed]), f"{where}: the pack is neither the previous one nor the new one"
        outcomes["old" if got == packs[current] else "new"] += 1
        loads(out)
        # Whatever else the killed cook left is a hidden temporary, not something to load.
        for f in out_dir.iterdir():
            if f.name not in expected_files and f.name not in settled:
                assert f.name.startswith(".") and (f.name.endswith(".tmp") or ".tmp-" in f.name), f"{where}: stray file {f.name}"
                assert not f.name.endswith(".pack"), f.name
        assert sorted(out_dir.glob("*.pack")) == [out]

        # The next cook succeeds, with exactly the bytes that seed gives, and clears the dead
        # cook's temporaries.
        finish(cook(src, out, seed))
        assert out.read_bytes() == packs[seed], f"the cook after kill {k} gave different bytes"
        loads(out)
        left = sorted(f.name for f in out_dir.iterdir() if f.name.startswith(".") and f.name != ".cook-cache")
        left += sorted(str(f.relative_to(out_dir)) for f in (out_dir / ".cook-cache").rglob("*.tmp"))
        assert left == [], f"after kill {k}: temporary files left: {left}"
        current = seed
    print(f"stages {order}; {KILLS} kills: {outcomes}")


def test_an_interrupted_write_leaves_the_old_file_and_no_temporary(tmp_path):
    """The cooker's small files (stage cache entries, the output stamp, the report) go through
    `write_atomic`: an exception or Ctrl-C in the middle keeps the previous file and removes the
    half-written temporary; a finished write replaces the file whole."""
    from asset_pipeline.cache import write_atomic

    path = tmp_path / "stamp.json"
    path.write_text("old")

    def interrupted(f):
        f.write(b"half")
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        write_atomic(path, interrupted)
    assert path.read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["stamp.json"]
    write_atomic(path, lambda f: f.write(b"new"))
    assert path.read_text() == "new"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["stamp.json"]
