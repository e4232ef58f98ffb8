"""Fixtures shared by the end-to-end tests."""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
COOK = REPO / ".venv" / "bin" / "cook"
DEMO = REPO / "target" / "release" / "demo"


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
        return subprocess.run([str(COOK), *map(str, args)], capture_output=True, text=True, timeout=300, **kwargs)

    return run


def run_demo(args, timeout=300, env=None) -> subprocess.CompletedProcess:
    """Run the built `demo` binary (text output captured)."""
    assert DEMO.exists(), f"{DEMO} is built by `make build` (a prerequisite of `make test`)"
    return subprocess.run([str(DEMO), *map(str, args)], capture_output=True, text=True, timeout=timeout, env=env)


def cook_ok(source: Path, out: Path, *args: str) -> None:
    """Cook `source` to `out` with the CLI (and `args`) and require success."""
    result = subprocess.run([str(COOK), str(source), "-o", str(out), *args], capture_output=True, text=True, timeout=300)
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
