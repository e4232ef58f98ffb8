"""`cook --watch`: a level edited while the cooker watches it (asset_pipeline/watch.py).

The cooker runs as the user runs it (the console script, a child process); the test waits on its
output lines (events), never on sleeps: each step edits the level and waits for the line that
says what the cooker did about it.
"""

from __future__ import annotations

import json
import os
import re
import queue
import signal
import subprocess
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from asset_pipeline import _core
from conftest import COOK

LEVEL = """
[level]
name = "watched"
texels_per_metre = 4
sky = {{ color = [0.5, 0.7, 1.0], intensity = 3000 }}

[[materials]]
name = "stone"
base_color = {color}

[[brushes]]
name = "floor"
kind = "box"
size = [6, 0.5, 6]
material = "stone"

[[brushes]]
name = "pillar"
kind = "box"
size = [1, 3, 1]
translation = [0, 1.75, 0]
material = "stone"

[[objects]]
name = "room"
op = "union"
operands = ["floor", "pillar"]
"""

# Generous fail-safe for one step on a loaded machine; a step normally takes well under a second.
STEP_TIMEOUT_S = 120


class Watcher:
    """`cook --watch` in a child process, its stdout and stderr lines in one queue as they come."""

    def __init__(self, *args: str, cwd: Path):
        self.proc = subprocess.Popen([str(COOK), *args, "--watch"], cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     text=True, bufsize=1)
        self.lines: queue.Queue[tuple[str, str]] = queue.Queue()
        self.seen: list[tuple[str, str]] = []
        for name, stream in (("out", self.proc.stdout), ("err", self.proc.stderr)):
            threading.Thread(target=self._pump, args=(name, stream), daemon=True).start()

    def _pump(self, name: str, stream) -> None:
        for line in stream:
            self.lines.put((name, line.rstrip("\n")))

    def next_line(self) -> tuple[str, str]:
        """The next line (stream, text), within the fail-safe."""
        try:
            item = self.lines.get(timeout=STEP_TIMEOUT_S)
        except queue.Empty:
            pytest.fail(f"the cooker said nothing for {STEP_TIMEOUT_S} s; so far:\n" + self.transcript())
        self.seen.append(item)
        return item

    def expect(self, prefix: str, stream: str = "out") -> str:
        """Wait for the next line of `stream` starting with `prefix`; fail (with everything the
        cooker said) if the cooker exits or the fail-safe passes first."""
        deadline = time.monotonic() + STEP_TIMEOUT_S
        while True:
            try:
                name, line = self.lines.get(timeout=max(0.0, deadline - time.monotonic()))
            except queue.Empty:
                pytest.fail(f"no '{prefix}' line within {STEP_TIMEOUT_S} s; the cooker said:\n" + self.transcript())
            self.seen.append((name, line))
            if name == stream and line.startswith(prefix):
                return line

    def transcript(self) -> str:
        return "\n".join(f"[{n}] {line}" for n, line in self.seen)

    def stop(self) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
        return self.proc.wait(timeout=STEP_TIMEOUT_S)


PROP = """
[[props]]
name = "crate"
gltf = "crate.gltf"
translation = [2, 0.75, 2]
"""


def write_crate(path: Path, color) -> None:
    """A one-box glTF prop with its buffer in a file of its own (crate.bin)."""
    from gltf_scenes import Scene

    s = Scene()
    s.node("crate", mesh=s.box_mesh("crate", size=(1, 1, 1), material=s.material("paint", color=(*color, 1))))
    s.write(path, external=True)


def colour_of(pack: Path) -> list[float]:
    manifest = json.loads(_core.read_pack_manifest(pack))
    return manifest["materials"][0]["base_color"][:3]


def write_level(path: Path, text: str) -> None:
    # As an editor saves: a new file renamed over the old one.
    tmp = path.with_name(f".{path.name}.swp")
    tmp.write_text(text)
    os.replace(tmp, path)


