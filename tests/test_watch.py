"""The iteration loop: `cook --watch` (asset_pipeline/watch.py) on a level edited while it
watches, and `demo --watch --headless` (engine::assets::reload) on a pack rewritten under it.

Both run as the user runs them (child processes); the tests wait on their output lines (events),
never on sleeps: each step edits a file and waits for the line that says what was done about it.
"""

from __future__ import annotations

import json
import os
import re
import queue
import shutil
import signal
import subprocess
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from asset_pipeline import _core
from conftest import COOK, DEMO, REPO

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
    """`cook --watch` (or `command`) in a child process, its stdout and stderr lines in one queue
    as they come."""

    def __init__(self, *args: str, cwd: Path, command: list[str] | None = None, env: dict | None = None):
        command = command if command is not None else [str(COOK), *args, "--watch"]
        self.proc = subprocess.Popen(command, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, bufsize=1, env=env)
        self.lines: queue.Queue[tuple[str, str]] = queue.Queue()
        self.seen: list[tuple[str, str]] = []
        self.pos = {"out": 0, "err": 0}  # where each stream's next `expect` starts in `seen`
        self.read = 0  # `next_line`'s place in `seen`
        for name, stream in (("out", self.proc.stdout), ("err", self.proc.stderr)):
            threading.Thread(target=self._pump, args=(name, stream), daemon=True).start()

    def _pump(self, name: str, stream) -> None:
        for line in stream:
            self.lines.put((name, line.rstrip("\n")))

    def _pull(self, deadline: float, what: str) -> None:
        """One more line from the child into `seen`, or fail at the deadline with the transcript."""
        try:
            item = self.lines.get(timeout=max(0.0, deadline - time.monotonic()))
        except queue.Empty:
            pytest.fail(f"no {what} within {STEP_TIMEOUT_S} s; the child said:\n" + self.transcript())
        self.seen.append(item)

    def next_line(self) -> tuple[str, str]:
        """The next line of either stream not yet read by `next_line`, within the fail-safe."""
        deadline = time.monotonic() + STEP_TIMEOUT_S
        while self.read >= len(self.seen):
            self._pull(deadline, "line")
        self.read += 1
        return self.seen[self.read - 1]

    def expect(self, prefix: str, stream: str = "out") -> str:
        """The next line of `stream` (after the last one `expect` matched there) starting with
        `prefix`. The two streams are read apart: stdout and stderr lines reach the pipes in
        no fixed order, and waiting on one never drops a line of the other."""
        deadline = time.monotonic() + STEP_TIMEOUT_S
        i = self.pos[stream]
        while True:
            while i >= len(self.seen):
                self._pull(deadline, f"'{prefix}' line")
            name, line = self.seen[i]
            i += 1
            if name == stream and line.startswith(prefix):
                self.pos[stream] = i
                return line

    def transcript(self) -> str:
        return "\n".join(f"[{n}] {line}" for n, line in self.seen)

    def stop(self) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
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


def mean_rgb(png: Path) -> np.ndarray:
    from PIL import Image

    with Image.open(png) as im:
        return np.asarray(im.convert("RGB"), np.float64).reshape(-1, 3).mean(0)


