"""The cooker end to end: `cook` on real samples, and on bad input the CLI fails cleanly:
exit 2, one `cook: error:` line naming the file, no traceback, nothing written."""

from __future__ import annotations

import base64
import fcntl
import json
import os
import pty
import struct
import subprocess
import termios
from pathlib import Path

import pytest
from PIL import Image

import asset_pipeline
from conftest import COOK, gltf_samples_path

SAMPLES = sorted(gltf_samples_path().glob("*/*.gl[tb]*")) if gltf_samples_path().is_dir() else []


def triangle_gltf(indices: tuple[int, ...] = (0, 1, 2)) -> dict:
    """A one-triangle glTF (u16 indices in view 0, positions in view 1) with its buffer embedded."""
    idx = struct.pack(f"<{len(indices)}H", *indices)
    idx_padded = idx + b"\0" * (-len(idx) % 4)
    positions = struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, 1, 0)
    buf = idx_padded + positions
    return {
        "asset": {"version": "2.0"},
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"name": "Tri", "primitives": [{"attributes": {"POSITION": 1}, "indices": 0}]}],
        "accessors": [
            {"bufferView": 0, "componentType": 5123, "count": len(indices), "type": "SCALAR"},
            {"bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]},
        ],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": len(idx)},
            {"buffer": 0, "byteOffset": len(idx_padded), "byteLength": len(positions)},
        ],
        "buffers": [{"byteLength": len(buf),
                     "uri": "data:application/octet-stream;base64," + base64.b64encode(buf).decode()}],
    }


def write_json(path: Path, doc: dict) -> Path:
    path.write_text(json.dumps(doc))
    return path


def assert_failed_cleanly(result: subprocess.CompletedProcess, out: Path, *fragments: str) -> None:
    """Exit 2, a single `cook: error:` line containing every fragment, and no pack or temporary
    file at or beside `out`."""
    assert result.returncode == 2, result
    assert "Traceback" not in result.stderr, result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("cook: error: "), result.stderr
    for f in fragments:
        assert f in lines[0], (f, lines[0])
    assert result.stdout == ""
    assert not out.exists()
    if out.parent.is_dir():
        assert not [p.name for p in out.parent.iterdir() if p.name.startswith(f".{out.name}")], "temporary file left"


# --- real samples ---------------------------------------------------------------------------

def test_box_textured_cooks_and_reads_back(gltf_samples, run_cook, tmp_path):
    out = tmp_path / "box.pack"
    r = run_cook(gltf_samples / "BoxTextured" / "BoxTextured.gltf", "-o", out)
    assert r.returncode == 0, r.stderr
    # Not a terminal: one plain line per stage, no bar.
    assert "%|" not in r.stderr and all(l.startswith("cook: ") for l in r.stderr.splitlines()), r.stderr
    assert "cook: import: 1/1" in r.stderr and "cook: write: 1/1" in r.stderr
    # A static box: baked (its lightmap page is the second texture) under the default sky. The
    # default lightmaps are directional, so the page comes with a third texture, its direction
    # (Rgba8Unorm, as big as the page and, like it, one level).
    assert r.stdout.splitlines() == [f"cook: wrote {out}: 1 mesh, 12 triangles, 3 textures, {out.stat().st_size} bytes"]
    s = asset_pipeline.read_pack_summary(out)
    page = s["texture_sizes"][1]
    assert s == {
        "meshes": 1, "submeshes": 1, "vertices": 24, "indices": 36, "triangles": 12, "materials": 1,
        "textures": 3, "texture_sizes": [[256, 256], page, page], "texture_mips": [9, 1, 1], "nodes": 2, "bytes": out.stat().st_size,
        "lightmap_pages": 1, "lightmaps_baked": 1, "probes": s["probes"],
    }
    assert s["probes"] >= 1
    assert sorted(p.name for p in tmp_path.iterdir()) == [".cook-cache", "box.lightmap0.exr", "box.pack", "box.report", "box.report.md"]


