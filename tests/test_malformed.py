"""A corpus of malformed inputs, made here from small valid ones (no binaries in the repository):
glTF (.gltf and .glb), level TOML, images, and packs handed to the runtime.

Every case must fail cleanly: exit status 2, one ``cook: error:`` (or ``demo: error:``) line that
names the file and the problem, no panic, no traceback, nothing written, and memory bounded: the
cook runs under an address-space limit, so an input that makes it allocate gigabytes shows up as
a crash here rather than as a machine that swaps.
"""

from __future__ import annotations

import base64
import json
import os
import resource
import struct
import subprocess
import sys
import textwrap
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
import pytest

from conftest import COOK, DEMO, REPO, gltf_samples_path

sys.path.insert(0, str(REPO / "content"))
from gltf_writer import GltfWriter, png_bytes  # noqa: E402

# The cook's address space is capped: Python, numpy, manifold3d and the Rust core take well under
# 1 GB; a bad count that turns into a multi-gigabyte allocation fails instead of passing.
MEMORY_LIMIT = 3 << 30
ENV = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "RAYON_NUM_THREADS": "2"}


def run_limited(args: list, timeout: float = 120) -> subprocess.CompletedProcess:
    def limit():
        resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))

    return subprocess.run([str(a) for a in args], capture_output=True, text=True, timeout=timeout, preexec_fn=limit, env=ENV)


def assert_clean_failure(r: subprocess.CompletedProcess, prog: str, named: Path, fragments: list[str], out: Path | None = None) -> str:
    """Exit 2 with one `<prog>: error: <file>...` line holding every fragment; no panic, no traceback,
    no output or temporary file left. Returns the message."""
    what = f"exit {r.returncode}\nstdout: {r.stdout}\nstderr: {r.stderr}"
    assert r.returncode == 2, what
    for bad in ("Traceback", "panicked", "RUST_BACKTRACE", "memory allocation of", "MemoryError"):
        assert bad not in r.stderr, what
    lines = [l for l in r.stderr.splitlines() if l.startswith(f"{prog}: error: ")]
    assert len(lines) == 1, what
    msg = lines[0]
    assert str(named) in msg, (str(named), msg)
    for f in fragments:
        assert f in msg, (f, msg)
    if out is not None:
        assert not out.exists(), "a pack was written"
        assert not [p.name for p in out.parent.iterdir() if p.name.startswith(f".{out.name}")], "temporary file left"
    return msg


# ---- valid starting points --------------------------------------------------------------------


def quad_writer(texture: bool = True) -> GltfWriter:
    """A textured quad: accessors 0 POSITION, 1 NORMAL, 2 TEXCOORD_0, 3 indices (u32, 6); buffer
    views 0..3 in that order; image 0 (a 4x4 PNG) on material 0."""
    w = GltfWriter("test_malformed")
    pos = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32)
    nrm = np.tile(np.array([0, 0, 1], np.float32), (4, 1))
    uv = np.array([[0, 1], [1, 1], [1, 0], [0, 0]], np.float32)
    idx = np.array([0, 1, 2, 0, 2, 3], np.uint32)
    tex = w.texture("checker", np.full((4, 4, 4), 200, np.uint8)) if texture else None
    mat = w.material("m", texture=tex)
    w.node("quad", mesh=w.mesh("Quad", pos, nrm, uv, idx, mat))
    return w


def quad_doc(texture: bool = True) -> dict:
    w = quad_writer(texture)
    w.doc["buffers"] = [{"byteLength": len(w.blob), "uri": "data:application/octet-stream;base64," + base64.b64encode(bytes(w.blob)).decode()}]
    if not texture:
        w.doc["samplers"] = []
    return {k: v for k, v in w.doc.items() if v != []}


def get_blob(doc: dict, buffer: int = 0) -> bytearray:
    return bytearray(base64.b64decode(doc["buffers"][buffer]["uri"].split(",", 1)[1]))


def set_blob(doc: dict, blob: bytes, buffer: int = 0) -> dict:
    doc["buffers"][buffer]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(bytes(blob)).decode()
    doc["buffers"][buffer]["byteLength"] = len(blob)
    return doc


def glb_bytes(doc: dict, blob: bytes | None = None) -> bytes:
    """`doc` as a binary glTF: buffer 0 becomes the BIN chunk."""
    doc = json.loads(json.dumps(doc))
    if blob is None:
        blob = bytes(get_blob(doc))
        del doc["buffers"][0]["uri"]
    j = json.dumps(doc).encode()
    j += b" " * (-len(j) % 4)
    b = blob + b"\0" * (-len(blob) % 4)
    body = struct.pack("<II", len(j), 0x4E4F534A) + j + struct.pack("<II", len(b), 0x004E4942) + b
    return b"glTF" + struct.pack("<II", 2, 12 + len(body)) + body


def glb_json_len(g: bytes) -> int:
    return struct.unpack_from("<I", g, 12)[0]


def patch(b: bytes, at: int, fmt: str, *values) -> bytes:
    b = bytearray(b)
    struct.pack_into(fmt, b, at, *values)
    return bytes(b)


def png(w: int = 4, h: int = 4) -> bytes:
    return png_bytes(np.full((h, w, 4), 128, np.uint8))


def png_chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def png_claiming(w: int, h: int, rows: int = 2) -> bytes:
    """A PNG whose header says w x h but whose pixel data holds `rows` rows of width 2."""
    raw = b"".join(b"\x00" + b"\x80" * 8 for _ in range(rows))
    return (b"\x89PNG\r\n\x1a\n" + png_chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 6, 0, 0, 0))
            + png_chunk(b"IDAT", zlib.compress(raw)) + png_chunk(b"IEND", b""))


def jpeg() -> bytes:
    from io import BytesIO

    from PIL import Image

    f = BytesIO()
    Image.new("RGB", (16, 16), (200, 100, 50)).save(f, format="JPEG")
    return f.getvalue()


