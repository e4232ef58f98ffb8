"""glTF 2.0 (.gltf/.glb) -> scene IR, through the Rust core's importer."""

from __future__ import annotations

import os

import numpy as np

from asset_pipeline import _core, ir


def arrays_from_wire(raw) -> list[np.ndarray]:
    """(dtype, shape, bytes) triples from the Rust core -> numpy arrays (no copy)."""
    return [np.frombuffer(b, dtype=np.dtype(d)).reshape(shape) for d, shape, b in raw]


def arrays_to_wire(arrays: list[np.ndarray]) -> list[tuple[str, tuple[int, ...], bytes]]:
    """numpy arrays -> (dtype, shape, bytes) triples for the Rust core (little-endian)."""
    out = []
    for a in arrays:
        a = np.ascontiguousarray(a)
        if a.dtype.byteorder == ">":
            a = a.astype(a.dtype.newbyteorder("<"))
        out.append((a.dtype.str, a.shape, a.tobytes()))
    return out


def import_gltf(path: str | os.PathLike, root: str | os.PathLike | None = None, allow_external_uris: bool = False) -> ir.Scene:
    """Import a glTF file. Its buffer and image URIs must stay inside `root` (default: the
    file's own folder) unless `allow_external_uris`. The scene's `files` lists every file read.
    Raises asset_pipeline.CookError naming the file and the problem."""
    text, raw, files = _core.import_gltf(os.fspath(path), None if root is None else os.fspath(root), allow_external_uris)
    scene = ir.from_wire(text, arrays_from_wire(raw))
    scene.files = [os.fspath(f) for f in files]
    return scene


def write_pack(scene: ir.Scene, out: str | os.PathLike) -> dict:
    """Write the pack for `scene` atomically; returns the Rust core's summary."""
    text, arrays = ir.to_wire(scene)
    return _core.write_pack(text, arrays_to_wire(arrays), os.fspath(out))


def decode_image(path: str | os.PathLike) -> np.ndarray:
    """A PNG/JPEG file as an (h, w, 4) uint8 RGBA array."""
    w, h, data = _core.decode_image(os.fspath(path))
    return np.frombuffer(data, dtype=np.uint8).reshape(h, w, 4)