def test_demo_watch_reloads_a_rewritten_pack_and_keeps_the_old_one_for_a_corrupt_one(tmp_path):
    """`demo --watch --headless`: a pack the cooker rewrites is shown from the next frame (the
    screenshot after `reloaded` has the new colour); a corrupt pack put in its place is refused
    with its error and the demo goes on with the old scene; validation clean throughout."""
    assert DEMO.exists(), f"{DEMO} is built by `make build` (a prerequisite of `make test`)"
    level, pack, shot = tmp_path / "level.toml", tmp_path / "level.pack", tmp_path / "shot.png"

    def cook(color: str) -> None:
        level.write_text(LEVEL.format(color=color))
        r = subprocess.run([str(COOK), "level.toml", "-o", "level.pack", "--quality", "draft", "-q"], cwd=tmp_path, capture_output=True,
                           text=True, timeout=STEP_TIMEOUT_S)
        assert r.returncode == 0, r.stderr

    cook("[0.9, 0.1, 0.1]")
    demo = Watcher(cwd=tmp_path, command=[str(DEMO), "level.pack", "--headless", "--watch", "--validation", "--flight", "0",
                                          "--width", "320", "--height", "180", "--screenshot", str(shot)])
    try:
        demo.expect("watching level.pack")
        red = mean_rgb(shot)
        cook("[0.1, 0.1, 0.9]")
        demo.expect("reloaded level.pack")
        demo.expect(f"wrote {shot}")
        blue = mean_rgb(shot)
        assert blue[2] - red[2] > 2.0 and red[0] - blue[0] > 2.0, (red, blue)

        # A corrupt pack, put in place whole (as a cook writes): refused, the old scene stays.
        corrupt = tmp_path / ".level.pack.tmp"
        corrupt.write_bytes(b"GAMEPACK" + bytes(200))
        os.replace(corrupt, pack)
        error = demo.expect("demo: error: level.pack", stream="err")
        assert error.endswith("still showing the last good pack"), error
        assert demo.proc.poll() is None, demo.transcript()
        cook("[0.1, 0.9, 0.1]")
        demo.expect("reloaded level.pack")
        demo.expect(f"wrote {shot}")
        green = mean_rgb(shot)
        assert green[1] - blue[1] > 2.0, (blue, green)
    finally:
        code = demo.stop()
    assert code == 0, demo.transcript()
    demo.expect("validation errors: 0")
    assert not [line for n, line in demo.seen if n == "err" and "validation" in line.lower()], demo.transcript()


def test_demo_watch_recompiles_an_edited_shader_and_keeps_the_pipelines_on_a_broken_one(tmp_path):
    """`demo --watch --headless` with shader sources (ENGINE_SHADERS, a copy of shaders/): an
    edited shader is compiled again and drawn with from the next frame; one that does not compile
    prints glslc's error and the frames go on with the pipelines they had; validation clean."""
    assert DEMO.exists(), f"{DEMO} is built by `make build` (a prerequisite of `make test`)"
    shaders = tmp_path / "shaders"
    shutil.copytree(REPO / "shaders", shaders)
    (tmp_path / "level.toml").write_text(LEVEL.format(color="[0.5, 0.5, 0.5]"))
    r = subprocess.run([str(COOK), "level.toml", "-o", "level.pack", "--quality", "draft", "-q"], cwd=tmp_path, capture_output=True, text=True,
                       timeout=STEP_TIMEOUT_S)
    assert r.returncode == 0, r.stderr
    shot = tmp_path / "shot.png"
    demo = Watcher(cwd=tmp_path, command=[str(DEMO), "level.pack", "--headless", "--watch", "--validation", "--flight", "0", "--render-scale", "1",
                                          "--width", "320", "--height", "180", "--screenshot", str(shot)],
                   env={**os.environ, "ENGINE_SHADERS": str(shaders)})
    tonemap = shaders / "tonemap.frag"
    original = tonemap.read_text()
    try:
        demo.expect(f"watching level.pack and the shaders in {shaders}")
        before = mean_rgb(shot)
        # Every pixel the tone map writes made pure red.
        tonemap.write_text(original.replace("out_color = encoded(", "out_color = vec4(1.0, 0.0, 0.0, 1.0) + 0.0 * encoded("))
        assert "tonemap.frag.spv" in demo.expect("reloaded shaders (")
        demo.expect(f"wrote {shot}")
        red = mean_rgb(shot)
        assert red[0] > 250 and red[1] < 5 and red[2] < 5, (before, red)

        tonemap.write_text(original + "\nthis is not GLSL\n")
        error = demo.expect("demo: shader error:", stream="err")
        assert "tonemap.frag" in error, error
        demo.expect("demo: the pipelines are as they were", stream="err")
        assert demo.proc.poll() is None, demo.transcript()

        tonemap.write_text(original)
        demo.expect("reloaded shaders (")
        demo.expect(f"wrote {shot}")
        assert np.abs(mean_rgb(shot) - before).max() < 1.0, (before, mean_rgb(shot))
    finally:
        code = demo.stop()
    assert code == 0, demo.transcript()
    demo.expect("validation errors: 0")