def with_image(doc: dict, data: bytes, mime: str = "image/png", via_view: bool = False) -> dict:
    """Replace image 0's bytes (as a data: URI, or a buffer view with a mimeType)."""
    if via_view:
        blob = get_blob(doc)
        while len(blob) % 4:
            blob.append(0)
        doc["bufferViews"].append({"buffer": 0, "byteOffset": len(blob), "byteLength": len(data)})
        set_blob(doc, blob + data)
        doc["images"][0] = {"bufferView": len(doc["bufferViews"]) - 1, "mimeType": mime}
    else:
        doc["images"][0] = {"uri": f"data:{mime};base64," + base64.b64encode(data).decode()}
    return doc


def set_float(doc: dict, view: int, at: int, value: float) -> dict:
    """Overwrite the f32 `at` bytes into buffer view `view`."""
    blob = get_blob(doc)
    struct.pack_into("<f", blob, doc["bufferViews"][view]["byteOffset"] + at, value)
    return set_blob(doc, blob)


def set_position(doc: dict, vertex: int, value: float) -> dict:
    return set_float(doc, 0, vertex * 12 + 4, value)


def set_index(doc: dict, k: int, value: int) -> dict:
    blob = get_blob(doc)
    struct.pack_into("<I", blob, doc["bufferViews"][3]["byteOffset"] + 4 * k, value)
    return set_blob(doc, blob)


def sparse_doc(**sparse_changes) -> dict:
    """The quad with a sparse POSITION accessor (two substitutions at vertices 1 and 2)."""
    doc = quad_doc(texture=False)
    blob = get_blob(doc)
    indices, values = struct.pack("<2H", 1, 2) + b"\0\0", struct.pack("<6f", 2, 0, 0, 2, 2, 0)
    doc["bufferViews"] += [{"buffer": 0, "byteOffset": len(blob), "byteLength": 4},
                           {"buffer": 0, "byteOffset": len(blob) + 4, "byteLength": 24}]
    set_blob(doc, blob + indices + values)
    sp = {"count": 2, "indices": {"bufferView": 4, "componentType": 5123}, "values": {"bufferView": 5}}
    for k, v in sparse_changes.items():
        if k == "index_values":
            blob = get_blob(doc)
            struct.pack_into("<2H", blob, doc["bufferViews"][4]["byteOffset"], *v)
            set_blob(doc, blob)
        else:
            sp[k] = v
    doc["accessors"][0]["sparse"] = sp
    return doc


def sample_with_sparse_index(d: Path, value: int) -> Path:
    """Khronos' SimpleSparseAccessor with its last sparse index (u16 at byte 244) set to `value`."""
    sample = gltf_samples_path() / "SimpleSparseAccessor" / "SimpleSparseAccessor.gltf"
    if not sample.is_file():
        pytest.skip(f"glTF samples not found at {gltf_samples_path()}")
    doc = json.loads(sample.read_text())
    blob = get_blob(doc)
    struct.pack_into("<H", blob, 244, value)
    p = d / "sparse.gltf"
    p.write_text(json.dumps(set_blob(doc, blob)))
    return p


def nodes_doc(nodes: list[dict], roots: list[int]) -> dict:
    doc = quad_doc(texture=False)
    doc["nodes"] = nodes
    doc["scenes"] = [{"nodes": roots}]
    return doc


