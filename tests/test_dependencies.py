"""What a cook reads: every byte of every file it reaches (a level's textures and props, a prop's
buffers and images) is in its cache key, so editing any of them rebuilds exactly what depends on
it; so are the versions of the libraries that shape an output. And it reads nothing outside the
source's folder tree unless told to (--allow-external-uris).
"""

from __future__ import annotations

import json
import textwrap
from pathlib import Path

import numpy as np
import pytest

from asset_pipeline import bake, cache
from asset_pipeline.pipeline import CookSettings, cook
from gltf_scenes import Scene, png_bytes

LEVEL = """
[level]
name = "yard"
texels_per_metre = 4
sky = { color = [0.5, 0.6, 1.0], intensity = 2000 }

[[materials]]
name = "tiles"
texture = "tiles.png"

[[brushes]]
name = "slab"
kind = "box"
size = [6, 0.5, 6]
translation = [0, -0.25, 0]
material = "tiles"

[[objects]]
name = "ground"
op = "union"
operands = ["slab"]

[[props]]
name = "statue"
gltf = "props/statue.gltf"
translation = [0, 0.5, 0]
static = true

[[lights]]
name = "sun"
kind = "sun"
direction = [-0.3, -0.8, -0.5]
intensity = 50000
"""


def write_prop(path: Path) -> None:
    """A textured cube with its buffer and image in files beside it (statue.bin, statue.image0.png)."""
    w = Scene()
    tex = w.texture("marble", np.full((8, 8, 4), (200, 120, 80, 255), np.uint8))
    w.node("statue", mesh=w.box_mesh("cube", material=w.material("marble", texture=tex)))
    w.write(path, external=True)


@pytest.fixture
def yard(tmp_path) -> Path:
    (tmp_path / "tiles.png").write_bytes(png_bytes(np.full((16, 16, 4), 180, np.uint8)))
    write_prop(tmp_path / "props" / "statue.gltf")
    level = tmp_path / "yard.toml"
    level.write_text(textwrap.dedent(LEVEL))
    return level


SETTINGS = CookSettings(bake=bake.BakeSettings(preset="draft", samples=4, probe_samples=8))


def stage_work(result) -> dict:
    """Per stage: (items done, items from the cache)."""
    return {s.name: (s.items, s.cached) for s in result.stages}


def chart_entries(out: Path) -> set:
    return {p.name for p in (out.parent / ".cook-cache" / "uv2-charts").glob("*.npz")}


def test_editing_any_file_a_level_reads_rebuilds_what_depends_on_it_and_nothing_else(yard):
    out = yard.with_name("yard.pack")
    first = cook(yard, out, SETTINGS)
    assert not first.up_to_date
    work = stage_work(first)
    assert work["level"] == (1, 0) and work["bake"][1] == 0
    # The prop's buffer and image are among the files the cook read.
    assert cook(yard, out, SETTINGS).up_to_date
    charts = chart_entries(out)
    meshes = work["lod"][0]

    # The prop's texture: its albedo changes the bake and its own mip chain; no geometry stage runs.
    (yard.parent / "props" / "statue.image0.png").write_bytes(png_bytes(np.full((8, 8, 4), (20, 200, 40, 255), np.uint8)))
    r = cook(yard, out, SETTINGS)
    assert not r.up_to_date
    w = stage_work(r)
    assert w["level"] == (1, 0), "the source stage re-reads the prop"
    assert w["uv2"][1] == w["uv2"][0] and w["lod"] == (meshes, meshes), w
    assert w["bake"][1] == 0, "the bake sees the new texture"
    assert w["textures"][0] - w["textures"][1] == 1, "only the edited texture's mips are made again"
    assert chart_entries(out) == charts

    # The level's texture: the bake and that texture's mips.
    (yard.parent / "tiles.png").write_bytes(png_bytes(np.full((16, 16, 4), 90, np.uint8)))
    r = cook(yard, out, SETTINGS)
    w = stage_work(r)
    assert w["level"] == (1, 0) and w["uv2"][1] == w["uv2"][0] and w["lod"] == (meshes, meshes)
    assert w["bake"][1] == 0 and w["textures"][0] - w["textures"][1] == 1
    assert cook(yard, out, SETTINGS).up_to_date