def test_watch_recooks_an_edit_keeps_the_pack_on_a_broken_one_and_resumes(tmp_path):
    level, pack = tmp_path / "level.toml", tmp_path / "level.pack"
    level.write_text(LEVEL.format(color="[0.8, 0.2, 0.2]"))
    w = Watcher("level.toml", "-o", "level.pack", "--quality", "draft", "-q", cwd=tmp_path)
    try:
        first = w.expect("cook: wrote level.pack")
        w.expect("cook: watching 1 file")
        assert "cached:" not in first, first  # a new cache: everything ran
        assert colour_of(pack) == pytest.approx([0.8, 0.2, 0.2])

        # A material colour edit: the pack is rewritten with the new colour, and the stages the
        # colour cannot change (lightmap UVs, LODs, mesh optimisation) come from the cache.
        t0 = time.monotonic()
        write_level(level, LEVEL.format(color="[0.2, 0.8, 0.2]"))
        w.expect("cook: changed: level.toml")
        wrote = w.expect("cook: wrote level.pack")
        seconds = time.monotonic() - t0
        assert colour_of(pack) == pytest.approx([0.2, 0.8, 0.2])
        ran, cached = re.search(r"ran: ([^;]*); cached: ([^)]*)\)", wrote).groups()
        assert {"level", "bake", "write"} <= set(ran.split(", ")), wrote
        assert {"uv2", "lod", "mesh_opt"} <= set(cached.split(", ")), wrote
        assert seconds < 5.0, f"the edit took {seconds:.2f} s to reach the pack"
        w.expect("cook: watching 1 file")

        # A broken edit: the error on one line, the pack byte for byte as it was.
        good = pack.read_bytes()
        write_level(level, LEVEL.format(color="[0.2, 0.8]"))
        error = w.expect("cook: error:", stream="err")
        assert "level.toml" in error and "base_color" in error, error
        w.expect("cook: level.pack left as it was")
        w.expect("cook: watching 1 file")
        assert pack.read_bytes() == good

        # The fix cooks again.
        write_level(level, LEVEL.format(color="[0.1, 0.3, 0.9]"))
        w.expect("cook: wrote level.pack")
        assert colour_of(pack) == pytest.approx([0.1, 0.3, 0.9])
        w.expect("cook: watching 1 file")
    finally:
        code = w.stop()
    assert code == 0, w.transcript()
    w.expect("cook: stopped watching")
    assert not any(n == "err" and "Traceback" in line for n, line in w.seen), w.transcript()


def test_watch_follows_a_new_prop_file(tmp_path):
    """An edit that names a new file (a glTF prop) is followed by watching that file too."""
    level, pack = tmp_path / "level.toml", tmp_path / "level.pack"
    level.write_text(LEVEL.format(color="[0.8, 0.8, 0.8]"))
    w = Watcher("level.toml", "-o", "level.pack", "--quality", "draft", "-q", cwd=tmp_path)
    try:
        w.expect("cook: watching 1 file")
        write_crate(tmp_path / "crate.gltf", color=(0.9, 0.1, 0.1))
        write_level(level, LEVEL.format(color="[0.8, 0.8, 0.8]") + PROP)
        w.expect("cook: wrote level.pack")
        w.expect("cook: watching 3 files")  # the level, the prop and its buffer
        before = pack.read_bytes()
        write_crate(tmp_path / "crate.gltf", color=(0.1, 0.1, 0.9))
        assert "crate.gltf" in w.expect("cook: changed: ")
        w.expect("cook: wrote level.pack")
        assert pack.read_bytes() != before
    finally:
        assert w.stop() == 0, w.transcript()


def test_watch_cannot_start_without_its_output_directory(tmp_path):
    (tmp_path / "level.toml").write_text(LEVEL.format(color="[0.8, 0.2, 0.2]"))
    r = subprocess.run([str(COOK), "level.toml", "-o", "missing/level.pack", "--watch"], cwd=tmp_path, capture_output=True, text=True,
                       timeout=STEP_TIMEOUT_S)
    assert r.returncode == 2
    assert r.stderr.strip().splitlines() == ["cook: error: missing/level.pack: output directory 'missing' does not exist"]


def samples_of(pack: Path) -> int | None:
    return json.loads(_core.read_pack_manifest(pack))["lightmap"].get("samples")


