"""The mesh optimisation stage (issue 24, mesh_opt.py): every LOD in vertex cache, overdraw and
vertex fetch order. Order only: the cooked scene holds the same triangles (windings kept) with
the same corner values in every per-vertex stream, and the vertex cache model counts fewer
vertex shader runs. The ACMR the stage reports is checked against an independent FIFO
simulation."""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pytest

from asset_pipeline import ir
from asset_pipeline.mesh_opt import optimize_lod, vertices_transformed
from asset_pipeline.pipeline import CookSettings, cook

from conftest import COOK, REPO

GOLEM = REPO / "content" / "levels" / "characters" / "golem.gltf"
LEVEL = REPO / "content" / "levels" / "temple.toml"
SAMPLES = ["AlienCake/alien.glb", "PalmTree/PalmTree.gltf", "GolfBall/GolfBall.glb", "SimpleMorph/SimpleMorph.gltf",
           "RiggedSimple/RiggedSimple.gltf", "Terrain/terrain.glb"]


def triangle_set(lod: ir.Lod) -> list[tuple]:
    """Each triangle as (material, lightmap block, its three corners' bytes over every
    per-vertex stream), rotated so the smallest corner comes first (the winding kept), sorted:
    equal for two LODs exactly when they draw the same triangles with the same values."""
    n = lod.vertex_count
    streams = [a.reshape(n, -1).view(np.uint8).reshape(n, -1) for _, a in sorted(lod.attributes.items())]
    for d in (lod.morph_positions, lod.morph_normals):
        if d is not None:
            streams.append(np.ascontiguousarray(d.transpose(1, 0, 2)).reshape(n, -1).view(np.uint8))
    rows = np.concatenate(streams, axis=1)
    corner = [bytes(r) for r in rows]
    blocks = lod.lightmap_blocks if lod.lightmap_blocks is not None else np.zeros(lod.triangle_count, np.uint32)
    out = []
    for t, m, b in zip(lod.triangles, lod.materials, blocks):
        c = [corner[i] for i in t]
        k = min(range(3), key=lambda j: c[j])
        out.append((int(m), int(b), c[k], c[(k + 1) % 3], c[(k + 2) % 3]))
    return sorted(out)


def fifo_acmr(triangles: np.ndarray, cache_size: int = 16) -> float:
    """Vertices transformed per triangle by a FIFO post-transform cache of `cache_size`
    entries (the model meshoptimizer's analyzer uses), simulated here independently."""
    cache: list[int] = []
    misses = 0
    for i in triangles.reshape(-1).tolist():
        if i not in cache:
            misses += 1
            cache.append(i)
            if len(cache) > cache_size:
                cache.pop(0)
    return misses / max(len(triangles), 1)


def cooked_pair(source: Path, tmp: Path, **settings) -> tuple:
    """The scene cooked with and without the stage (nothing else differs), and the stage's stats."""
    common = dict(force=True, baking=False, report=False, cache_dir=tmp / "cache", **settings)
    on = cook(source, tmp / "on.pack", CookSettings(**common))
    off = cook(source, tmp / "off.pack", CookSettings(mesh_opt=False, **common))
    return on, off


def assert_same_geometry(on, off, what: str) -> None:
    assert len(on.scene.meshes) == len(off.scene.meshes)
    for a, b in zip(on.scene.meshes, off.scene.meshes):
        assert len(a.lods) == len(b.lods), f"{what} mesh '{a.name}'"
        for level, (la, lb) in enumerate(zip(a.lods, b.lods)):
            assert la.error == lb.error
            assert triangle_set(la) == triangle_set(lb), f"{what} mesh '{a.name}' LOD {level}: the triangles or their values changed"


def test_the_level_keeps_its_triangles_and_transforms_fewer_vertices(tmp_path):
    on, off = cooked_pair(LEVEL, tmp_path)
    assert_same_geometry(on, off, "temple")
    s = on.mesh_opt
    assert s and not off.mesh_opt
    # Measured 1.18 -> 0.76 over every LOD, LOD 0 1.13 -> 0.77 (16-entry FIFO).
    assert s["acmr_after"] < 0.8 < 1.1 < s["acmr_before"], s
    assert s["lod0_acmr_after"] < 0.8 < 1.1 < s["lod0_acmr_before"], s
    assert s["triangles"] == sum(l.triangle_count for m in on.scene.meshes for l in m.lods)
    assert s["vertices_after"] == sum(l.vertex_count for m in on.scene.meshes for l in m.lods)
    # Submeshes are still contiguous groups: each (material, block) appears in one run.
    for m in on.scene.meshes:
        for lod in m.lods:
            keys = lod.materials.astype(np.uint64) << np.uint64(32) | (lod.lightmap_blocks.astype(np.uint64) if lod.lightmap_blocks is not None else np.uint64(0))
            assert np.all(np.diff(keys.astype(np.int64)) >= 0), f"{m.name}: groups not in ascending runs"
    # The pack with the stage is a different, valid pack (the runtime's tests load the default one).
    assert (tmp_path / "on.pack").read_bytes() != (tmp_path / "off.pack").read_bytes()


def test_a_skinned_morphing_character_keeps_every_stream(tmp_path):
    on, off = cooked_pair(GOLEM, tmp_path)
    assert_same_geometry(on, off, "golem")
    golem = max(on.scene.meshes, key=lambda m: m.base.triangle_count)
    assert "joints" in golem.base.attributes and golem.base.morph_positions is not None
    assert on.mesh_opt["acmr_after"] < on.mesh_opt["acmr_before"]


@pytest.mark.parametrize("sample", SAMPLES)
def test_samples_keep_their_triangles(sample, gltf_samples, tmp_path):
    source = gltf_samples / sample
    if not source.exists():
        pytest.skip(f"{source} is not among the samples")
    on, off = cooked_pair(source, tmp_path, lightmap_uvs=False)
    assert_same_geometry(on, off, sample)
    s = on.mesh_opt
    assert s["acmr_after"] <= s["acmr_before"] + 1e-6, s


def test_the_reported_acmr_is_a_fifo_cache_s(tmp_path):
    """meshoptimizer's analyzer against a FIFO simulated here, before and after, on the golem's
    LOD 0 (22 848 triangles)."""
    from asset_pipeline.gltf_import import import_gltf_scene

    scene = import_gltf_scene(GOLEM)
    lod = max((m.base for m in scene.meshes), key=lambda l: l.triangle_count)
    new = optimize_lod(lod)
    order = np.argsort(lod.materials, kind="stable")  # the pack draws group after group
    for l, tris in ((lod, lod.triangles[order]), (new, new.triangles)):
        assert vertices_transformed(l) == pytest.approx(fifo_acmr(tris) * l.triangle_count, rel=1e-5)
    assert fifo_acmr(new.triangles) < 0.8 * fifo_acmr(lod.triangles[order])


def test_the_cli_turns_it_off(tmp_path):
    out = tmp_path / "golem.pack"
    r = subprocess.run([str(COOK), str(GOLEM), "-o", str(out), "--no-mesh-opt", "--no-bake", "--cache", str(tmp_path / "c")],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "Mesh optimisation" not in out.with_suffix(".report.md").read_text()
    r = subprocess.run([str(COOK), str(GOLEM), "-o", str(out), "--no-bake", "--cache", str(tmp_path / "c")], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "## Mesh optimisation" in out.with_suffix(".report.md").read_text()