def test_editing_a_props_geometry_recharts_that_mesh_only(yard):
    out = yard.with_name("yard.pack")
    cook(yard, out, SETTINGS)
    charts = chart_entries(out)
    # Stretch the cube in its .bin: new geometry, so new charts for it alone.
    bin_path = yard.parent / "props" / "statue.bin"
    doc = json.loads((yard.parent / "props" / "statue.gltf").read_text())
    view = doc["bufferViews"][doc["accessors"][doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"]]["bufferView"]]
    blob = bytearray(bin_path.read_bytes())
    pos = np.frombuffer(blob, np.float32, view["byteLength"] // 4, view.get("byteOffset", 0)).copy().reshape(-1, 3)
    pos[:, 1] *= 2.0
    blob[view.get("byteOffset", 0):view.get("byteOffset", 0) + view["byteLength"]] = pos.tobytes()
    bin_path.write_bytes(bytes(blob))
    r = cook(yard, out, SETTINGS)
    w = stage_work(r)
    assert w["uv2"][1] == 0 and w["bake"][1] == 0
    assert w["lod"][0] - w["lod"][1] == 1, "only the prop's LOD chain is rebuilt"
    assert len(chart_entries(out) - charts) == 1, "only the prop is charted again"


def test_a_library_version_is_part_of_the_stages_it_shapes(yard, monkeypatch):
    out = yard.with_name("yard.pack")
    cook(yard, out, SETTINGS)
    real = cache.library_version

    def upgraded(name):
        return real(name) + " (upgraded)"

    # Each library reruns its own stage (and what follows from its output, which here is the same
    # bytes, so later stages hit the cache again).
    for library, stage in (("xatlas", "uv2"), ("fast-simplification", "lod"), ("manifold3d", "level"), ("pyoidn", "bake")):
        monkeypatch.setattr("asset_pipeline.pipeline.library_version", lambda n, lib=library: upgraded(n) if n == lib else real(n))
        monkeypatch.setattr("asset_pipeline.cache.library_version", lambda n, lib=library: upgraded(n) if n == lib else real(n))
        r = cook(yard, out, SETTINGS)
        assert not r.up_to_date, library
        w = stage_work(r)
        assert w[stage][1] < w[stage][0], (library, w)
        others = {s: v for s, v in w.items() if s not in (stage, "write")}
        assert all(cached == items for items, cached in others.values()), (library, w)
        monkeypatch.setattr("asset_pipeline.pipeline.library_version", real)
        monkeypatch.setattr("asset_pipeline.cache.library_version", real)


def test_denoising_or_not_is_part_of_the_bake_key(yard, monkeypatch):
    from asset_pipeline import lightmap_post

    out = yard.with_name("yard.pack")
    cook(yard, out, SETTINGS)
    monkeypatch.setattr(lightmap_post, "_load_pyoidn", lambda: (None, "ImportError: pretend it is not installed"))
    r = cook(yard, out, SETTINGS)
    assert stage_work(r)["bake"][1] == 0, "a bake without the denoiser is another result"


# ---- reading outside the source's folder -----------------------------------------------------------


def test_external_uris_are_refused_then_allowed_with_the_flag(run_cook, tmp_path):
    asset = tmp_path / "asset"
    write_prop(tmp_path / "shared" / "statue.gltf")
    doc = json.loads((tmp_path / "shared" / "statue.gltf").read_text())
    doc["buffers"][0]["uri"] = "../shared/statue.bin"
    doc["images"][0]["uri"] = (tmp_path / "shared" / "statue.image0.png").resolve().as_posix()
    asset.mkdir()
    src = asset / "scene.gltf"
    src.write_text(json.dumps(doc))
    out = tmp_path / "scene.pack"
    r = run_cook(src, "-o", out, "-q", "--no-bake")
    assert r.returncode == 2 and "buffer 0: URI '../shared/statue.bin' reaches outside the asset's folder" in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and not out.exists()
    r = run_cook(src, "-o", out, "-q", "--no-bake", "--allow-external-uris")
    assert r.returncode == 0, r.stderr
    assert out.exists()
