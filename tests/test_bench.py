"""The frame-time benchmarks (issue 9): a short run of every `bench` scenario on the real device,
with the validation layer on, and the exact counters each frame's fixed work produces pinned.

Times are reported (printed with -s, and in the JSON), never gated: CI machines are shared. The
counters are exact because every frame advances the simulation by a fixed step and the camera is
a function of the frame number, so a change here means the engine did different work (culling
stopped culling, an emitter's rate changed, a character lost vertices...).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from conftest import REPO

BENCH = REPO / "target" / "release" / "bench"
REPORT = REPO / "tools" / "bench_report.py"
LEVEL = REPO / "build" / "temple.pack"
CHARACTER = REPO / "build" / "golem.pack"
SCENARIOS = ["demo-flythrough", "culling-100k", "boids-10k", "particles-100k", "skinned-64", "prepass-overdraw"]
# The short run: what the pinned counters below are for (frame WARMUP + FRAMES - 1 is the last).
WARMUP, FRAMES = 2, 3
# Half of `make bench`'s 1280x720 in each direction, for time: the fill-bound scenarios run four
# times faster on lavapipe, and only the LOD choices and fragment counts depend on the size.
WIDTH, HEIGHT = 640, 360
# The pinned runs draw at a fixed render scale: LODs are picked in render pixels, so an adaptive
# scale (set by the machine's speed) would make the triangle counts the machine's. Half, what
# the adaptive scale settles at on lavapipe.
SCALE = 0.5


def run_bench(*args, timeout=900) -> subprocess.CompletedProcess:
    assert BENCH.exists(), f"{BENCH} is built by `make build` (a prerequisite of `make test`)"
    env = dict(os.environ, ENGINE_VALIDATION="1")
    return subprocess.run([str(BENCH), *map(str, args)], capture_output=True, text=True, timeout=timeout, env=env, cwd=REPO)


@pytest.fixture(scope="module")
def results(tmp_path_factory) -> tuple[Path, dict[str, dict], str]:
    """Every scenario, once, into a temporary directory: (directory, results by scenario, stdout)."""
    for pack in (LEVEL, CHARACTER):
        assert pack.exists(), f"{pack} is made by `make cook` (a prerequisite of `make test`)"
    out = tmp_path_factory.mktemp("bench")
    r = run_bench("--all", "--frames", FRAMES, "--warmup", WARMUP, "--width", WIDTH, "--height", HEIGHT, "--json-dir", out,
                  "--level", LEVEL, "--character", CHARACTER, "--render-scale", SCALE)
    assert r.returncode == 0, f"bench failed ({r.returncode}):\n{r.stdout}\n{r.stderr}"
    assert "[vulkan validation error]" not in r.stderr, r.stderr
    return out, {name: json.loads((out / f"{name}.json").read_text()) for name in SCENARIOS}, r.stdout


def test_times_are_reported_not_gated(results, capsys):
    """Print the short run's frame times into the CI log (past pytest's capture)."""
    lines = [line for line in results[2].splitlines() if "cpu_frame_ms" in line or line.startswith(("bench:", "floor"))]
    # Header, floor, a line per scenario, and one per variant: pre-pass off, instancing off, LOD
    # selection off (skinned-64) and demo-flythrough's.
    assert len(lines) == 2 + len(SCENARIOS) + 3 + len(DEMO_VARIANTS)
    with capsys.disabled():
        print("\nbench short run (times are not checked):\n" + "\n".join(lines))


def test_every_scenario_writes_complete_results(results):
    out, docs, _ = results
    for name, doc in docs.items():
        assert doc["scenario"] == name and (doc["width"], doc["height"]) == (WIDTH, HEIGHT)
        assert (doc["frames"], doc["warmup_frames"]) == (FRAMES, WARMUP)
        cpu = doc["cpu_frame_ms"]
        assert cpu["count"] == FRAMES == len(doc["samples"]["cpu_frame_ms"]), name
        assert 0 < cpu["p50"] <= cpu["p95"] <= cpu["p99"] <= cpu["max"], (name, cpu)
        # A whole frame cannot be faster than clearing an empty one... by much: the floor's
        # command buffer is made per frame, so allow a little noise below it.
        assert doc["floor_ratio"]["p50"] > 0.5, (name, doc["floor_ratio"])
        assert doc["floor_ratio"]["p50"] == pytest.approx(cpu["p50"] / doc["floor_ms"]["p50"])
        for p in ("skinning", "shadow", "prepass", "shading", "particles", "tonemap"):
            assert set(doc["pass_gpu_ms"][p]) >= {"p50", "p95", "p99", "max"}, (name, p)
        # The frame's parts (update, prepare and record, fence wait) are parts of it: their
        # means add up to the frame's (the same frames, timed by one clock).
        parts = [doc[k] for k in ("cpu_update_ms", "cpu_record_ms", "fence_wait_ms")]
        assert all(p["count"] == FRAMES and p["p50"] >= 0 for p in parts), (name, parts)
        assert sum(p["mean"] for p in parts) == pytest.approx(cpu["mean"], rel=0.02, abs=0.05), (name, parts, cpu)
    assert not list(out.glob("*.tmp*")), "temporary files left behind"


def counters(results, name) -> dict:
    return results[1][name]["counters"]


def test_culling_100k_culls_the_same_cubes(results):
    c = counters(results, "culling-100k")
    assert c["instances"] == c["cull_tested"] == 100_000
    assert (c["culled"], c["drawn"]) == (CULLING_CULLED, 100_000 - CULLING_CULLED)
    assert c["triangles"] == 12 * c["drawn"]  # one LOD: 12 triangles a cube


def test_culling_100k_draws_its_cubes_instanced(results):
    """The visible cubes are one mesh: with instancing, one call per LOD and pass (the cubes
    have one LOD and no sun, so the pre-pass and the shading pass make one each); without, one
    per cube and pass. Both variants draw the same cubes."""
    doc = results[1]["culling-100k"]
    on, off = doc["counters"], doc["variants"]["instancing_off"]["counters"]
    assert on["drawn"] == off["drawn"] == 100_000 - CULLING_CULLED
    assert on["draw_calls"] == 2
    assert off["draw_calls"] == 2 * off["drawn"]


def test_boids_10k_steps_and_draws_the_whole_flock(results):
    c = counters(results, "boids-10k")
    assert c["boids"] == 10_000
    assert c["boids_drawn"] == BOIDS_DRAWN
    # Two fixed 1/120 s steps per 1/60 s frame.
    assert c["sim_steps"] == 2 * (WARMUP + FRAMES)


def test_particles_100k_holds_the_same_particles(results):
    c = counters(results, "particles-100k")
    assert c["particles"] == c["particles_live"] == PARTICLES_LIVE
    assert 80_000 < c["particles"] < 120_000


def test_skinned_64_skins_every_character(results):
    # At the LODs their size on screen picks (the golem's morph target has LODs too), and in the
    # variant every one at full detail.
    doc = results[1]["skinned-64"]
    c, full = doc["counters"], doc["variants"]["lod_off"]["counters"]
    assert c["animated_instances"] == full["animated_instances"] == 64
    assert (c["skinned_vertices"], c["lod_histogram"]) == SKINNED_LOD
    assert full["skinned_vertices"] == SKINNED_VERTICES and full["lod_histogram"][0] == 64
    assert full["skinned_vertices"] % 64 == 0


def test_culling_along_the_whole_flythrough(tmp_path):
    # What frustum and occlusion culling remove along the demo's camera loop: 60 frames spread
    # over the whole flight (ground level, up, around above the roofs, down), summed per frame.
    # Culling depends on the camera alone, not on the machine: exact (the triangles, at the LODs
    # picked in render pixels, at the fixed SCALE).
    r = run_bench("--scenario", "demo-flythrough", "--frames", 60, "--warmup", 0, "--width", WIDTH, "--height", HEIGHT,
                  "--no-variants", "--json-dir", tmp_path, "--level", LEVEL, "--character", CHARACTER, "--render-scale", SCALE)
    assert r.returncode == 0, f"bench failed ({r.returncode}):\n{r.stdout}\n{r.stderr}"
    totals = json.loads((tmp_path / "demo-flythrough.json").read_text())["counter_totals"]
    assert totals == FLYTHROUGH_TOTALS


def test_every_series_reports_its_render_scale(results, tmp_path):
    # The pinned run: every series of every scenario at the fixed scale it was given.
    for name, doc in results[1].items():
        for series in [doc, *doc.get("variants", {}).values()]:
            rs = series["render_scale"]
            assert rs["frames_at"] == {f"{SCALE:.2f}": FRAMES} and rs["min"] == rs["max"] == SCALE, (name, rs)
            assert len(series["samples"]["render_scale"]) == FRAMES
    # Adaptive by default: each series (the default, each variant) on its own controller; every
    # measured frame at a scale in 0.5..1.
    r = run_bench("--scenario", "skinned-64", "--frames", FRAMES, "--warmup", WARMUP, "--width", WIDTH, "--height", HEIGHT,
                  "--json-dir", tmp_path, "--character", CHARACTER)
    assert r.returncode == 0, f"bench failed ({r.returncode}):\n{r.stdout}\n{r.stderr}"
    doc = json.loads((tmp_path / "skinned-64.json").read_text())
    for series in [doc, *doc["variants"].values()]:
        rs = series["render_scale"]
        assert sum(rs["frames_at"].values()) == FRAMES
        assert 0.5 <= rs["min"] <= rs["p50"] <= rs["max"] <= 1.0, rs


def test_prepass_removes_the_overdraw(results):
    doc = results[1]["prepass-overdraw"]
    on, off = doc["counters"], doc["variants"]["prepass_off"]["counters"]
    assert on["drawn"] == off["drawn"] == 16
    assert on["prepass_fragment_invocations"] is not None and off["prepass_fragment_invocations"] is None
    # Drawn back to front, without the pre-pass every layer shades the pixels it covers; with it,
    # only the nearest does (16 layers, the farther ones covering less of the view).
    assert off["fragments_shaded"] > 8 * on["fragments_shaded"], (on, off)
    assert (on["fragments_shaded"], off["fragments_shaded"]) == OVERDRAW_FRAGMENTS_SHADED


def test_demo_flythrough_draws_the_level_with_its_life(results):
    c = counters(results, "demo-flythrough")
    assert c["animated_instances"] == 2  # the priest and the pilgrim
    assert c["boids"] == 32  # the doves
    pinned = {k: c[k] for k in DEMO_COUNTERS}
    assert pinned == DEMO_COUNTERS


def test_demo_flythrough_measures_each_look_feature_against_the_default(results):
    """Its frames cycle through the default and a variant per feature; each variant's passes show
    the feature switched: MSAA resolves, FXAA filters, no transparent pass without transparency
    (the sky is the tone map's, so it has no pass of its own to show). Every variant
    draws the same content (the counters but the fragments, which MSAA's edges add to, and the
    two glass panes' draw calls, which transparency off skips)."""
    doc = results[1]["demo-flythrough"]
    variants = doc["variants"]
    assert set(variants) == set(DEMO_VARIANTS)
    ran = lambda v, p: v["pass_gpu_ms"][p]["p50"] > 0  # noqa: E731 (a pass that did not run has 0 ms)
    assert not ran(doc, "resolve") and not ran(doc, "fxaa")
    assert ran(variants["aa_msaa"], "resolve") and not ran(variants["aa_msaa"], "fxaa")
    assert ran(variants["aa_fxaa"], "fxaa") and not ran(variants["aa_fxaa"], "resolve")
    assert ran(doc, "transparent") and not ran(variants["transparency_off"], "transparent")  # the lanterns' glass
    same = {k: v for k, v in doc["counters"].items() if "fragment" not in k}
    for name, v in variants.items():
        assert v["cpu_frame_ms"]["count"] == FRAMES, name
        skipped = {"draw_calls": 2} if name == "transparency_off" else {}
        assert {k: x + skipped[k] if k in skipped else x for k, x in v["counters"].items() if k in same} == same, name


def test_bad_arguments_exit_2_with_a_clear_message():
    r = run_bench("--scenario", "culling-1m")
    assert r.returncode == 2 and "unknown scenario 'culling-1m'" in r.stderr and "culling-100k" in r.stderr, r.stderr
    r = run_bench("--scenario", "culling-100k", "--frames", "0")
    assert r.returncode == 2 and "--frames must be at least 1" in r.stderr, r.stderr
    r = run_bench("--scenario", "culling-100k", "--frames")
    assert r.returncode == 2 and "--frames needs a value" in r.stderr, r.stderr


def test_help_lists_every_scenario():
    r = run_bench("--help")
    assert r.returncode == 0, r.stderr
    for name in SCENARIOS:
        assert name in r.stdout
    for option in ("--scenario", "--all", "--frames", "--warmup", "--json-dir", "--level", "--character"):
        assert option in r.stdout
    # The subcommands' help is not an error either.
    for sub, options in (("sim", ("--boids", "--brute-max", "--particles", "--steps")), ("skinned", ("--pack", "--characters"))):
        r = run_bench(sub, "--help")
        assert r.returncode == 0 and r.stderr == "", (sub, r.returncode, r.stderr)
        for option in options:
            assert option in r.stdout, (sub, option)
    r = run_bench("sim", "--boids", "ten")
    assert r.returncode == 2 and "--boids: 'ten' is not a whole number" in r.stderr, r.stderr


def test_missing_level_says_how_to_cook_it(tmp_path):
    r = run_bench("--scenario", "demo-flythrough", "--frames", 1, "--warmup", 0, "--level", tmp_path / "none.pack", "--json-dir", tmp_path)
    assert r.returncode == 1 and "none.pack" in r.stderr and "make cook" in r.stderr, r.stderr
    assert not (tmp_path / "demo-flythrough.json").exists()


def run_report(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(REPORT), *map(str, args)], capture_output=True, text=True, timeout=60)


def test_report_writes_plots_and_summary(results):
    out = results[0]
    r = run_report(out)
    assert r.returncode == 0, r.stderr
    summary = (out / "summary.md").read_text()
    assert summary in r.stdout
    for name in SCENARIOS:
        assert f"| {name} |" in summary
        svg = ET.fromstring((out / f"{name}.svg").read_text())  # well-formed, or it raises
        lines = svg.findall("{http://www.w3.org/2000/svg}polyline")
        # One point per measured frame; a line for the default and one per variant (the overdraw
        # and culling plots' switch-off frames, the flythrough's look features).
        assert len(lines) == 1 + len(results[1][name].get("variants", {})), name
        assert all(len(line.get("points").split()) == FRAMES for line in lines), name
    assert "| prepass-overdraw (prepass off) |" in summary
    assert "| culling-100k (instancing off) |" in summary
    assert "| demo-flythrough (aa msaa) |" in summary


def test_compare_prints_ratios_and_rejects_bad_input(results, tmp_path):
    out = results[0]
    r = run_report("compare", out, out)
    assert r.returncode == 0, r.stderr
    for name in SCENARIOS:
        assert f"| {name} |" in r.stdout
    assert "1.00x" in r.stdout and "same" in r.stdout
    # A run that did different work is named as such, not passed off as noise.
    changed = tmp_path / "changed"
    changed.mkdir()
    doc = json.loads((out / "culling-100k.json").read_text())
    doc["counters"]["culled"] = 0
    doc["cpu_frame_ms"]["p50"] *= 2
    (changed / "culling-100k.json").write_text(json.dumps(doc))
    r = run_report("compare", out, changed)
    assert r.returncode == 0, r.stderr
    row = next(line for line in r.stdout.splitlines() if line.startswith("| culling-100k |"))
    assert "2.00x" in row and row.endswith("| culled |"), row
    assert "in one set only (not compared): " in r.stdout and "demo-flythrough" in r.stdout
    r = run_report("compare", out, tmp_path / "missing")
    assert r.returncode == 2 and "missing: no such directory" in r.stderr, r.stderr
    (tmp_path / "broken.json").write_text("{")
    r = run_report("compare", out, tmp_path)
    assert r.returncode == 1 and "broken.json: not a readable JSON file" in r.stderr, r.stderr


# ---- the pinned counters of the short run (frame WARMUP + FRAMES - 1, 640x360 at SCALE) ------------------

CULLING_CULLED = 74_446
BOIDS_DRAWN = 10_000
PARTICLES_LIVE = 100_174
SKINNED_VERTICES = 813_440  # 64 golems of 12 710 vertices (a seam vertex per capsule ring for the texture, MikkTSpace splits)
# The same 64 at the LODs the framed grid picks at 640x360 drawn at SCALE (LODs in render pixels):
# all 64 at LOD 6, the coarsest (320 vertices).
SKINNED_LOD = (20_480, [0, 0, 0, 0, 0, 0, 64, 0])
# (pre-pass on, off): about half of the 320x180 pixels drawn (640x360 at SCALE), then the sum
# over the 16 layers.
OVERDRAW_FRAGMENTS_SHADED = (27_468, 319_112)
# build/temple.pack from the camera flight's last measured frame (2/3 of the loop: above the
# roofs, the whole level in view): the level's chunks and whole meshes, 32 doves, the priest's
# and the pilgrim's golems skinned, the fountain's and the brazier's particles after 2 s of warm-up.
# Summed over the 60 frames of the loop: instance-frames the frustum culled, occlusion tested and
# culled (hidden behind the level's chunks and meshes), drawn, and the triangles drawn.
FLYTHROUGH_TOTALS = {"frustum_culled": 425, "occlusion_tested": 1813, "occlusion_culled": 37, "drawn": 3798, "triangles": 270_704}
DEMO_VARIANTS = ["aa_msaa", "aa_fxaa", "sky_off", "material_maps_off", "specular_off", "transparency_off", "lightmaps_bicubic", "reflections_off"]
DEMO_COUNTERS = {
    "instances": 39,  # the level's 4 whole meshes and 25 chunks (temple 15, courtyard 10), 2 golems, 2 lanterns of 4 parts
    "drawn": 69,  # with the 32 doves
    "culled": 2,
    # Occlusion: the 8 largest static instances in view rasterised on the CPU; the rest tested.
    "occluders": 8,
    "occlusion_tested": 31,
    "occlusion_culled": 2,
    "triangles": 4_310,
    # One per submesh and pass (each chunk is an instance of its own mesh); the lanterns' three
    # opaque parts in the pre-pass, shading and shadow passes, their glass in the transparent one.
    "draw_calls": 168,
    "lod_histogram": [26, 6, 1, 2, 0, 0, 2, 0],  # the golems at LOD 6 from above the roofs
    "particles": 301,
    "boids_drawn": 32,
    "skinned_vertices": 1_720,
    "fragments_shaded": 32_163,  # at SCALE: 320x180 pixels drawn
}