@pytest.mark.parametrize(
    "source",
    SAMPLES or [pytest.param(None, marks=pytest.mark.skip(reason=f"no glTF samples at {gltf_samples_path()}"))],
    ids=lambda p: p.stem if p else "none",
)
def test_every_sample_cooks_and_bakes_its_static_meshes(source, tmp_path):
    """Cooked directly, as `cook model.glb`: a model with static mesh nodes is baked (a quick
    preset at a low density here; tools/bake_samples.py reports every model at medium)."""
    from asset_pipeline.bake import BakeSettings
    from asset_pipeline.gltf_import import import_gltf
    from asset_pipeline.pipeline import CookSettings

    out = tmp_path / f"{source.stem}.pack"
    calls = []
    settings = CookSettings(bake=BakeSettings(preset="draft", samples=4, probe_samples=8), texels_per_metre=4.0)
    summary = asset_pipeline.cook(source, out, progress=lambda stage, done, total: calls.append((stage, done, total)), settings=settings)
    assert summary["meshes"] >= 1 and summary["triangles"] >= 1
    assert asset_pipeline.read_pack_summary(out) == summary
    assert calls[0] == ("import", 0, 1) and calls[-1] == ("write", 1, 1), calls
    static = import_gltf(source).static_nodes()
    if static:
        assert summary["lightmap_pages"] >= 1 and summary["lightmaps_baked"] == summary["lightmap_pages"], summary
        assert summary["probes"] >= 1
        assert out.with_name(f"{source.stem}.lightmap0.exr").exists()
    else:
        assert summary["lightmap_pages"] == 0, summary


def test_broken_sample_accessor(gltf_samples, run_cook, tmp_path):
    doc = json.loads((gltf_samples / "BoxTextured" / "BoxTextured.gltf").read_text())
    doc["bufferViews"][1]["byteLength"] = 500  # POSITION (accessor 2) sits at 288..576 in it
    src = write_json(tmp_path / "broken.gltf", doc)
    out = tmp_path / "broken.pack"
    assert_failed_cleanly(run_cook(src, "-o", out), out,
                          f"{src}: mesh 0 'Mesh' primitive 0: accessor 2 (POSITION) needs 576 bytes but buffer view 1 holds 500")


# --- generated content: runs everywhere -----------------------------------------------------

def test_generated_triangle_cooks(run_cook, tmp_path):
    src = write_json(tmp_path / "tri.gltf", triangle_gltf())
    out = tmp_path / "tri.pack"
    r = run_cook(src, "-o", out)
    assert r.returncode == 0, r.stderr
    s = asset_pipeline.read_pack_summary(out)
    assert (s["meshes"], s["vertices"], s["indices"], s["materials"], s["nodes"]) == (1, 3, 3, 1, 1)


def test_missing_file(run_cook, tmp_path):
    out = tmp_path / "x.pack"
    assert_failed_cleanly(run_cook(tmp_path / "x.gltf", "-o", out), out, f"{tmp_path / 'x.gltf'}: no such file")


def test_text_file_is_not_gltf(run_cook, tmp_path):
    src = tmp_path / "x.gltf"
    src.write_text("this is not json\n")
    out = tmp_path / "x.pack"
    assert_failed_cleanly(run_cook(src, "-o", out), out, f"{src}: not a glTF 2.0 file: ")


def test_png_renamed_glb_is_not_gltf(run_cook, tmp_path):
    src = tmp_path / "picture.glb"
    Image.new("RGB", (4, 4), "red").save(src, format="PNG")
    out = tmp_path / "picture.pack"
    assert_failed_cleanly(run_cook(src, "-o", out), out, f"{src}: not a glTF 2.0 file: ")


def test_broken_accessor(run_cook, tmp_path):
    doc = triangle_gltf()
    doc["accessors"][1]["count"] = 4
    src = write_json(tmp_path / "broken.gltf", doc)
    out = tmp_path / "broken.pack"
    assert_failed_cleanly(run_cook(src, "-o", out), out,
                          f"{src}: mesh 0 'Tri' primitive 0: accessor 1 (POSITION) needs 48 bytes but buffer view 1 holds 36")


def test_index_out_of_range(run_cook, tmp_path):
    src = write_json(tmp_path / "tri.gltf", triangle_gltf(indices=(0, 1, 3)))
    out = tmp_path / "tri.pack"
    assert_failed_cleanly(run_cook(src, "-o", out), out,
                          f"{src}: mesh 0 'Tri' primitive 0: accessor 0 (indices) element 2 is 3, but there are only 3 vertices")


