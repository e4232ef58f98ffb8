"""MikkTSpace tangents for the shared samples whose normal maps come without TANGENT (GolfBall,
Terrain; shading.md 2.4 and test 6): every corner of a normal-mapped triangle gets a unit
tangent perpendicular to its normal, w = +-1 and the same on the whole triangle, with glTF's
handedness (cross(N, T) * w points toward decreasing v, up the image), and the LOD chain keeps
them. The algorithm itself is compared with the reference C implementation in cook_core
(tangents.rs)."""

from __future__ import annotations

import numpy as np
import pytest

from asset_pipeline.gltf_import import import_gltf
from asset_pipeline.lod import build_lods

SAMPLES = [("GolfBall", "GolfBall.glb"), ("Terrain", "terrain.glb")]


def normal_mapped_lods(scene):
    """(mesh name, LOD 0, triangle mask) for every mesh with a normal-mapped material."""
    mapped = {i for i, m in enumerate(scene.materials) if m.normal_texture is not None}
    for mesh in scene.meshes:
        lod = mesh.lods[0]
        mask = np.isin(lod.materials, list(mapped))
        if mask.any():
            yield mesh.name, lod, mask


def check_frames(lod, mask, what: str) -> None:
    a = lod.attributes
    tri = lod.triangles[mask]
    n = a["normal"].astype(np.float64)[tri]
    t = a["tangent"].astype(np.float64)[tri]
    assert np.allclose(np.linalg.norm(t[..., :3], axis=2), 1, atol=1e-4), f"{what}: tangents not unit length"
    assert np.isin(t[..., 3], (-1.0, 1.0)).all(), f"{what}: w is not a handedness sign"
    # MikkTSpace orthogonalises against the vertex normal.
    dots = np.abs(np.einsum("tkc,tkc->tk", n, t[..., :3]))
    assert dots.max() < 1e-3, f"{what}: tangent not perpendicular to the normal ({dots.max():.2e})"
    p = a["position"].astype(np.float64)[tri]
    uv = a["uv0"].astype(np.float64)[tri]
    e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    d1, d2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    det = d1[:, 0] * d2[:, 1] - d2[:, 0] * d1[:, 1]
    area = np.linalg.norm(np.cross(e1, e2), axis=1)
    ok = (np.abs(det) > 1e-12) & (area > 1e-12)
    assert ok.mean() > 0.99, f"{what}: {(~ok).sum()} degenerate triangles"
    w = t[ok][..., 3]
    assert (w == w[:, :1]).all(), f"{what}: w changes within {(w != w[:, :1]).any(axis=1).sum()} triangles"
    # Handedness: the bitangent cross(N, T) * w points toward decreasing v (glTF's v runs down
    # the image, a normal map's green up it).
    dpdv = (e2[ok] * d1[ok, 0:1] - e1[ok] * d2[ok, 0:1]) / det[ok, None]
    bit = np.cross(n[ok], t[ok][..., :3]) * t[ok][..., 3:]
    agree = np.einsum("tc,tkc->tk", -dpdv / np.linalg.norm(dpdv, axis=1, keepdims=True), bit)
    assert (agree > 0).mean() > 0.999, f"{what}: bitangents disagree with -dP/dv on {(agree <= 0).any(axis=1).sum()} triangles"


@pytest.mark.parametrize("name,file", SAMPLES)
def test_sample_normal_maps_get_mikktspace_tangents_through_the_lods(gltf_samples, name, file):
    path = gltf_samples / name / file
    if not path.exists():
        pytest.skip(f"{path} is missing")
    scene = import_gltf(path)
    found = list(normal_mapped_lods(scene))
    assert found, f"{name}: no normal-mapped mesh (the sample changed?)"
    for mesh, lod, mask in found:
        check_frames(lod, mask, f"{name} mesh {mesh!r} LOD 0")
        for k, level in enumerate(build_lods(lod)[1:], start=1):
            t = level.attributes["tangent"].astype(np.float64)
            n = level.attributes["normal"].astype(np.float64)
            assert np.allclose(np.linalg.norm(t[:, :3], axis=1), 1, atol=1e-4), f"{name} {mesh!r} LOD {k}: tangents not unit"
            assert np.isin(t[:, 3], (-1.0, 1.0)).all(), f"{name} {mesh!r} LOD {k}: w is not a sign"
            assert np.abs(np.einsum("ij,ij->i", n, t[:, :3])).max() < 1e-3, f"{name} {mesh!r} LOD {k}: T not perpendicular to N"


def test_the_golems_stone_gets_mikktspace_tangents(tmp_path):
    """Our own normal-mapped character (content/characters/make_creature.py: stone plates from
    the cooker's procedural flagstones, no TANGENT written): the same checks, on a skinned mesh
    whose capsules wrap their texture around a seam."""
    import subprocess
    import sys

    from conftest import REPO

    gltf = tmp_path / "golem.gltf"
    subprocess.run([sys.executable, str(REPO / "content" / "characters" / "make_creature.py"), str(gltf)], check=True, timeout=300)
    scene = import_gltf(gltf)
    stone = scene.materials[0]
    assert stone.normal_texture is not None and stone.metallic_roughness_texture == stone.occlusion_texture is not None
    found = list(normal_mapped_lods(scene))
    assert [mesh for mesh, _, _ in found] == ["golem"]
    for mesh, lod, mask in found:
        assert mask.all()
        check_frames(lod, mask, f"golem mesh {mesh!r} LOD 0")
