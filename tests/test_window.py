"""`demo` in a real X window (Xvfb), presenting through a Vulkan swapchain on lavapipe.

The test starts its own Xvfb, waits until demo has presented frames, takes a screenshot of the
X screen with ImageMagick's `import` (as a person would), and compares it with the headless
render of the same pack at the same size: the window must show the same scene.
"""

import os
import queue
import shutil
import signal
import subprocess
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from conftest import DEMO, REPO

WIDTH, HEIGHT = 640, 360


class DemoLog:
    """demo's stdout lines as they come and its stderr, each read by a thread of its own: a wait
    for a line ends at its deadline even when demo prints nothing, and demo never blocks on a
    full stderr pipe that nobody reads (validation warnings go there)."""

    def __init__(self, proc: subprocess.Popen):
        self.proc = proc
        self.lines: list[str] = []
        self.err: list[str] = []
        self._queue: queue.Queue = queue.Queue()
        self._threads = [threading.Thread(target=self._pump, args=(proc.stdout, self._queue.put, None), daemon=True),
                         threading.Thread(target=self._pump, args=(proc.stderr, self.err.append, ""), daemon=True)]
        for t in self._threads:
            t.start()

    @staticmethod
    def _pump(stream, put, end):
        """Every line of `stream`, then `end` (None marks the end of stdout's queue)."""
        for line in stream:
            put(line)
        put(end)

    def wait_for(self, text: str, timeout: float) -> None:
        """Until a line containing `text` has been printed (fails at `timeout` seconds, or when
        demo exits first, with what it printed)."""
        self.wait_for_count(text, 1, timeout)

    def wait_for_count(self, text: str, count: int, timeout: float) -> None:
        """Until `count` lines containing `text` have been printed (as `wait_for`)."""
        deadline = time.monotonic() + timeout
        while sum(text in line for line in self.lines) < count:
            try:
                line = self._queue.get(timeout=max(0.0, deadline - time.monotonic()))
            except queue.Empty:
                raise AssertionError(f"not {count} '{text}' lines within {timeout} s:\n{''.join(self.lines)}\n{''.join(self.err[-40:])}") from None
            assert line is not None, f"demo exited ({self.proc.wait(timeout=60)}) before '{text}':\n{''.join(self.lines)}\n{''.join(self.err)}"
            self.lines.append(line)

    def wait_for_err(self, text: str, timeout: float) -> None:
        """Until stderr has a line containing `text` (its reader thread appends them)."""
        deadline = time.monotonic() + timeout
        while not any(text in line for line in self.err):
            assert self.proc.poll() is None, f"demo exited before '{text}' on stderr:\n{''.join(self.err)}"
            assert time.monotonic() < deadline, f"no '{text}' on stderr within {timeout} s:\n{''.join(self.err[-40:])}"
            time.sleep(0.05)

    def finish(self, timeout: float = 60) -> tuple[str, str]:
        """demo's whole stdout and stderr once it has exited."""
        self.proc.wait(timeout=timeout)
        for t in self._threads:  # each ends at its pipe's end, after demo's last line
            t.join(timeout=timeout)
        while (line := self._queue.get(timeout=timeout)) is not None:
            self.lines.append(line)
        return "".join(self.lines), "".join(self.err)


def free_display() -> int:
    for n in range(90, 200):
        if not Path(f"/tmp/.X11-unix/X{n}").exists() and not Path(f"/tmp/.X{n}-lock").exists():
            return n
    raise RuntimeError("no free X display number")


