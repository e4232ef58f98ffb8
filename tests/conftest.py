"""Fixtures shared by the end-to-end tests."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
COOK = REPO / ".venv" / "bin" / "cook"
DEMO = REPO / "target" / "release" / "demo"

# A suite started in the background by a non-interactive shell (`make test &`, nohup) inherits
# SIGINT ignored, and so would every process it starts: Python then installs no Ctrl-C handler, so
# a cook could not be interrupted and the Ctrl-C test failed for the way the suite was started
# (issue 27's first stress run). With a handler here, exec gives the tests' processes SIGINT's
# default, as a terminal would.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


def run_bounded(args, timeout: float, *, env=None, cwd=None, input=None) -> subprocess.CompletedProcess:
    """subprocess.run(args, capture_output=True, text=True, timeout=timeout), except that a process
    still running at its timeout fails the test with where it was stuck: every thread's native
    stack (gdb, where installed) and, for a Python program, every thread's Python stack
    (faulthandler, on the SIGABRT that ends it). A hang seen once in many runs is then found from
    that one failure, not guessed at."""
    args = [str(a) for a in args]
    env = {**(os.environ if env is None else env), "PYTHONFAULTHANDLER": "1"}
    with subprocess.Popen(args, stdin=subprocess.PIPE if input is not None else subprocess.DEVNULL, stdout=subprocess.PIPE,
                          stderr=subprocess.PIPE, text=True, env=env, cwd=cwd) as proc:
        try:
            out, err = proc.communicate(input, timeout=timeout)
        except subprocess.TimeoutExpired:
            native = _native_stacks(proc.pid)
            proc.send_signal(signal.SIGABRT)
            try:
                out, err = proc.communicate(timeout=60)
            except subprocess.TimeoutExpired:
                proc.kill()
                out, err = proc.communicate()
            pytest.fail(f"{Path(args[0]).name} still ran after {timeout} s, stopped with SIGABRT: {' '.join(args)}\n"
                        f"--- its stderr (Python's stacks at the end) ---\n{err[-30000:]}\n--- native stacks ---\n{native}", pytrace=False)
    return subprocess.CompletedProcess(args, proc.returncode, out, err)


def _native_stacks(pid: int) -> str:
    gdb = shutil.which("gdb")
    if gdb is None:
        return "(gdb is not installed)"
    try:
        r = subprocess.run([gdb, "-p", str(pid), "-batch", "-nx", "-ex", "thread apply all bt"], capture_output=True, text=True, timeout=120)
        return r.stdout[-30000:] + r.stderr[-2000:]
    except subprocess.TimeoutExpired:
        return "(gdb did not finish in 120 s)"


def gltf_samples_path() -> Path:
    """Where the Khronos sample models live: $GLTF_SAMPLES_DIR, else <repo>/../shared/gltf-samples."""
    return Path(os.environ.get("GLTF_SAMPLES_DIR") or REPO.parent / "shared" / "gltf-samples")


@pytest.fixture(scope="session")
def gltf_samples() -> Path:
    d = gltf_samples_path()
    if not d.is_dir():
        pytest.skip(f"glTF samples not found at {d} (set GLTF_SAMPLES_DIR to run these tests)")
    return d


@pytest.fixture
def run_cook():
    """Run the installed `cook` console script: run_cook(*args) -> CompletedProcess (text)."""
    if not COOK.exists():
        pytest.fail(f"{COOK} is missing: build and install the cooker first "
                    "(VIRTUAL_ENV=$PWD/.venv .venv/bin/maturin develop --release -m asset_pipeline/Cargo.toml)")

    def run(*args: object, **kwargs) -> subprocess.CompletedProcess:
        return run_bounded([COOK, *args], 300, **kwargs)

    return run


def run_demo(args, timeout=300, env=None) -> subprocess.CompletedProcess:
    """Run the built `demo` binary (text output captured)."""
    assert DEMO.exists(), f"{DEMO} is built by `make build` (a prerequisite of `make test`)"
    return run_bounded([DEMO, *args], timeout, env=env)


def cook_ok(source: Path, out: Path, *args: str) -> None:
    """Cook `source` to `out` with the CLI (and `args`) and require success."""
    result = run_bounded([COOK, source, "-o", out, *args], 300)
    assert result.returncode == 0, f"cook {source} failed ({result.returncode}):\n{result.stderr}"
    assert out.exists()


@pytest.fixture(scope="session")
def demo_level_uv2():
    """The demo level's static meshes with lightmap UVs, computed once per test session:
    (static meshes, their LODs placed on the atlas, LightmapLayout, stats, Uv2Settings)."""
    from asset_pipeline import uv2
    from asset_pipeline.csg import build_level
    from asset_pipeline.level import load_level

    level_path = REPO / "content" / "levels" / "temple.toml"
    level = load_level(level_path)
    scene = build_level(level)
    static = [scene.meshes[i] for i in scene.static_meshes()]
    settings = uv2.Uv2Settings(texels_per_metre=float(level.texels_per_metre))
    r = uv2.lightmap_uvs([(m.base, 1.0, m.texels_per_metre) for m in static], settings, names=[m.name for m in static])
    return static, r.placed, r.layout, r.stats, settings


# ---- temporary files -------------------------------------------------------------------------
# pytest.ini has pytest remove a passing test's tmp_path; the fixture below does the same for what
# a module made with tmp_path_factory, once the module ends. The run's summary says how much the
# tests wrote and the most the run held at once (what a CI machine's disk must have room for).

def _tree_bytes(path: Path) -> int:
    total = 0
    for root, _dirs, files in os.walk(path):
        for f in files:
            try:
                total += os.lstat(os.path.join(root, f)).st_size
            except OSError:
                pass
    return total


_TEMP = {"written": 0, "peak": 0}


@pytest.fixture(autouse=True, scope="module")
def _module_temporaries(request, tmp_path_factory):
    """Remove the directories this module's fixtures made under the session's base temporary
    directory when the module ends, unless one of its tests failed (then they stay, with the
    failing test's own, for inspection)."""
    base = tmp_path_factory.getbasetemp()
    before = set(base.iterdir())
    failed = request.session.testsfailed
    yield
    made = set(base.iterdir()) - before
    _TEMP["written"] += sum(_tree_bytes(p) for p in made)
    if request.session.testsfailed == failed:
        for p in made:
            shutil.rmtree(p, ignore_errors=True)


@pytest.hookimpl(wrapper=True)
def pytest_runtest_call(item):
    # After the test body, before its fixtures are torn down: what the run holds now.
    try:
        return (yield)
    finally:
        factory = getattr(item.config, "_tmp_path_factory", None)
        base = getattr(factory, "_basetemp", None)
        if base is not None and base.is_dir():
            _TEMP["peak"] = max(_TEMP["peak"], _tree_bytes(base))
            own = item.funcargs.get("tmp_path") if hasattr(item, "funcargs") else None
            if isinstance(own, Path) and own.is_dir():
                _TEMP["written"] += _tree_bytes(own)


def pytest_terminal_summary(terminalreporter):
    if _TEMP["peak"]:
        terminalreporter.write_line(f"temporary files: tests' own directories wrote {_TEMP['written'] / 1e6:.0f} MB "
                                    f"(module fixtures' included); the most held at once {_TEMP['peak'] / 1e6:.0f} MB")
