"""Determinism: the same inputs and seed give byte-identical packs (and lightmap EXRs) across
separate runs, thread counts (the bake's --threads and rayon's pool for the Rust core) and Python
hash seeds (so no set or dict order leaks into the bytes), each run with an empty cache so every
stage really runs. A level (CSG, lightmap UVs, a draft bake, procedural textures with mips) and a
generated glTF scene (content/demo/make_scene.py: meshes, PNG textures, LODs) are cooked.

Executors: `--executor ray` against `--executor local` is covered by tests/test_ray.py
(test_demo_level_on_ray_is_byte_identical_to_local, pack and EXR pages, and the same again with
a worker killed mid-bake), which starts a loopback Ray cluster; it is not repeated here.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import COOK, REPO, run_bounded
from test_atomic import LEVEL

RUNS = {
    "default": {"PYTHONHASHSEED": "0"},
    "one-thread": {"RAYON_NUM_THREADS": "1", "PYTHONHASHSEED": "1", "_args": ("--threads", "1")},
    "two-threads": {"RAYON_NUM_THREADS": "2", "PYTHONHASHSEED": "2", "_args": ("--threads", "2")},
}


def cook_outputs(src: Path, out: Path, run: dict, seed: int = 7) -> dict[str, bytes]:
    """Cook `src` into `out` in a fresh process with an empty cache; the pack and EXR bytes."""
    out.parent.mkdir(parents=True)
    env = {**os.environ, "OMP_NUM_THREADS": "1", **{k: v for k, v in run.items() if not k.startswith("_")}}
    args = [str(COOK), str(src), "-o", str(out), "-q", "--quality", "draft", "--seed", str(seed), "--cache", str(out.parent / "cache"),
            *run.get("_args", ())]
    r = run_bounded(args, 300, env=env)
    assert r.returncode == 0, r.stderr
    return {p.name: p.read_bytes() for p in sorted(out.parent.iterdir()) if p.suffix in (".pack", ".exr")}


@pytest.fixture(scope="module")
def sources(tmp_path_factory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("sources")
    level = d / "level.toml"
    level.write_text(LEVEL)
    scene = d / "scene.gltf"
    subprocess.run([sys.executable, str(REPO / "content" / "demo" / "make_scene.py"), str(scene)], check=True, capture_output=True, timeout=120)
    return {"level": level, "scene": scene}


@pytest.mark.parametrize("kind", ["level", "scene"])
def test_same_inputs_and_seed_give_identical_bytes_across_runs_and_threads(kind, sources, tmp_path):
    src = sources[kind]
    outputs = {name: cook_outputs(src, tmp_path / name / "x.pack", run) for name, run in RUNS.items()}
    reference = outputs["default"]
    assert "x.pack" in reference
    if kind == "level":
        assert "x.lightmap0.exr" in reference, sorted(reference)
    for name, got in outputs.items():
        assert sorted(got) == sorted(reference), name
        for f in reference:
            assert got[f] == reference[f], f"{kind}: {f} differs between the default run and {name}"


def test_the_seed_changes_the_bake(sources, tmp_path):
    """The other side of the coin: the seed is an input, so another seed gives other lightmaps."""
    a = cook_outputs(sources["level"], tmp_path / "a" / "x.pack", RUNS["default"], seed=7)
    b = cook_outputs(sources["level"], tmp_path / "b" / "x.pack", RUNS["default"], seed=8)
    assert a["x.lightmap0.exr"] != b["x.lightmap0.exr"]