@pytest.fixture
def xvfb():
    for tool in ("Xvfb", "import"):
        assert shutil.which(tool), f"{tool} is installed by `make setup` (xvfb, imagemagick)"
    n = free_display()
    # -r: no key auto-repeat. A loaded machine can hold xdotool between a key's press and release
    # past the 660 ms repeat delay; the server then sent a second press, and F5 turned the
    # lightmaps off and at once on again (a fresh-clone CI run saw "lightmaps off", "lightmaps
    # on" from one key). The tests press keys; they never mean to hold them.
    proc = subprocess.Popen(["Xvfb", f":{n}", "-screen", "0", f"{WIDTH}x{HEIGHT}x24", "-nolisten", "tcp", "-r"], stderr=subprocess.DEVNULL)
    deadline = time.time() + 20
    while not Path(f"/tmp/.X11-unix/X{n}").exists():
        assert proc.poll() is None, "Xvfb exited at start-up"
        assert time.time() < deadline, "Xvfb did not start within 20 s"
        time.sleep(0.1)
    yield f":{n}"
    proc.terminate()
    proc.wait(timeout=10)


def window_screenshot(xvfb, tmp_path, *extra_args, env_extra=None, ready="presented 10 frames"):
    """Run demo in the window on `xvfb` until it has printed `ready` (presented frames),
    screenshot the X screen, close it with SIGTERM; the screenshot as an RGB int16 array and
    demo's stdout, after checking a clean exit."""
    pack = REPO / "build" / "temple.pack"
    assert pack.exists(), "build/temple.pack is made by `make cook`"
    env = {**os.environ, "DISPLAY": xvfb, "ENGINE_VALIDATION": "1", **(env_extra or {})}
    env.pop("WAYLAND_DISPLAY", None)
    demo = subprocess.Popen(
        [str(DEMO), str(pack), "--width", str(WIDTH), "--height", str(HEIGHT), "--render-scale", "1", *extra_args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    log = DemoLog(demo)
    try:
        log.wait_for(ready, timeout=120)
        assert any(l.startswith("window:") for l in log.lines), "demo fell back to headless instead of opening a window"
        shot = tmp_path / "window.png"
        subprocess.run(["import", "-display", xvfb, "-window", "root", str(shot)], check=True, timeout=60)
    finally:
        demo.send_signal(signal.SIGTERM)  # closes the window cleanly (validation verdict, teardown)
        out, err = log.finish()
    assert demo.returncode == 0, f"demo exit {demo.returncode}:\n{out}\n{err}"
    assert "validation errors: 0" in out, out
    assert "[vulkan validation error]" not in err, err
    return np.asarray(Image.open(shot).convert("RGB"), dtype=np.int16), out


def headless_render(tmp_path):
    pack = REPO / "build" / "temple.pack"
    headless = tmp_path / "headless.png"
    result = subprocess.run(
        [str(DEMO), str(pack), "--headless", "--frames", "1", "--width", str(WIDTH), "--height", str(HEIGHT), "--render-scale", "1", "--screenshot", str(headless)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stderr
    return np.asarray(Image.open(headless).convert("RGB"), dtype=np.int16)


def test_demo_window_shows_the_scene(xvfb, tmp_path):
    window, _ = window_screenshot(xvfb, tmp_path)
    offscreen = headless_render(tmp_path)
    assert window.shape == offscreen.shape, f"screenshot {window.shape} vs render {offscreen.shape}"
    diff = np.abs(window - offscreen).max(axis=-1)
    # The static scene must match. The window advances the golems, particles and doves by wall-clock
    # time and the headless render by fixed 1/60 s steps, so the moving things (about 1% of the
    # frame) can sit elsewhere; a window that showed the wrong scene would differ almost everywhere.
    assert (diff > 3).mean() < 0.03, f"the window does not show the scene: {(diff > 3).mean():.1%} of pixels differ"
    # And it is a scene, not a blank screen.
    assert len({tuple(p // 16) for p in window.reshape(-1, 3)}) > 20


def test_demo_window_draws_the_overlay_over_the_scene(xvfb, tmp_path):
    # The overlay window sits at the top left (about 450 px wide): under it the scene is covered,
    # to its right the frame is the same as without it. Validation stays clean throughout.
    window, _ = window_screenshot(xvfb, tmp_path, "--overlay")
    offscreen = headless_render(tmp_path)
    diff = np.abs(window - offscreen).max(axis=-1) > 3
    assert diff[20:HEIGHT - 20, 20:400].mean() > 0.9, f"only {diff[20:HEIGHT - 20, 20:400].mean():.1%} of the overlay's area changed"
    assert diff[:, 480:].mean() < 0.01, f"{diff[:, 480:].mean():.1%} of the pixels right of the overlay changed"


def test_the_window_survives_a_lost_device(xvfb, tmp_path):
    # The 30th frame's submit reports a lost device: the window makes the device, its surface
    # and swapchain, the renderer and the scene again and goes on showing the scene (the same
    # picture as a headless render, but for the moving characters and birds); validation stays
    # clean over both devices and the window closes cleanly.
    window, out = window_screenshot(xvfb, tmp_path, env_extra={"ENGINE_INJECT_DEVICE_LOST": "30"}, ready="window: device made again shown")
    assert "window: device lost at frame 30 (the GPU was lost (injected by ENGINE_INJECT_DEVICE_LOST)" in out, out
    offscreen = headless_render(tmp_path)
    diff = np.abs(window - offscreen).max(axis=-1)
    assert (diff > 3).mean() < 0.03, f"after the loss the window does not show the scene: {(diff > 3).mean():.1%} of pixels differ"


class DemoWindow:
    """`demo` on an Xvfb display, driven by synthetic X input (xdotool, through XTEST: the
    events reach the window as a person's would). `wait_for` reads demo's log lines."""

    def __init__(self, display: str, *packs: Path):
        assert shutil.which("xdotool"), "xdotool is installed by `make setup`"
        self.display = display
        self.env = {**os.environ, "DISPLAY": display, "ENGINE_VALIDATION": "1"}
        self.env.pop("WAYLAND_DISPLAY", None)
        self.proc = subprocess.Popen([str(DEMO), *map(str, packs), "--width", str(WIDTH), "--height", str(HEIGHT)],
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=self.env)
        self.demo_log = DemoLog(self.proc)
        self.log = self.demo_log.lines

    def wait_for(self, text: str, timeout: float = 120.0):
        self.demo_log.wait_for(text, timeout)

    def xdotool(self, *args):
        subprocess.run(["xdotool", *map(str, args)], check=True, timeout=30, env=self.env)

    def focus(self):
        """Give the window the keyboard focus: there is no window manager to do it on a click."""
        found = subprocess.run(["xdotool", "search", "--name", "^demo - "], capture_output=True, text=True, timeout=30, env=self.env)
        assert found.returncode == 0 and found.stdout.split(), f"no demo window on {self.display}: {found.stderr}"
        self.xdotool("windowfocus", "--sync", found.stdout.split()[0])

    def key(self, name: str, then: str):
        """Press key `name` in the window, wait for demo to log `then`, then for its log that the
        change is on screen (the frames after the first one recorded with it were presented):
        synchronised on frames, not on time, however slowly the machine renders."""
        self.focus()
        self.xdotool("key", name)
        self.wait_for(then, timeout=60)
        self.wait_for(f"{then} shown", timeout=120)

    def screenshot(self, path: Path) -> np.ndarray:
        subprocess.run(["import", "-display", self.display, "-window", "root", str(path)], check=True, timeout=60)
        return np.asarray(Image.open(path).convert("RGB"), dtype=np.int16)

    def screenshot_until(self, path: Path, done, timeout: float = 60.0) -> np.ndarray:
        """Screenshots until `done(image)` holds or `timeout` passes; the last one. On a loaded
        machine a change can take seconds to reach the screen (lavapipe renders a few frames a
        second then), so a fixed wait would catch the frame before it."""
        end = time.monotonic() + timeout
        while True:
            image = self.screenshot(path)
            if done(image) or time.monotonic() > end:
                return image
            time.sleep(0.5)

    def close(self):
        """Close the window (SIGTERM, unless it is already closing) and check a clean exit with no
        validation message."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        out, err = self.demo_log.finish()
        assert self.proc.returncode == 0, f"demo exit {self.proc.returncode}:\n{out}\n{err}"
        assert "validation errors: 0" in out and "[vulkan validation" not in err, out + err

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(timeout=60)


def changed(a: np.ndarray, b: np.ndarray) -> float:
    """Fraction of pixels that differ by more than 3 steps in some channel."""
    return float((np.abs(a - b).max(axis=-1) > 3).mean())


def test_keys_and_mouse_drive_the_demo_window(xvfb, tmp_path):
    # The player's input, synthesised: F5 turns the lightmaps off (probes and sun light the
    # static level instead: most of the frame changes) and on again (back to the first image, but
    # for the moving characters, particles and birds); a drag with the left button turns the
    # view; Tab switches to the second pack; Escape quits cleanly with validation clean.
    temple, second = REPO / "build" / "temple.pack", REPO / "build" / "demo.pack"
    assert temple.exists() and second.exists(), "build/temple.pack and build/demo.pack are made by `make cook`"
    with DemoWindow(xvfb, temple, second) as w:
        w.wait_for("presented 10 frames")
        lit = w.screenshot(tmp_path / "lit.png")
        w.key("F5", "window: lightmaps off")
        unlit = w.screenshot_until(tmp_path / "unlit.png", lambda im: changed(lit, im) > 0.15)
        w.key("F5", "window: lightmaps on")
        relit = w.screenshot_until(tmp_path / "relit.png", lambda im: changed(lit, im) < 0.07)
        w.xdotool("mousemove", WIDTH // 2, HEIGHT // 2)
        w.xdotool("mousedown", 1)
        # The view turns by the pointer's whole travel while the button is down, however the
        # moves are spaced: no pauses between them.
        for step in range(1, 9):
            w.xdotool("mousemove", WIDTH // 2 + 20 * step, HEIGHT // 2)
        w.xdotool("mouseup", 1)
        turned = w.screenshot_until(tmp_path / "turned.png", lambda im: changed(relit, im) > 0.5)
        w.key("Tab", "window: scene 2 of 2")
        other = w.screenshot_until(tmp_path / "other.png", lambda im: changed(turned, im) > 0.5)
        # The other switches, each rendered with for a moment (validation checks every frame).
        for key, switch in [("F2", "depth pre-pass"), ("F3", "frustum culling"), ("F4", "LOD selection"), ("F6", "walk mode")]:
            first, second = ("on", "off") if key == "F6" else ("off", "on")
            w.key(key, f"window: {switch} {first}")
            w.key(key, f"window: {switch} {second}")
        w.focus()
        w.xdotool("key", "Escape")
        w.close()
    print(f"changed: lightmaps off {changed(lit, unlit):.1%}, on again {changed(lit, relit):.1%}, "
          f"turned {changed(relit, turned):.1%}, next scene {changed(turned, other):.1%}")
    # Without lightmaps the static level loses its baked shadows and bounce light (the probes'
    # smooth light remains): 58% of this view changes with irradiance lightmaps, 29% with the
    # default directional ones (their sun is lit at run time, with its shadow map, either way), so
    # 15% holds for both. The moving golem and birds alone change a few per cent between any two
    # screenshots.
    assert changed(lit, unlit) > 0.15, "turning the lightmaps off left the frame as it was"
    assert changed(lit, relit) < 0.07, "turning them on again did not bring the lit frame back"
    assert changed(lit, unlit) > 3 * changed(lit, relit)
    assert changed(relit, turned) > 0.5, "dragging with the mouse did not turn the view"
    assert changed(turned, other) > 0.5, "Tab did not switch the scene"


def test_resizing_hiding_and_showing_the_window_keep_it_rendering(xvfb, tmp_path):
    # A resize rebuilds the swapchain at the new size (the old one is out of date, which must not
    # be fatal) and the scene fills the new size; an unmapped (hidden, as minimised) window and
    # its return keep the demo running; validation stays clean throughout.
    with DemoWindow(xvfb, REPO / "build" / "temple.pack") as w:
        w.wait_for("presented 10 frames")
        w.focus()
        window_id = subprocess.run(["xdotool", "getwindowfocus"], capture_output=True, text=True, timeout=30, env=w.env).stdout.strip()
        w.xdotool("windowsize", "--sync", window_id, 400, 240)
        # "... shown": the frames after the rebuild have been presented at the new size.
        w.wait_for("window: swapchain rebuilt at 400x240 shown", timeout=60)
        small = w.screenshot(tmp_path / "small.png")
        w.xdotool("windowunmap", "--sync", window_id)
        # Hidden for a while (a duration under test, not a wait for something to happen).
        time.sleep(1.0)
        w.xdotool("windowmap", "--sync", window_id)
        # A start-up resize may have printed this size's line already: wait for one more.
        full_size = f"window: swapchain rebuilt at {WIDTH}x{HEIGHT} shown"
        seen = sum(full_size in line for line in w.log)
        w.xdotool("windowsize", "--sync", window_id, WIDTH, HEIGHT)
        w.demo_log.wait_for_count(full_size, seen + 1, timeout=60)
        full = w.screenshot(tmp_path / "full.png")
        w.close()
    colours = lambda img: len({tuple(p // 16) for p in img.reshape(-1, 3)})
    # The small window shows the scene in its 400x240 corner of the screen; the rest is the bare root.
    root = small[-1, -1]
    assert colours(small[:240, :400]) > 20 and (small[:, 420:] == root).all() and (small[260:, :] == root).all()
    # Back at full size, the scene covers the whole screen again.
    uncovered = (full == root).all(axis=-1).mean()
    assert uncovered < 0.01 and colours(full[:, 420:]) > 20, f"the window did not render again at full size ({uncovered:.1%} bare)"


def test_the_window_reloads_a_rewritten_pack_under_watch(xvfb, tmp_path):
    """`demo --watch` in the window: a pack rewritten by the cooker is shown (`reloaded`), a
    corrupt one is refused with its error while the window goes on, validation clean."""
    from conftest import COOK
    from test_watch import LEVEL

    level = tmp_path / "level.toml"

    def cook(color: str) -> None:
        level.write_text(LEVEL.format(color=color))
        r = subprocess.run([str(COOK), "level.toml", "-o", "level.pack", "--quality", "draft", "-q"], cwd=tmp_path, capture_output=True,
                           text=True, timeout=300)
        assert r.returncode == 0, r.stderr

    cook("[0.9, 0.1, 0.1]")
    env = {**os.environ, "DISPLAY": xvfb, "ENGINE_VALIDATION": "1"}
    env.pop("WAYLAND_DISPLAY", None)
    demo = subprocess.Popen([str(DEMO), "level.pack", "--watch", "--width", str(WIDTH), "--height", str(HEIGHT)], cwd=tmp_path,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    log = DemoLog(demo)
    try:
        log.wait_for("presented 10 frames", timeout=120)
        assert any(l.startswith("window:") for l in log.lines), "demo fell back to headless instead of opening a window"
        cook("[0.1, 0.1, 0.9]")
        log.wait_for("reloaded level.pack", timeout=120)
        corrupt = tmp_path / ".level.pack.tmp"
        corrupt.write_bytes(b"not a pack")
        os.replace(corrupt, tmp_path / "level.pack")
        log.wait_for_err("still showing the last good pack", timeout=120)
        cook("[0.1, 0.9, 0.1]")
        log.wait_for_count("reloaded level.pack", 2, timeout=120)
    finally:
        demo.send_signal(signal.SIGTERM)
        out, err = log.finish()
    assert demo.returncode == 0, f"demo exit {demo.returncode}:\n{out}\n{err}"
    assert "validation errors: 0" in out, out
    assert "[vulkan validation error]" not in err, err
