"""Quantised vertices (engine/pack/src/vertex.rs): every attribute of every LOD of every shared
sample and of the demo level, as the pack stores it and the runtime decodes it, against what the
cooker had before writing (`CookResult.scene`), within issue 24's bounds: positions within 1e-4 of
the mesh's size, normals and tangents within 0.5°, texture coordinates within a quarter texel of
the largest texture the LOD's materials sample through them (uv0, texcoord1; with the slot's
KHR_texture_transform scale) and of the lightmap page (uv1, through each instance's region). A
coordinate set no texture reads (AlienCake's untextured meshes span up to 79 units of uv0) is
held to half a 16-bit step of its range, which the codec's own test pins."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from asset_pipeline import _core
from asset_pipeline.cook import cook_detailed
from asset_pipeline.pipeline import CookSettings
from conftest import REPO, gltf_samples_path

SAMPLES = sorted(gltf_samples_path().glob("*/*.gl[tb]*")) if gltf_samples_path().is_dir() else []
SOURCES = [REPO / "content" / "levels" / "temple.toml", *SAMPLES]

# pack::Vertex decoded, 80 bytes.
VERTEX = np.dtype([("position", "<f4", 3), ("normal", "<f4", 3), ("tangent", "<f4", 4), ("uv0", "<f4", 2), ("uv1", "<f4", 2),
                   ("texcoord1", "<f4", 2), ("color", "u1", 4), ("pad", "<u4", 3)])
SLOTS = ("base_color", "normal", "metallic_roughness", "occlusion", "emissive")


def texels_per_unit(doc: dict, materials: set[int]) -> dict[int, float]:
    """Per texture-coordinate set (0: uv0, 1: texcoord1), the most texels one unit of it spans in
    any texture the materials sample through it (texture size times the slot's scale)."""
    out = {0: 0.0, 1: 0.0}
    for k in materials:
        m = doc["materials"][k]
        for slot in SLOTS:
            t = m.get(f"{slot}_texture")
            if t is not None:
                uv = m[f"{slot}_uv"]
                size = max(doc["textures"][t]["width"], doc["textures"][t]["height"])
                out[uv["tex_coord"]] = max(out[uv["tex_coord"]], size * max(abs(uv["scale"][0]), abs(uv["scale"][1])))
    return out


def _angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    a = a.astype(np.float64)
    b = b.astype(np.float64)
    la, lb = np.linalg.norm(a, axis=1), np.linalg.norm(b, axis=1)
    keep = (la > 1e-6) & (lb > 1e-6)
    cos = np.einsum("ij,ij->i", a[keep], b[keep]) / (la[keep] * lb[keep])
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def _pack(path: Path) -> tuple[dict, bytes]:
    doc, data = _core.read_pack(path)
    return json.loads(doc), data


@pytest.mark.parametrize("source", SOURCES, ids=lambda p: p.stem)
def test_every_stored_attribute_is_within_its_bound(source: Path, tmp_path: Path):
    if not source.exists():
        pytest.skip(f"{source} not found (set GLTF_SAMPLES_DIR to run the samples)")
    out = tmp_path / "q.pack"
    # Baking and texture compression change no vertex; skipped, the test cooks in seconds.
    r = cook_detailed(source, out, progress=False, settings=CookSettings(baking=False, compress=False, report=False))
    doc, data = _pack(out)
    assert len(doc["meshes"]) == len(r.scene.meshes)
    page = max(max(p) for p in doc["lightmap"]["pages"]) if doc.get("lightmap") else 0
    worst = {"position": 0.0, "normal": 0.0, "tangent": 0.0, "uv0": 0.0, "texcoord1": 0.0, "uv1": 0.0}
    lods = 0
    for i, (m, mesh) in enumerate(zip(doc["meshes"], r.scene.meshes)):
        assert m["name"] == mesh.name
        size = float(np.max(np.ptp(mesh.lods[0].attributes["position"].astype(np.float64), axis=0))) if mesh.lods[0].vertex_count else 0.0
        regions = [n["lightmap"] for n in doc["nodes"] if n["mesh"] == i and n.get("lightmap")]
        for level, (stored, lod) in enumerate(zip(m["lods"], mesh.lods)):
            what = f"{source.name}: mesh '{mesh.name}' LOD {level}"
            v = stored["vertices"]
            assert v["len"] == stored["vertex_count"] * _core.VERTEX_STRIDE == lod.vertex_count * 36, what
            got = np.frombuffer(_core.decode_vertices(data[v["offset"]:v["offset"] + v["len"]], json.dumps(stored["uv_ranges"])), VERTEX)
            a = lod.attributes
            lods += 1
            err = float(np.max(np.abs(got["position"].astype(np.float64) - a["position"]), initial=0.0))
            assert err <= 1e-4 * size, f"{what}: position error {err} of a {size} m mesh"
            worst["position"] = max(worst["position"], err / size if size else 0.0)
            for name in ("normal", "tangent"):
                if name in a:
                    want = a[name][:, :3]
                    ang = float(np.max(_angle_deg(want, got[name][:, :3]), initial=0.0))
                    assert ang <= 0.5, f"{what}: {name} off by {ang}°"
                    worst[name] = max(worst[name], ang)
            if "tangent" in a:
                signs = np.where(a["tangent"][:, 3] < 0, -1.0, 1.0)
                assert np.array_equal(got["tangent"][:, 3], signs), f"{what}: a bitangent sign flipped"
            density = texels_per_unit(doc, {sm["material"] for sm in stored["submeshes"]})
            for k, name in enumerate(("uv0", "texcoord1")):
                if name in a:
                    d = float(np.max(np.abs(got[name].astype(np.float64) - a[name]), initial=0.0))
                    rng = stored["uv_ranges"][name]
                    # Half a 16-bit step of the range, plus float32 rounding of the affine map.
                    tol = 0.5 * max(rng[:2]) / 65535 + 4 * float(np.finfo(np.float32).eps) * (max(abs(rng[2]), abs(rng[3])) + max(rng[:2]))
                    assert d <= tol, f"{what}: {name} off by {d}, more than half a step of its range"
                    texels = d * density[k]
                    assert texels <= 0.25, f"{what}: {name} off by {texels} texels of its largest texture ({density[k]} texels a unit)"
                    worst[name] = max(worst[name], texels)
            if "uv1" in a and regions:
                d = np.abs(got["uv1"].astype(np.float64) - a["uv1"])
                texels = max(float(np.max(d * np.array(reg["scale"]), initial=0.0)) * page for reg in regions)
                assert texels <= 0.25, f"{what}: uv1 off by {texels} texels of the {page}² page"
                worst["uv1"] = max(worst["uv1"], texels)
            if "color" in a:
                assert np.array_equal(got["color"], a["color"]), f"{what}: colour changed"
    assert lods > 0
    # Every coordinate set here fits 16 bits within a quarter texel: no precision warning.
    assert not [w for w in r.scene.warnings if "16-bit" in w], r.scene.warnings
    print(f"{source.name}: {lods} LODs; worst position {worst['position']:.2e} of the size, normal {worst['normal']:.4f}°, "
          f"tangent {worst['tangent']:.4f}°, uv0 {worst['uv0']:.4f} / texcoord1 {worst['texcoord1']:.4f} texels of their textures, "
          f"uv1 {worst['uv1']:.4f} texels of the {page}² page")


def test_coordinates_too_wide_for_16_bits_are_a_warning_naming_mesh_and_texture(tmp_path: Path):
    """A quad tiled 0..200 times over a 256² texture: 16 bits over 200 units are off by up to
    200 / 131070 * 256 = 0.39 texels, more than a quarter: the cook says so (and still cooks);
    tiled 0..100 times (0.20 texels) it does not."""
    import sys

    import numpy as np

    sys.path.insert(0, str(REPO / "content"))
    from gltf_writer import GltfWriter

    def quad(tiles: float) -> Path:
        w = GltfWriter("test_vertex_quantisation")
        pos = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32)
        nrm = np.tile(np.array([0, 0, 1], np.float32), (4, 1))
        uv = np.array([[0, tiles], [tiles, tiles], [tiles, 0], [0, 0]], np.float32)
        tex = w.texture("tiles", np.random.default_rng(1).integers(0, 255, (256, 256, 4), dtype=np.uint8))
        w.node("floor", mesh=w.mesh("Floor", pos, nrm, uv, np.array([0, 1, 2, 0, 2, 3], np.uint32), w.material("m", texture=tex)))
        path = tmp_path / f"quad{tiles:g}.gltf"
        w.write(path)
        return path

    settings = CookSettings(baking=False, compress=False, report=False, lods=False)
    wide = cook_detailed(quad(200), tmp_path / "wide.pack", progress=False, settings=settings)
    [warning] = [w for w in wide.scene.warnings if "16-bit" in w]
    assert "mesh 'Floor'" in warning and "uv0 spans 200.0 units" in warning and "0.39 texels" in warning and "'tiles'" in warning, warning
    assert (tmp_path / "wide.pack").exists()
    narrow = cook_detailed(quad(100), tmp_path / "narrow.pack", progress=False, settings=settings)
    assert not [w for w in narrow.scene.warnings if "16-bit" in w], narrow.scene.warnings