def animated_doc(times: list[float], values: list[float], interpolation: str = "LINEAR") -> dict:
    """The quad with a translation clip on node 0."""
    doc = quad_doc(texture=False)
    blob = get_blob(doc)
    t, v = struct.pack(f"<{len(times)}f", *times), struct.pack(f"<{len(values)}f", *values)
    doc["bufferViews"] += [{"buffer": 0, "byteOffset": len(blob), "byteLength": len(t)},
                           {"buffer": 0, "byteOffset": len(blob) + len(t), "byteLength": len(v)}]
    set_blob(doc, blob + t + v)
    doc["accessors"] += [{"bufferView": 4, "componentType": 5126, "count": len(times), "type": "SCALAR"},
                         {"bufferView": 5, "componentType": 5126, "count": len(values) // 3, "type": "VEC3"}]
    doc["animations"] = [{"name": "move", "samplers": [{"input": 4, "output": 5, "interpolation": interpolation}],
                          "channels": [{"sampler": 0, "target": {"node": 0, "path": "translation"}}]}]
    return doc


def amplified_doc(primitives: int, vertices: int, targets: int = 0) -> dict:
    """A small file whose meshes reference one big accessor many times: `primitives` primitives of
    `vertices` vertices each (with `targets` morph targets on the same accessor)."""
    pos = np.zeros((vertices, 3), np.float32)
    pos[:, 0] = np.arange(vertices) % 7
    pos[:, 1] = np.arange(vertices) // 7 % 5
    blob = pos.tobytes()
    prim = {"attributes": {"POSITION": 0, "NORMAL": 0}}
    if targets:
        prim["targets"] = [{"POSITION": 0}] * targets
    return {
        "asset": {"version": "2.0"},
        "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
        "meshes": [{"name": "Big", "primitives": [prim] * primitives}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": vertices, "type": "VEC3",
                       "min": [0, 0, 0], "max": [6, 4, 0]}],
        "bufferViews": [{"buffer": 0, "byteLength": len(blob)}],
        "buffers": [{"byteLength": len(blob), "uri": "data:application/octet-stream;base64," + base64.b64encode(blob).decode()}],
    }


# ---- the corpus ---------------------------------------------------------------------------------


@dataclass
class Case:
    """`make(dir) -> source` writes the input; the error must name `named(dir)` (default: the
    source) and contain every fragment."""
    name: str
    make: Callable[[Path], Path]
    fragments: list[str]
    named: Callable[[Path], Path] | None = None


def gltf_case(name: str, mutate: Callable[[], dict], *fragments: str) -> Case:
    def make(d: Path) -> Path:
        p = d / f"{name}.gltf"
        p.write_text(json.dumps(mutate()))
        return p
    return Case(f"gltf-{name}", make, list(fragments))


def glb_case(name: str, make_bytes: Callable[[], bytes], *fragments: str) -> Case:
    def make(d: Path) -> Path:
        p = d / f"{name}.glb"
        p.write_bytes(make_bytes())
        return p
    return Case(f"glb-{name}", make, list(fragments))


def edit(doc: dict, path: str, value) -> dict:
    """Set doc[a][b]... for path 'a.0.b' (value None deletes)."""
    keys = [int(k) if k.isdigit() else k for k in path.split(".")]
    target = doc
    for k in keys[:-1]:
        target = target[k]
    if value is None:
        del target[keys[-1]]
    else:
        target[keys[-1]] = value
    return doc


def q(path: str, value, texture: bool = False) -> Callable[[], dict]:
    return lambda: edit(quad_doc(texture), path, value)


GLB = lambda: glb_bytes(quad_doc(texture=False))  # noqa: E731

GLTF_CASES = [
    # binary container
    glb_case("truncated-header", lambda: GLB()[:10], "not a glTF 2.0 file"),
    glb_case("truncated-in-json", lambda: GLB()[:40], "not a glTF 2.0 file: GLB header declares a length of", "bytes but the file has 40 (cut short?)"),
    glb_case("truncated-in-bin", lambda: GLB()[:-40], "not a glTF 2.0 file: GLB header declares a length of", "(cut short?)"),
    glb_case("length-past-end", lambda: patch(GLB(), 8, "<I", len(GLB()) + 4096), f"not a glTF 2.0 file: GLB header declares a length of {len(GLB()) + 4096} bytes but the file has {len(GLB())}"),
    glb_case("length-under-header", lambda: patch(GLB(), 8, "<I", 8), "not a glTF 2.0 file", "GLB header declares a length of 8 bytes"),
    glb_case("json-chunk-length-huge", lambda: patch(GLB(), 12, "<I", 0xFFFFFFF0), "not a glTF 2.0 file: GLB chunk 0 (JSON) declares 4294967280 bytes but only"),
    glb_case("bin-chunk-length-huge", lambda: patch(GLB(), 20 + glb_json_len(GLB()), "<I", 0x7FFFFFF0), "not a glTF 2.0 file: GLB chunk 1 (BIN) declares 2147483632 bytes but only"),
    glb_case("container-version-1", lambda: patch(GLB(), 4, "<I", 1), "not a glTF 2.0 file", "GLB container version 1"),
    glb_case("first-chunk-not-json", lambda: patch(GLB(), 16, "<I", 0x004E4942), "not a glTF 2.0 file"),
    glb_case("json-chunk-garbage", lambda: GLB()[:20] + b"\xff" * glb_json_len(GLB()) + GLB()[20 + glb_json_len(GLB()):], "not a glTF 2.0 file"),
    glb_case("missing-bin-chunk", lambda: (lambda g: patch(g[:20 + glb_json_len(g)], 8, "<I", 20 + glb_json_len(g)))(GLB()),
             "buffer 0 refers to the GLB binary chunk, which is missing"),
    glb_case("bin-chunk-shorter-than-buffer",
             lambda: glb_bytes(edit(edit(quad_doc(False), "buffers.0.uri", None), "buffers.0.byteLength", 4096), bytes(get_blob(quad_doc(False)))),
             "buffer 0 holds", "declares byteLength 4096"),
    # buffers and views
    gltf_case("buffer-longer-than-data", q("buffers.0.byteLength", 10_000), "buffer 0 holds", "declares byteLength 10000"),
    gltf_case("buffer-bad-base64", q("buffers.0.uri", "data:application/octet-stream;base64,@@@notbase64"), "buffer 0: bad base64"),
    gltf_case("buffer-missing-file", q("buffers.0.uri", "missing.bin"), "buffer 0: cannot read", "missing.bin"),
    gltf_case("buffer-remote-uri", q("buffers.0.uri", "https://example.com/quad.bin"), "buffer 0: unsupported URI scheme"),
    gltf_case("view-outside-buffer", q("bufferViews.0.byteOffset", 4000), "buffer view 0", "does not fit in buffer 0"),
    gltf_case("view-length-huge", q("bufferViews.0.byteLength", 2**40), "buffer view 0", "does not fit in buffer 0"),
    # accessors
    gltf_case("accessor-count-past-view", q("accessors.0.count", 5), "accessor 0 (POSITION) needs 60 bytes but buffer view 0 holds 48"),
    gltf_case("accessor-offset-past-view", q("accessors.1.byteOffset", 1000), "accessor 1 (NORMAL) needs", "buffer view 1 holds 48"),
    gltf_case("accessor-count-absurd", q("accessors.0.count", 2**31 - 1), "accessor 0 (POSITION) has 2147483647 elements, more than the cooker's limit"),
    gltf_case("accessor-stride-too-small", q("bufferViews.0.byteStride", 4), "accessor 0 (POSITION): buffer view 0 has stride 4, less than the 12-byte element"),
    gltf_case("accessor-stride-huge", lambda: edit(edit(quad_doc(False), "bufferViews.0.byteStride", 252), "accessors.0.count", 50_000_000),
              "accessor 0 (POSITION) needs", "buffer view 0 holds 48"),
    gltf_case("accessor-wrong-type", q("accessors.0.type", "VEC2"), "accessor 0 (POSITION) is VEC2 of F32, expected VEC3"),
    gltf_case("accessor-wrong-component", q("accessors.2.componentType", 5125), "accessor 2 (TEXCOORD_0) is VEC2 of U32"),
    gltf_case("accessor-view-missing", q("accessors.1.bufferView", 99), "accessors[1].bufferView: Index out of bounds"),
    gltf_case("position-accessor-missing", q("meshes.0.primitives.0.attributes.POSITION", 42), "POSITION: Index out of bounds"),
    gltf_case("indices-accessor-missing", q("meshes.0.primitives.0.indices", 42), "indices: Index out of bounds"),
    gltf_case("accessor-count-zero", q("accessors.3.count", 0), "accessor 3 (indices) has no elements (count 0)"),
    gltf_case("attribute-count-mismatch", q("accessors.1.count", 3), "accessor 1 (NORMAL) has 3 elements but POSITION has 4"),
    gltf_case("no-position", q("meshes.0.primitives.0.attributes.POSITION", None), 'meshes[0].primitives[0].attributes["POSITION"]: Missing data'),
    gltf_case("mode-lines", q("meshes.0.primitives.0.mode", 1), "mode Lines is not supported"),
    # extensions: one the cooker does not implement, if required, is refused by name
    gltf_case("extension-required-unsupported", lambda: {**quad_doc(False), "extensionsUsed": ["KHR_draco_mesh_compression"],
                                                         "extensionsRequired": ["KHR_draco_mesh_compression"]},
              "requires extension 'KHR_draco_mesh_compression', which the cooker does not support"),
    # indices
    gltf_case("index-beyond-vertex-count", lambda: set_index(quad_doc(False), 4, 4), "accessor 3 (indices) element 4 is 4, but there are only 4 vertices"),
    gltf_case("index-u32-max", lambda: set_index(quad_doc(False), 0, 2**32 - 1), "accessor 3 (indices) element 0 is 4294967295"),
    gltf_case("indices-not-whole-triangles", q("accessors.3.count", 5), "5 indices do not make whole triangles"),
    gltf_case("indices-float", q("accessors.3.componentType", 5126), "accessor 3 (indices) is SCALAR of F32"),
    # values
    gltf_case("position-nan", lambda: set_position(quad_doc(False), 2, float("nan")), "accessor 0 (POSITION) element 2 is not a finite number"),
    gltf_case("position-inf", lambda: set_position(quad_doc(False), 1, float("inf")), "accessor 0 (POSITION) element 1 is not a finite number"),
    glb_case("position-minus-inf", lambda: glb_bytes(set_position(quad_doc(False), 3, float("-inf"))), "accessor 0 (POSITION) element 3 is not a finite number"),
    gltf_case("normal-nan", lambda: set_float(quad_doc(False), 1, 8, float("nan")), "accessor 1 (NORMAL) element 0 is not a finite number"),
    gltf_case("uv-inf", lambda: set_float(quad_doc(False), 2, 12, float("inf")), "accessor 2 (TEXCOORD_0) element 1 is not a finite number"),
    # sparse accessors
    gltf_case("sparse-index-out-of-range", lambda: sparse_doc(index_values=(1, 9)), "accessor 0 (POSITION): sparse index 1 is 9, past the accessor's 4 elements"),
    gltf_case("sparse-indices-not-increasing", lambda: sparse_doc(index_values=(2, 1)), "sparse indices are not strictly increasing"),
    gltf_case("sparse-count-over-accessor", lambda: sparse_doc(count=5), "sparse count 5 is not in 1..=4"),
    gltf_case("sparse-values-view-short", lambda: edit(sparse_doc(), "bufferViews.5.byteLength", 12), "accessor 0 (POSITION) sparse values needs 24 bytes but buffer view 5 holds 12"),
    gltf_case("sparse-absurd-count",
              lambda: edit(edit(edit(sparse_doc(), "accessors.0.count", 60_000_000), "accessors.0.bufferView", None), "meshes.0.primitives.0", {"attributes": {"POSITION": 0}}),
              "more than the cooker's limit"),
    # node graphs
    gltf_case("node-cycle", lambda: nodes_doc([{"mesh": 0, "children": [1]}, {"children": [0]}], [0]), "node 0 is reached twice in the scene"),
    gltf_case("node-own-child", lambda: nodes_doc([{"mesh": 0, "children": [0]}], [0]), "node 0 is reached twice"),
    gltf_case("node-two-parents", lambda: nodes_doc([{"children": [2]}, {"children": [2]}, {"mesh": 0}], [0, 1]), "node 2 is reached twice"),
    gltf_case("node-child-missing", lambda: nodes_doc([{"mesh": 0, "children": [7]}], [0]), "nodes[0].children[0]: Index out of bounds"),
    gltf_case("scene-node-missing", lambda: nodes_doc([{"mesh": 0}], [3]), "scenes[0].nodes[0]: Index out of bounds"),
    gltf_case("node-mesh-missing", lambda: nodes_doc([{"mesh": 5}], [0]), "nodes[0].mesh: Index out of bounds"),
    # absurd amounts from a small file
    gltf_case("primitives-amplified", lambda: amplified_doc(primitives=3000, vertices=30_000), "more than the cooker's limit"),
    gltf_case("morph-targets-amplified", lambda: amplified_doc(primitives=1, vertices=30_000, targets=3000), "more than the cooker's limit"),
    # images
    gltf_case("image-truncated-png", lambda: with_image(quad_doc(), png(64, 64)[:60]), "image 0 (base colour of material 0 'm'): cannot decode"),
    gltf_case("image-truncated-jpeg", lambda: with_image(quad_doc(), jpeg()[:200], "image/jpeg"), "image 0 (base colour of material 0 'm'): cannot decode"),
    gltf_case("image-size-disagrees-with-data", lambda: with_image(quad_doc(), png_claiming(64, 64)), "image 0", "cannot decode"),
    gltf_case("image-zero-size", lambda: with_image(quad_doc(), png_claiming(0, 0)), "image 0", "cannot decode"),
    # Refused from the header, before the decoder allocates 40 GB.
    gltf_case("image-dimensions-absurd", lambda: with_image(quad_doc(), png_claiming(100_000, 100_000)), "image 0", "100000 x 100000 texels, larger than the 16384"),
    gltf_case("image-too-wide", lambda: with_image(quad_doc(), png(16400, 1)), "image 0 (base colour of material 0 'm'): 16400 x 1 texels, larger than the 16384"),
    gltf_case("image-missing-file", lambda: edit(quad_doc(), "images.0", {"uri": "textures/missing.png"}), "image 0 (base colour of material 0 'm'): cannot read", "missing.png"),
    gltf_case("image-not-an-image", lambda: with_image(quad_doc(), b"<html>not found</html>", via_view=True), "image 0", "cannot decode"),
    gltf_case("image-mime-unsupported", lambda: with_image(quad_doc(), b"GIF89a\x01\x00\x01\x00\x00\x00\x00;", "image/gif", via_view=True),
              "image 0", "cannot decode: The image format Gif is not supported"),
    gltf_case("image-mime-ktx2", lambda: with_image(quad_doc(), b"\xabKTX 20\xbb\r\n\x1a\n" + bytes(64), "image/ktx2", via_view=True), "image 0", "cannot decode"),
    gltf_case("image-view-missing", lambda: edit(quad_doc(), "images.0", {"bufferView": 40, "mimeType": "image/png"}), "images[0].bufferView: Index out of bounds"),
    gltf_case("image-no-source", lambda: edit(quad_doc(), "images.0", {"name": "nothing"}), "image 0 'nothing'", "has neither a uri nor a bufferView"),
    gltf_case("texture-source-missing", q("textures.0.source", 9, texture=True), "textures[0].source: Index out of bounds"),
    # animation and skins
    gltf_case("anim-times-not-increasing", lambda: animated_doc([0, 1, 0.5], [0] * 9), "animation 0 'move' channel 0", "key times are not strictly increasing"),
    gltf_case("anim-time-nan", lambda: animated_doc([0, float("nan")], [0] * 6), "animation 0 'move' channel 0", "not a finite number"),
    gltf_case("anim-output-count", lambda: animated_doc([0, 1, 2], [0] * 6), "animation 0 'move' channel 0", "2 output values for 3 keys"),
    gltf_case("skin-joint-outside-scene", lambda: edit(edit(quad_doc(False), "nodes", [{"mesh": 0}, {"name": "orphan"}]), "skins", [{"joints": [1]}]),
              "skin 0: joint node 1 'orphan' is not in the scene"),
    # the Khronos sample with a sparse accessor, its sparse index pointed past the end
    Case("sample-sparse-index-out-of-range", lambda d: sample_with_sparse_index(d, 200),
         ["accessor 1 (POSITION): sparse index 2 is 200, past the accessor's 14 elements"]),
]


# ---- paths that reach outside the asset's folder --------------------------------------------------
# A downloaded asset must not carry the user's files away inside a cooked pack: buffer and image
# URIs stay inside the asset's folder tree (and a level's paths inside the level's), unless
# --allow-external-uris. Each case puts a real file outside the folder, so only the rule stops it.


def outside_case(name: str, uri: str, kind: str, fragment: str) -> Case:
    """A .gltf in d/asset/ whose buffer 0 or image 0 URI (`uri`, with {outside} replaced by the
    absolute folder d/) names a file that exists in d/, outside the asset's folder."""
    def make(d: Path) -> Path:
        asset = d / "asset"
        asset.mkdir()
        doc = quad_doc(texture=kind == "image")
        blob = bytes(get_blob(doc))
        (d / "secret.bin").write_bytes(blob)
        (d / "secret.png").write_bytes(png(4, 4))
        target = uri.replace("{outside}", d.resolve().as_posix())
        if kind == "buffer":
            doc["buffers"][0] = {"byteLength": len(blob), "uri": target}
        else:
            doc["images"][0] = {"uri": target}
        p = asset / f"{name}.gltf"
        p.write_text(json.dumps(doc))
        return p
    return Case(f"outside-{name}", make, [fragment, "reaches outside the asset's folder", "--allow-external-uris"])


def outside_level_case(name: str, extra: str, fragment: str, files: dict[str, Callable[[], bytes]]) -> Case:
    """A level in d/level/ naming a file (`files`, written relative to d/level/, so '../x' lands
    in d/) that lies outside the level's folder."""
    def make(d: Path) -> Path:
        level = d / "level"
        level.mkdir()
        for n, data in files.items():
            (level / n).resolve().parent.mkdir(parents=True, exist_ok=True)
            (level / n).resolve().write_bytes(data())
        p = level / f"{name}.toml"
        p.write_text(LEVEL + textwrap.dedent(extra).replace("{outside}", d.resolve().as_posix()))
        return p
    return Case(f"outside-level-{name}", make, [fragment, "reaches outside the level's folder", "--allow-external-uris"])


OUTSIDE_CASES = [
    outside_case("buffer-dotdot", "../secret.bin", "buffer", "buffer 0: URI '../secret.bin'"),
    outside_case("buffer-dotdot-inside-first", "sub/../../secret.bin", "buffer", "buffer 0: URI 'sub/../../secret.bin'"),
    outside_case("buffer-absolute", "{outside}/secret.bin", "buffer", "buffer 0: URI '/"),
    outside_case("buffer-file-uri", "file://{outside}/secret.bin", "buffer", "buffer 0: URI 'file://"),
    outside_case("image-dotdot", "../secret.png", "image", "image 0"),
    outside_case("image-absolute", "{outside}/secret.png", "image", "image 0"),
    outside_case("image-file-uri", "file:{outside}/secret.png", "image", "image 0"),
]


# ---- levels -------------------------------------------------------------------------------------

LEVEL = """
[level]
name = "bad"
texels_per_metre = 4

[[materials]]
name = "stone"

[[brushes]]
name = "b"
kind = "box"
size = [1, 1, 1]
material = "stone"

[[brushes]]
name = "c"
kind = "box"
size = [0.5, 2, 0.5]
material = "stone"

[[objects]]
name = "o"
op = "difference"
operands = ["b", "c"]
"""


def level_case(name: str, change: Callable[[str], str], *fragments: str, files: dict[str, bytes] | None = None,
               named: str | None = None) -> Case:
    """`change(LEVEL)` is the level; `files` are written beside it; the error names `named`
    (a file beside the level) or the level itself."""
    def make(d: Path) -> Path:
        for n, data in (files or {}).items():
            (d / n).parent.mkdir(parents=True, exist_ok=True)
            (d / n).write_bytes(data() if callable(data) else data)
        p = d / f"{name}.toml"
        text = change(LEVEL)
        p.write_bytes(text if isinstance(text, bytes) else text.encode())
        return p
    return Case(f"level-{name}", make, list(fragments), None if named is None else (lambda d: d / named))


def add(extra: str) -> Callable[[str], str]:
    return lambda s: s + textwrap.dedent(extra)


def sub(old: str, new: str) -> Callable[[str], str]:
    def change(s: str) -> str:
        assert old in s, old
        return s.replace(old, new, 1)
    return change


PROP = '\n[[props]]\nname = "statue"\ngltf = "statue.gltf"\n'
TEXTURED = '\n[[materials]]\nname = "tiles"\ntexture = "tiles.png"\n\n[[brushes]]\nname = "t"\nkind = "box"\nsize = [1, 1, 1]\ntranslation = [4, 0, 0]\nmaterial = "tiles"\n\n[[objects]]\nname = "tiled"\nop = "union"\noperands = ["t"]\n'

LEVEL_CASES = [
    level_case("toml-syntax", add('\n[[brushes]]\nname = "x\n'), f".toml:{len(LEVEL.splitlines()) + 3}:", "Illegal character"),
    level_case("not-utf8", lambda s: s.encode() + b'\n# \xff\xfe\n', "cannot read the level"),
    level_case("unknown-top-level-key", add('\n[[brushs]]\nname = "x"\n'), "brushs: unknown key 'brushs'"),
    level_case("unknown-brush-key", sub('size = [1, 1, 1]', 'size = [1, 1, 1]\ncolour = "red"'), "brushes[0].colour: unknown key 'colour' for a box brush"),
    level_case("unknown-level-key", sub('texels_per_metre = 4', 'texels_per_metre = 4\ngravity = 9.8'), "level.gravity: unknown key 'gravity'"),
    level_case("operand-unknown", sub('operands = ["b", "c"]', 'operands = ["b", "nope"]'), "objects[0].operands[1]: 'nope' is not a brush or an object defined above"),
    level_case("operand-itself", sub('operands = ["b", "c"]', 'operands = ["b", "o"]'), "objects[0].operands[1]: object 'o' cannot be its own operand"),
    level_case("operand-defined-later", add('\n[[objects]]\nname = "p"\nop = "union"\noperands = ["q"]\n\n[[objects]]\nname = "q"\nop = "union"\noperands = ["b"]\n'),
               "objects[1].operands[0]", "defined before they are used"),
    level_case("operands-empty", sub('operands = ["b", "c"]', 'operands = []'), "objects[0].operands: expected a non-empty array of names"),
    level_case("operands-not-names", sub('operands = ["b", "c"]', 'operands = ["b", 3]'), "objects[0].operands[1]: expected a non-empty string"),
    level_case("difference-one-operand", sub('operands = ["b", "c"]', 'operands = ["b"]'), "objects[0].operands: a difference needs at least two operands"),
    level_case("op-unknown", sub('op = "difference"', 'op = "xor"'), "objects[0].op: unknown value 'xor'"),
    level_case("result-empty", sub('size = [0.5, 2, 0.5]', 'size = [3, 3, 3]'), "object 'o': the difference of b, c is empty"),
    level_case("size-negative", sub('size = [1, 1, 1]', 'size = [1, -2, 1]'), "brushes[0].size: must be > 0, got -2"),
    level_case("size-nan", sub('size = [1, 1, 1]', 'size = [1, nan, 1]'), "brushes[0].size: expected a number"),
    level_case("translation-inf", sub('material = "stone"', 'material = "stone"\ntranslation = [inf, 0, 0]'), "brushes[0].translation: expected a number"),
    level_case("scale-zero", sub('material = "stone"', 'material = "stone"\nscale = [1, 0, 1]'), "brushes[0].scale: must be > 0, got 0"),
    level_case("size-a-string", sub('size = [1, 1, 1]', 'size = "big"'), "brushes[0].size: expected an array of 3 numbers, got a string"),
    level_case("brush-kind-unknown", sub('kind = "box"', 'kind = "torus"'), "brushes[0].kind: unknown value 'torus'"),
    level_case("extrude-two-points", sub('kind = "box"\nsize = [1, 1, 1]', 'kind = "extrude"\nheight = 1\npoints = [[0, 0], [1, 0]]'), "brushes[0].points: expected an array of at least 3"),
    level_case("extrude-no-area", sub('kind = "box"\nsize = [1, 1, 1]', 'kind = "extrude"\nheight = 1\npoints = [[0, 0], [1, 0], [2, 0]]'), "brushes[0].points: the polygon has no area"),
    level_case("segments-absurd", sub('kind = "box"\nsize = [1, 1, 1]', 'kind = "cylinder"\nradius = 1\nheight = 1\nsegments = 1000000000'), "brushes[0].segments", "more than the cooker's limit"),
    level_case("repeat-absurd", sub('material = "stone"', 'material = "stone"\nrepeat = { count = 1000000000, step = [2, 0, 0] }'), "brushes[0].repeat.count", "more than the cooker's limit"),
    level_case("texels-per-metre-absurd", sub('texels_per_metre = 4', 'texels_per_metre = 1e9'), "uv2: o:", "more than the cooker's limit", "lower texels_per_metre"),
    level_case("material-unknown", sub('size = [1, 1, 1]\nmaterial = "stone"', 'size = [1, 1, 1]\nmaterial = "granite"'), "brushes[0].material: unknown material 'granite'"),
    level_case("name-duplicate", sub('name = "c"', 'name = "b"'), "brushes[1].name: 'b' is already the name of brushes[0]"),
    level_case("no-objects", lambda s: s[:s.index("[[objects]]")], "objects: a level needs at least one [[objects]] or [[props]] entry"),
    level_case("light-zero-direction", add('\n[[lights]]\nname = "sun"\nkind = "sun"\nintensity = 1000\ndirection = [0, 0, 0]\n'), "lights[0].direction: must not be the zero vector"),
    level_case("spawn-param-unknown", add('\n[[spawns]]\nname = "p"\nkind = "player"\nparams = { jump = 3 }\n'), "spawns[0].params.jump: unknown parameter 'jump'"),
    level_case("texture-missing", add(TEXTURED), "materials[1].texture: texture file 'tiles.png' not found"),
    level_case("texture-not-png", add(TEXTURED.replace("tiles.png", "tiles.jpg")), "materials[1].texture: texture files must be PNG"),
    level_case("texture-truncated-png", add(TEXTURED), "cannot decode image", files={"tiles.png": lambda: png(32, 32)[:50]}, named="tiles.png"),
    level_case("texture-dimensions-absurd", add(TEXTURED), "100000 x 100000 texels, larger than the 16384", files={"tiles.png": lambda: png_claiming(100_000, 100_000)}, named="tiles.png"),
    level_case("texture-too-tall", add(TEXTURED), "1 x 20000 texels, larger than the 16384", files={"tiles.png": lambda: png(1, 20000)}, named="tiles.png"),
    level_case("prop-missing", add(PROP), "props[0].gltf: prop file 'statue.gltf' not found"),
    level_case("prop-broken", add(PROP), "accessor 0 (POSITION) element 2 is not a finite number",
               files={"statue.gltf": lambda: json.dumps(set_position(quad_doc(False), 2, float("nan"))).encode()}, named="statue.gltf"),
    level_case("character-asset-broken", add('\n[[spawns]]\nname = "hero"\nkind = "character"\nparams = { asset = "hero.glb" }\n'),
               "spawns[0].params.asset: character 'hero': cannot import 'hero.glb'", files={"hero.glb": lambda: GLB()[:100]}),
]

def texture_at(path: str) -> str:
    return TEXTURED.replace('"tiles.png"', f'"{path}"')


LEVEL_OUTSIDE_CASES = [
    outside_level_case("texture-dotdot", texture_at("../tiles.png"), "materials[1].texture: texture file '../tiles.png'",
                       {"../tiles.png": lambda: png(4, 4)}),
    outside_level_case("texture-absolute", texture_at("{outside}/tiles.png"), "materials[1].texture: texture file '/",
                       {"../tiles.png": lambda: png(4, 4)}),
    outside_level_case("prop-dotdot", PROP.replace("statue.gltf", "../statue.gltf"), "props[0].gltf: prop file '../statue.gltf'",
                       {"../statue.gltf": lambda: json.dumps(quad_doc(False)).encode()}),
    outside_level_case("character-dotdot", '\n[[spawns]]\nname = "hero"\nkind = "character"\nparams = { asset = "../hero.glb" }\n',
                       "spawns[0].params.asset: character 'hero': asset '../hero.glb'", {"../hero.glb": GLB}),
]


def prop_buffer_outside_level(d: Path) -> Path:
    """A prop inside the level's folder whose buffer lies outside it: the prop's URIs may not
    leave the level's folder tree either."""
    level = d / "level"
    (level / "props").mkdir(parents=True)
    doc = quad_doc(False)
    blob = bytes(get_blob(doc))
    (d / "secret.bin").write_bytes(blob)
    doc["buffers"][0] = {"byteLength": len(blob), "uri": "../../secret.bin"}
    (level / "props" / "statue.gltf").write_text(json.dumps(doc))
    p = level / "prop-buffer.toml"
    p.write_text(LEVEL + PROP.replace("statue.gltf", "props/statue.gltf"))
    return p


LEVEL_OUTSIDE_CASES.append(Case("outside-level-prop-buffer", prop_buffer_outside_level,
                                ["buffer 0: URI '../../secret.bin' reaches outside the asset's folder", "--allow-external-uris"],
                                lambda d: d / "level" / "props" / "statue.gltf"))

CASES = GLTF_CASES + OUTSIDE_CASES + LEVEL_CASES + LEVEL_OUTSIDE_CASES


@pytest.fixture(scope="module")
def cooked_cases(tmp_path_factory) -> dict:
    """Every case made in its own directory and cooked, a few cooks at a time (most of a failing
    cook is the interpreter starting): name -> (directory, source, CompletedProcess)."""
    from concurrent.futures import ThreadPoolExecutor

    def run(case: Case):
        d = tmp_path_factory.mktemp(case.name)
        try:
            src = case.make(d)
        except pytest.skip.Exception as e:
            return case.name, (d, None, e)
        return case.name, (d, src, run_limited([COOK, src, "-o", d / "out.pack", "-q"]))

    with ThreadPoolExecutor(max_workers=4) as pool:
        return dict(pool.map(run, CASES))


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.name)
def test_bad_input_fails_cleanly(case, cooked_cases):
    d, src, r = cooked_cases[case.name]
    if src is None:
        pytest.skip(str(r))
    assert_clean_failure(r, "cook", case.named(d) if case.named else src, case.fragments, d / "out.pack")