def test_refining_bake_writes_growing_sample_counts_and_ends_at_the_one_shot_bytes(tmp_path):
    """While watching, each cook bakes in steps (a sixteenth, a quarter, all of the target's
    samples), each written as a pack; the last is the one-shot `cook --quality medium` to the byte."""
    level, pack = tmp_path / "level.toml", tmp_path / "level.pack"
    level.write_text(LEVEL.format(color="[0.8, 0.5, 0.2]"))
    w = Watcher("level.toml", "-o", "level.pack", "--quality", "medium", "-q", cwd=tmp_path)
    try:
        for cycle in range(2):
            lines, seen = [], []
            while True:
                name, line = w.next_line()
                if line.startswith("cook: wrote level.pack"):
                    lines.append(line)
                    seen.append(samples_of(pack))  # the pack as it is now (a later step may have replaced it)
                elif line.startswith("cook: watching"):
                    break
            counts = [int(re.search(r"bake (\d+) samples per texel", line).group(1)) for line in lines]
            assert counts == [8, 32, 128], w.transcript()
            assert all("refining" in line for line in lines[:-1]) and "refining" not in lines[-1], lines
            assert all(a <= b for a, b in zip(seen, seen[1:])) and seen[-1] == 128, seen
            if cycle == 0:
                write_level(level, LEVEL.format(color="[0.3, 0.5, 0.9]"))
    finally:
        assert w.stop() == 0, w.transcript()
    assert samples_of(pack) == 128

    # The same source cooked once at the target, elsewhere (its own cache): the same bytes.
    other = tmp_path / "once"
    other.mkdir()
    (other / "level.toml").write_text(level.read_text())
    r = subprocess.run([str(COOK), "level.toml", "-o", "level.pack", "--quality", "medium", "-q"], cwd=other, capture_output=True, text=True,
                       timeout=STEP_TIMEOUT_S)
    assert r.returncode == 0, r.stderr
    assert (other / "level.pack").read_bytes() == pack.read_bytes()
    assert (other / "level.lightmap0.exr").read_bytes() == (tmp_path / "level.lightmap0.exr").read_bytes()


def test_a_step_given_up_for_an_edit_writes_nothing_and_keeps_the_sums(tmp_path):
    """Refinement.stop asked between batches: a step given up raises Superseded before anything
    is written, and the sums stay those of the last finished step (the next step goes on from them)."""
    from asset_pipeline.bake import BakeSettings, Refinement, Superseded
    from asset_pipeline.cook import cook_detailed
    from asset_pipeline.pipeline import CookSettings

    level, pack = tmp_path / "level.toml", tmp_path / "level.pack"
    level.write_text(LEVEL.format(color="[0.8, 0.5, 0.2]"))
    r = Refinement()
    small = BakeSettings(preset="medium", samples=4, reflection_samples=1, batch_texels=64)
    cook_detailed(level, pack, progress=False, settings=CookSettings(bake=small, refine=r))
    assert r.samples == 4 and len(r.pages) == 1 and len(r.pages[0]) > 3 * 64  # several batches a page
    sums, before = r.pages[0].copy(), pack.read_bytes()
    asked = []
    r.stop = lambda: asked.append(1) or len(asked) > 2  # an edit arrives after two batches
    with pytest.raises(Superseded):
        cook_detailed(level, pack, progress=False, settings=CookSettings(bake=BakeSettings(preset="medium", batch_texels=64), refine=r))
    assert len(asked) == 3
    assert r.samples == 4 and np.array_equal(r.pages[0], sums)
    assert pack.read_bytes() == before
    # Going on from the kept sums ends where a one-shot bake does.
    r.stop = None
    cook_detailed(level, pack, progress=False, settings=CookSettings(bake=BakeSettings(preset="medium", batch_texels=64), refine=r))
    assert r.samples == 128
    once = tmp_path / "once"
    once.mkdir()
    (once / "level.toml").write_text(level.read_text())
    cook_detailed(once / "level.toml", once / "level.pack", progress=False, settings=CookSettings(bake=BakeSettings(preset="medium")))
    assert (once / "level.lightmap0.exr").read_bytes() == (tmp_path / "level.lightmap0.exr").read_bytes()