def test_bad_image(run_cook, tmp_path):
    doc = triangle_gltf()
    doc["meshes"][0]["primitives"][0]["material"] = 0
    doc["materials"] = [{"name": "m", "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]
    doc["textures"] = [{"source": 0}]
    doc["images"] = [{"name": "junk", "uri": "data:image/png;base64," + base64.b64encode(b"not a png").decode()}]
    src = write_json(tmp_path / "img.gltf", doc)
    out = tmp_path / "img.pack"
    assert_failed_cleanly(run_cook(src, "-o", out), out, f"{src}: image 0 'junk' (base colour of material 0 'm'): cannot decode")


def test_missing_output_directory_is_named(run_cook, tmp_path):
    src = write_json(tmp_path / "tri.gltf", triangle_gltf())
    out = tmp_path / "nowhere" / "tri.pack"
    assert_failed_cleanly(run_cook(src, "-o", out), out,
                          f"{out}: output directory '{tmp_path / 'nowhere'}' does not exist")


def test_missing_output_argument_is_a_usage_error(run_cook, tmp_path):
    src = write_json(tmp_path / "tri.gltf", triangle_gltf())
    r = run_cook(src)
    assert r.returncode == 2
    assert r.stderr.startswith("usage: cook") and "-o" in r.stderr and "Traceback" not in r.stderr
    assert [p.name for p in tmp_path.iterdir()] == ["tri.gltf"]


def test_existing_output_survives_a_failed_cook(run_cook, tmp_path):
    doc = triangle_gltf()
    doc["accessors"][1]["count"] = 4
    src = write_json(tmp_path / "broken.gltf", doc)
    out = tmp_path / "level.pack"
    out.write_bytes(b"previous pack")
    r = run_cook(src, "-o", out)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert out.read_bytes() == b"previous pack"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["broken.gltf", "level.pack"]


def test_successful_cook_replaces_existing_output(run_cook, tmp_path):
    src = write_json(tmp_path / "tri.gltf", triangle_gltf())
    out = tmp_path / "tri.pack"
    out.write_bytes(b"stale")
    assert run_cook(src, "-o", out, "--no-bake").returncode == 0
    assert asset_pipeline.read_pack_summary(out)["vertices"] == 3
    assert sorted(p.name for p in tmp_path.iterdir()) == [".cook-cache", "tri.gltf", "tri.pack", "tri.report", "tri.report.md"]


def test_api_raises_cook_error_with_the_message(tmp_path):
    with pytest.raises(asset_pipeline.CookError, match=r"x\.gltf: no such file$"):
        asset_pipeline.cook(tmp_path / "x.gltf", tmp_path / "x.pack", progress=False)
    with pytest.raises(asset_pipeline.CookError, match="not a pack file"):
        asset_pipeline.read_pack_summary(write_json(tmp_path / "t.gltf", triangle_gltf()))


def test_progress_callback_error_aborts_without_writing(tmp_path):
    src = write_json(tmp_path / "tri.gltf", triangle_gltf())
    out = tmp_path / "tri.pack"

    def boom(stage: str, done: int, total: int) -> None:
        raise KeyError("stop")

    with pytest.raises(KeyError, match="stop"):
        asset_pipeline.cook(src, out, progress=boom)
    assert not out.exists()


def test_progress_bar_only_on_a_terminal(tmp_path):
    if not COOK.exists():
        pytest.fail(f"{COOK} is missing")
    src = write_json(tmp_path / "tri.gltf", triangle_gltf())
    primary, secondary = pty.openpty()
    # A new pty is 0 columns wide, and tqdm draws nothing in no columns.
    fcntl.ioctl(secondary, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 80, 0, 0))
    with os.fdopen(primary, "rb", buffering=0) as terminal:
        try:
            r = subprocess.run([str(COOK), str(src), "-o", str(tmp_path / "tri.pack")], stdout=subprocess.PIPE,
                               stderr=secondary, timeout=120)
        finally:
            os.close(secondary)
        shown = b""
        while True:
            try:
                chunk = terminal.read(4096)
            except OSError:  # EIO: the terminal's other end is closed and drained
                break
            if not chunk:
                break
            shown += chunk
    assert r.returncode == 0
    assert b"import" in shown and b"write" in shown and b"%|" in shown, shown