# ---- packs handed to the runtime --------------------------------------------------------------

HEADER_LEN = 64


def crc_fixed(b: bytes) -> bytes:
    """Recompute the checksum (CRC-32 of the file with its checksum field as zero)."""
    b = bytearray(b)
    b[56:60] = b"\0\0\0\0"
    struct.pack_into("<I", b, 56, zlib.crc32(bytes(b)))
    return bytes(b)


def split_pack(b: bytes) -> tuple[dict, bytes]:
    """(manifest, data blob decoded): a cooked pack stores its blob zstd-compressed (header
    word 60 = 1), which the pack crate decodes."""
    import tempfile

    from asset_pipeline import _core

    meta_off, meta_len, data_off, data_len = struct.unpack_from("<4Q", b, 24)
    if struct.unpack_from("<I", b, 60)[0] == 0:
        return json.loads(b[meta_off:meta_off + meta_len]), b[data_off:data_off + data_len]
    with tempfile.TemporaryDirectory() as t:
        (Path(t) / "p.pack").write_bytes(b)
        _, data = _core.read_pack(Path(t) / "p.pack")
    return json.loads(b[meta_off:meta_off + meta_len]), data


def forge(b: bytes, manifest: Callable[[dict], object] = lambda m: None, data: Callable[[bytearray, dict], object] = lambda d, m: None,
          raw_meta: bytes | None = None) -> bytes:
    """A pack with an edited manifest and/or data blob, re-laid out (the blob stored as it is)
    and with a valid checksum, so only the reader's consistency checks stand between it and
    the GPU."""
    m, d = split_pack(b)
    d = bytearray(d)
    manifest(m)
    data(d, m)
    meta = raw_meta if raw_meta is not None else json.dumps(m).encode()
    data_off = -(-(HEADER_LEN + len(meta)) // 16) * 16
    out = bytearray(b[:HEADER_LEN]) + meta + b"\0" * (data_off - HEADER_LEN - len(meta)) + d
    struct.pack_into("<5Q", out, 16, len(out), HEADER_LEN, len(meta), data_off, len(d))
    struct.pack_into("<I", out, 60, 0)
    return crc_fixed(bytes(out))


def set_index_in_data(d: bytearray, m: dict, value: int) -> None:
    lod = m["meshes"][0]["lods"][0]
    struct.pack_into({"u16": "<H", "u32": "<I"}[lod["index_format"]], d, lod["indices"]["offset"] + {"u16": 2, "u32": 4}[lod["index_format"]], value)


def flip(b: bytes, at: int) -> bytes:
    b = bytearray(b)
    b[at] ^= 0x40
    return bytes(b)


PACK_CASES = {
    "empty": (lambda p: b"", "not a pack file"),
    "png-named-pack": (lambda p: png(), "not a pack file"),
    "truncated-header": (lambda p: p[:20], "truncated pack"),
    "truncated-body": (lambda p: p[:-100], "truncated pack: the header says"),
    "future-version": (lambda p: patch(p, 8, "<I", 99), "pack format version 99 is not supported"),
    # A pack from the build before 16-bit indices (format 6): the message says what to do.
    "old-version": (lambda p: patch(p, 8, "<I", 6), "pack format version 6 is not supported (this build reads version 11); re-cook the content"),
    "data-encoding-unknown": (lambda p: crc_fixed(patch(p, 60, "<I", 7)), "data encoding 7 is unknown"),
    "data-not-zstd": (lambda p: crc_fixed(patch(forge(p), 60, "<I", 1)), "data: not a zstd frame"),
    "index-format-unknown": (lambda p: forge(p, lambda m: m["meshes"][0]["lods"][0].update(index_format="u8")), "malformed pack: metadata"),
    "index-format-too-wide": (lambda p: forge(p, lambda m: m["meshes"][0]["lods"][0].update(index_format="u32")), "bytes stored but"),
    "flipped-data-byte": (lambda p: flip(p, len(p) - 7), "checksum mismatch"),
    "flipped-header-byte": (lambda p: flip(p, 30), "checksum mismatch"),
    "trailing-bytes": (lambda p: p + b"\0" * 16, "unexpected trailing bytes"),
    "section-outside-file": (lambda p: crc_fixed(patch(p, 40, "<Q", 1 << 40)), "data section"),
    "metadata-not-json": (lambda p: forge(p, raw_meta=b"{not json"), "malformed pack: metadata"),
    "metadata-wrong-shape": (lambda p: forge(p, raw_meta=b'{"meshes": 3}'), "malformed pack: metadata"),
    "vertices-outside-data": (lambda p: forge(p, lambda m: m["meshes"][0]["lods"][0]["vertices"].update(offset=1 << 30)), "lies outside the data"),
    "vertex-count-huge": (lambda p: forge(p, lambda m: m["meshes"][0]["lods"][0].update(vertex_count=2**32 - 1)), "bytes stored but"),
    "index-beyond-vertices": (lambda p: forge(p, data=lambda d, m: set_index_in_data(d, m, 1000)), "index"),
    "submesh-material-missing": (lambda p: forge(p, lambda m: m["meshes"][0]["lods"][0]["submeshes"][0].update(material=50)), "material 50 does not exist"),
    "node-parent-cycle": (lambda p: forge(p, lambda m: m["nodes"][0].update(parent=0)), "parent 0 does not precede it"),
    "node-mesh-missing": (lambda p: forge(p, lambda m: m["nodes"][0].update(mesh=9)), "mesh 9 does not exist"),
    "texture-missing": (lambda p: forge(p, lambda m: m["materials"][0].update(base_color_texture=7)), "texture 7 does not exist"),
    "texture-size-mismatch": (lambda p: forge(p, lambda m: m["textures"][0].update(width=8)), "texture 0"),
}


@pytest.fixture(scope="module")
def good_pack(tmp_path_factory) -> bytes:
    d = tmp_path_factory.mktemp("pack")
    src = d / "quad.gltf"
    src.write_text(json.dumps(quad_doc()))
    r = run_limited([COOK, src, "-o", d / "quad.pack", "-q", "--no-report"])
    assert r.returncode == 0, r.stderr
    return (d / "quad.pack").read_bytes()


@pytest.mark.parametrize("name", PACK_CASES)
def test_bad_pack_is_rejected_by_reader_and_runtime(name, good_pack, tmp_path):
    import asset_pipeline

    make, fragment = PACK_CASES[name]
    path = tmp_path / f"{name}.pack"
    path.write_bytes(make(good_pack))
    with pytest.raises(asset_pipeline.CookError) as e:
        asset_pipeline._core.read_pack_manifest(path)
    assert str(path) in str(e.value) and fragment in str(e.value), str(e.value)
    assert DEMO.exists(), f"{DEMO} is built by `make build`"
    r = run_limited([DEMO, path, "--headless", "--frames", "1", "--width", "32", "--height", "32", "--screenshot", tmp_path / "x.png"], timeout=60)
    assert_clean_failure(r, "demo", path, [fragment])
    assert not (tmp_path / "x.png").exists()


def test_corpus_size():
    """The issue asks for at least 50 hand-made bad inputs across glTF, levels, images and packs."""
    images = [c for c in CASES if "image" in c.name or "texture" in c.name]
    assert len(CASES) + len(PACK_CASES) >= 50
    assert len(images) >= 8 and len(LEVEL_CASES) >= 20 and len(PACK_CASES) >= 15
