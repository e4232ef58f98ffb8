"""`demo` in a real X window (Xvfb), presenting through a Vulkan swapchain on lavapipe.

The test starts its own Xvfb, waits until demo has presented frames, takes a screenshot of the
X screen with ImageMagick's `import` (as a person would), and compares it with the headless
render of the same pack at the same size: the window must show the same scene.
"""

import os
import shutil
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from conftest import DEMO, REPO

WIDTH, HEIGHT = 640, 360


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
    proc = subprocess.Popen(["Xvfb", f":{n}", "-screen", "0", f"{WIDTH}x{HEIGHT}x24", "-nolisten", "tcp"], stderr=subprocess.DEVNULL)
    deadline = time.time() + 20
    while not Path(f"/tmp/.X11-unix/X{n}").exists():
        assert proc.poll() is None, "Xvfb exited at start-up"
        assert time.time() < deadline, "Xvfb did not start within 20 s"
        time.sleep(0.1)
    yield f":{n}"
    proc.terminate()
    proc.wait(timeout=10)


def window_screenshot(xvfb, tmp_path, *extra_args):
    """Run demo in the window on `xvfb` until it has presented frames, screenshot the X screen,
    close it with SIGTERM; the screenshot as an RGB int16 array, after checking a clean exit."""
    pack = REPO / "build" / "temple.pack"
    assert pack.exists(), "build/temple.pack is made by `make cook`"
    env = {**os.environ, "DISPLAY": xvfb, "ENGINE_VALIDATION": "1"}
    env.pop("WAYLAND_DISPLAY", None)
    demo = subprocess.Popen(
        [str(DEMO), str(pack), "--width", str(WIDTH), "--height", str(HEIGHT), *extra_args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    try:
        lines = []
        deadline = time.time() + 120
        while True:
            line = demo.stdout.readline()
            assert line or demo.poll() is None, f"demo exited early ({demo.returncode}):\n{''.join(lines)}\n{demo.stderr.read()}"
            lines.append(line)
            if "presented 10 frames" in line:
                break
            assert time.time() < deadline, f"no frames presented within 120 s:\n{''.join(lines)}"
        assert any(l.startswith("window:") for l in lines), "demo fell back to headless instead of opening a window"
        shot = tmp_path / "window.png"
        subprocess.run(["import", "-display", xvfb, "-window", "root", str(shot)], check=True, timeout=60)
    finally:
        demo.send_signal(signal.SIGTERM)  # closes the window cleanly (validation verdict, teardown)
        out, err = demo.communicate(timeout=60)
    assert demo.returncode == 0, f"demo exit {demo.returncode}:\n{out}\n{err}"
    assert "validation errors: 0" in out, out
    assert "[vulkan validation error]" not in err, err
    return np.asarray(Image.open(shot).convert("RGB"), dtype=np.int16)


def headless_render(tmp_path):
    pack = REPO / "build" / "temple.pack"
    headless = tmp_path / "headless.png"
    result = subprocess.run(
        [str(DEMO), str(pack), "--headless", "--frames", "1", "--width", str(WIDTH), "--height", str(HEIGHT), "--screenshot", str(headless)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stderr
    return np.asarray(Image.open(headless).convert("RGB"), dtype=np.int16)


def test_demo_window_shows_the_scene(xvfb, tmp_path):
    window = window_screenshot(xvfb, tmp_path)
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
    window = window_screenshot(xvfb, tmp_path, "--overlay")
    offscreen = headless_render(tmp_path)
    diff = np.abs(window - offscreen).max(axis=-1) > 3
    assert diff[20:HEIGHT - 20, 20:400].mean() > 0.9, f"only {diff[20:HEIGHT - 20, 20:400].mean():.1%} of the overlay's area changed"
    assert diff[:, 480:].mean() < 0.01, f"{diff[:, 480:].mean():.1%} of the pixels right of the overlay changed"
