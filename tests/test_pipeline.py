"""Incremental cooking: stage caching by content hash, up-to-date detection, --force, reports.

These pin exact facts (which stages ran, which came from the cache, which files changed), not
times: speed is measured by benchmarks, not tests.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

import asset_pipeline
from asset_pipeline.cook import cook_detailed
from asset_pipeline.bake import BakeSettings
from asset_pipeline.pipeline import CookSettings

# These tests are about the pipeline, not light: the smallest bake that still runs every step.
QUICK_BAKE = BakeSettings(preset="draft", samples=1, probe_samples=4)
QUICK = CookSettings(bake=QUICK_BAKE)
QUICK_CLI = ("--quality", "draft", "--samples", "1", "--probe-samples", "4")
from conftest import COOK, REPO

LEVEL = REPO / "content" / "levels" / "temple.toml"


def snapshot(folder: Path) -> dict[str, tuple[int, int]]:
    """Every file below `folder` with its size and modification time."""
    return {str(p.relative_to(folder)): (p.stat().st_size, p.stat().st_mtime_ns) for p in folder.rglob("*") if p.is_file()}


def stage_table(result) -> dict[str, tuple[int, int]]:
    return {s.name: (s.items, s.cached) for s in result.stages}


@pytest.fixture
def level_copy(tmp_path) -> Path:
    """The demo level copied with everything beside it, so a test can edit it."""
    assert LEVEL.exists(), f"{LEVEL} is the project's demo level"
    dst = tmp_path / "content"
    shutil.copytree(LEVEL.parent.parent, dst)
    return dst / "levels" / LEVEL.name


def test_recook_with_nothing_changed_does_no_work_and_touches_nothing(level_copy, tmp_path):
    out_dir = tmp_path / "build"
    out_dir.mkdir()
    out = out_dir / "temple.pack"
    first = cook_detailed(level_copy, out, progress=False, settings=QUICK)
    assert not first.up_to_date
    names = [s.name for s in first.stages]
    assert names == ["level", "uv2", "bake", "chunks", "lod", "mesh_opt", "textures", "compress", "write"], names
    assert all(s.cached == 0 for s in first.stages)
    assert out.with_suffix(".report.md").exists() and out.with_name("temple.lightmap0.exr").exists()
    before = snapshot(out_dir)

    again = cook_detailed(level_copy, out, progress=False, settings=QUICK)
    assert again.up_to_date and again.stages == []
    assert again.summary == first.summary
    assert snapshot(out_dir) == before, "an up-to-date re-cook changed files"

    # A lightmap file that went missing is an output out of date: only the write stage runs.
    out.with_name("temple.lightmap0.exr").unlink()
    third = cook_detailed(level_copy, out, progress=False, settings=QUICK)
    assert not third.up_to_date and all(s.cached == s.items for s in third.stages if s.name != "write"), stage_table(third)
    assert out.with_name("temple.lightmap0.exr").exists()


def test_a_comment_in_the_level_reruns_only_the_level_stage(level_copy, tmp_path):
    out = tmp_path / "temple.pack"
    cook_detailed(level_copy, out, progress=False, settings=QUICK)
    level_copy.write_text(level_copy.read_text() + "\n# an edit that changes no geometry\n")
    result = cook_detailed(level_copy, out, progress=False, settings=QUICK)
    table = stage_table(result)
    assert table["level"] == (1, 0), table
    assert table["uv2"][1] == table["uv2"][0] > 0, f"lightmap UVs should come from the cache: {table}"
    assert table["lod"][1] == table["lod"][0] > 0, f"LODs should come from the cache: {table}"
    assert table["bake"][1] == table["bake"][0] > 0, f"the bake should come from the cache: {table}"
    assert table["textures"][1] == table["textures"][0] > 0, f"mip chains should come from the cache: {table}"


def test_force_rebuilds_every_stage_and_gives_the_same_pack(level_copy, tmp_path):
    out = tmp_path / "temple.pack"
    cook_detailed(level_copy, out, progress=False, settings=QUICK)
    first = out.read_bytes()
    forced = cook_detailed(level_copy, out, progress=False, settings=CookSettings(force=True, bake=QUICK_BAKE))
    assert not forced.up_to_date and all(s.cached == 0 for s in forced.stages)
    assert out.read_bytes() == first, "cooking is not deterministic"


def test_cli_force_and_up_to_date_messages(level_copy, tmp_path):
    import subprocess

    out = tmp_path / "temple.pack"
    run = lambda *a: subprocess.run([str(COOK), str(level_copy), "-o", str(out), *QUICK_CLI, *a], capture_output=True, text=True, timeout=600)
    assert run().returncode == 0
    r = run()
    assert r.returncode == 0 and "is up to date" in r.stdout, r.stdout
    r = run("--force")
    assert r.returncode == 0 and "wrote" in r.stdout and "cook: lod:" in r.stderr, (r.stdout, r.stderr)


def test_a_damaged_cache_entry_is_a_miss_not_a_failure(tmp_path, gltf_samples):
    out = tmp_path / "box.pack"
    src = gltf_samples / "BoxTextured" / "BoxTextured.gltf"
    settings = CookSettings(cache_dir=tmp_path / "cache")
    cook_detailed(src, out, progress=False, settings=settings)
    for entry in (tmp_path / "cache").rglob("*.npz"):
        entry.write_bytes(b"not an npz")
    out.unlink()
    result = cook_detailed(src, out, progress=False, settings=settings)
    assert all(s.cached == 0 for s in result.stages)
    assert asset_pipeline.read_pack_summary(out)["triangles"] == 12


def test_report_lists_lods_errors_atlas_and_stage_times(level_copy, tmp_path):
    out = tmp_path / "temple.pack"
    cook_detailed(level_copy, out, progress=False, settings=QUICK)
    report = out.with_suffix(".report.md").read_text()
    for heading in ("## Stages", "## Meshes and LODs", "## Lightmap atlas", "## Bake"):
        assert heading in report
    assert "| lod |" in report and "| uv2 |" in report
    # Every atlas page has a preview image that exists.
    previews = [line.split("](")[1].rstrip(")") for line in report.splitlines() if line.startswith("![UV2 page")]
    assert previews, "no UV2 previews in the report"
    for p in previews:
        assert (out.parent / p).is_file(), p
