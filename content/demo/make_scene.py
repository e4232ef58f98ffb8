"""Author the project's demo scene as a glTF 2.0 file: a paved yard with a colonnade and crates.

This is the project's own content (no third-party assets), generated so that it stays small in
git and exercises the cooker's glTF path: several meshes and materials, textures, a node
hierarchy, a mirrored instance and a double-sided material. Levels authored as CSG brushes
replace it as the demo's main content once the CSG stage lands.

usage: python make_scene.py OUT.gltf
"""

import base64
import json
import struct
import sys
import zlib
from pathlib import Path

import numpy as np


def png_bytes(rgba: np.ndarray) -> bytes:
    """Encode an (h, w, 4) uint8 array as PNG with the standard library only."""
    h, w, _ = rgba.shape
    raw = b"".join(b"\x00" + rgba[y].tobytes() for y in range(h))

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    header = struct.pack(">IIBBBBB", w, h, 8, 6, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b"")


def paving_texture(size: int = 128) -> np.ndarray:
    """Square flagstones with dark grout and a little per-stone tint variation."""
    y, x = np.mgrid[0:size, 0:size]
    stone = (x // 32) * 7 + (y // 32) * 13
    tint = 150 + (stone * 37 % 40)
    grout = ((x % 32) < 2) | ((y % 32) < 2)
    base = np.where(grout, 70, tint).astype(np.uint8)
    rgba = np.stack([base, (base * 0.95).astype(np.uint8), (base * 0.85).astype(np.uint8), np.full_like(base, 255)], -1)
    return rgba


def plank_texture(size: int = 64) -> np.ndarray:
    """Horizontal wooden planks with a darker frame: reads as a crate."""
    y, x = np.mgrid[0:size, 0:size]
    plank = (y // 16) % 2
    frame = (x < 5) | (x >= size - 5) | (y < 5) | (y >= size - 5)
    r = np.where(frame, 95, np.where(plank, 170, 150))
    g = (r * 0.68).astype(np.int64)
    b = (r * 0.40).astype(np.int64)
    return np.stack([r, g, b, np.full_like(r, 255)], -1).astype(np.uint8)


def box_mesh(half: np.ndarray, uv_scale: float = 1.0):
    """A box with per-face normals and uvs, counter-clockwise seen from outside."""
    faces = [
        ((1, 0, 0), (0, 0, -1), (0, 1, 0)),
        ((-1, 0, 0), (0, 0, 1), (0, 1, 0)),
        ((0, 1, 0), (1, 0, 0), (0, 0, -1)),
        ((0, -1, 0), (1, 0, 0), (0, 0, 1)),
        ((0, 0, 1), (1, 0, 0), (0, 1, 0)),
        ((0, 0, -1), (-1, 0, 0), (0, 1, 0)),
    ]
    corners = np.array([(-1, -1), (1, -1), (1, 1), (-1, 1)], dtype=np.float32)
    pos, nrm, uv, idx = [], [], [], []
    for i, (n, u, v) in enumerate(faces):
        n, u, v = (np.array(a, dtype=np.float32) for a in (n, u, v))
        p = (n[None] + corners[:, :1] * u[None] + corners[:, 1:] * v[None]) * half[None]
        pos.append(p)
        nrm.append(np.repeat(n[None], 4, 0))
        uv.append(np.stack([(corners[:, 0] + 1) * 0.5, (1 - corners[:, 1]) * 0.5], -1) * uv_scale)
        idx.append(np.array([0, 1, 2, 0, 2, 3], dtype=np.uint32) + 4 * i)
    return np.concatenate(pos), np.concatenate(nrm), np.concatenate(uv).astype(np.float32), np.concatenate(idx)


class GltfWriter:
    """Collects meshes, materials and images into one self-contained .gltf (data: URIs)."""

    def __init__(self):
        self.blob = bytearray()
        self.doc = {
            "asset": {"version": "2.0", "generator": "content/demo/make_scene.py"},
            "scene": 0,
            "scenes": [{"nodes": []}],
            "nodes": [],
            "meshes": [],
            "materials": [],
            "textures": [],
            "images": [],
            "samplers": [{"magFilter": 9729, "minFilter": 9987, "wrapS": 10497, "wrapT": 10497}],
            "accessors": [],
            "bufferViews": [],
            "buffers": [],
        }

    def _view(self, data: bytes, target=None) -> int:
        while len(self.blob) % 4:
            self.blob.append(0)
        view = {"buffer": 0, "byteOffset": len(self.blob), "byteLength": len(data)}
        if target:
            view["target"] = target
        self.blob += data
        self.doc["bufferViews"].append(view)
        return len(self.doc["bufferViews"]) - 1

    def _accessor(self, array: np.ndarray, kind: str, component: int, target: int, minmax=False) -> int:
        acc = {"bufferView": self._view(np.ascontiguousarray(array).tobytes(), target), "componentType": component, "count": len(array), "type": kind}
        if minmax:
            acc["min"] = array.min(0).tolist()
            acc["max"] = array.max(0).tolist()
        self.doc["accessors"].append(acc)
        return len(self.doc["accessors"]) - 1

    def mesh(self, name, pos, nrm, uv, idx, material) -> int:
        attrs = {
            "POSITION": self._accessor(pos, "VEC3", 5126, 34962, minmax=True),
            "NORMAL": self._accessor(nrm, "VEC3", 5126, 34962),
            "TEXCOORD_0": self._accessor(uv, "VEC2", 5126, 34962),
        }
        prim = {"attributes": attrs, "indices": self._accessor(idx, "SCALAR", 5125, 34963), "material": material}
        self.doc["meshes"].append({"name": name, "primitives": [prim]})
        return len(self.doc["meshes"]) - 1

    def texture(self, name, rgba) -> int:
        self.doc["images"].append({"name": name, "uri": "data:image/png;base64," + base64.b64encode(png_bytes(rgba)).decode()})
        self.doc["textures"].append({"source": len(self.doc["images"]) - 1, "sampler": 0})
        return len(self.doc["textures"]) - 1

    def material(self, name, color=(1, 1, 1, 1), texture=None, double_sided=False, roughness=0.9) -> int:
        pbr = {"baseColorFactor": list(color), "metallicFactor": 0.0, "roughnessFactor": roughness}
        if texture is not None:
            pbr["baseColorTexture"] = {"index": texture}
        self.doc["materials"].append({"name": name, "pbrMetallicRoughness": pbr, "doubleSided": double_sided})
        return len(self.doc["materials"]) - 1

    def node(self, name, mesh=None, translation=None, rotation=None, scale=None, children=None, root=True) -> int:
        n = {"name": name}
        for key, value in (("mesh", mesh), ("translation", translation), ("rotation", rotation), ("scale", scale), ("children", children)):
            if value is not None:
                n[key] = value
        self.doc["nodes"].append(n)
        index = len(self.doc["nodes"]) - 1
        if root:
            self.doc["scenes"][0]["nodes"].append(index)
        return index

    def write(self, path: Path):
        self.doc["buffers"] = [{"byteLength": len(self.blob), "uri": "data:application/octet-stream;base64," + base64.b64encode(bytes(self.blob)).decode()}]
        self.doc = {k: v for k, v in self.doc.items() if v != []}
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(path.suffix + ".tmp")
        tmp.write_text(json.dumps(self.doc, indent=1))
        tmp.replace(path)


def build_scene() -> GltfWriter:
    g = GltfWriter()
    paving = g.material("paving", texture=g.texture("paving", paving_texture()))
    wood = g.material("crate", texture=g.texture("planks", plank_texture()))
    stone = g.material("sandstone", color=(0.78, 0.66, 0.48, 1.0))
    cloth = g.material("awning", color=(0.62, 0.12, 0.10, 1.0), double_sided=True)

    ground = g.mesh("ground", *box_mesh(np.array([10.0, 0.1, 10.0], np.float32), uv_scale=5.0), paving)
    pillar = g.mesh("pillar", *box_mesh(np.array([0.35, 2.0, 0.35], np.float32)), stone)
    lintel = g.mesh("lintel", *box_mesh(np.array([4.6, 0.3, 0.5], np.float32)), stone)
    crate = g.mesh("crate", *box_mesh(np.array([0.5, 0.5, 0.5], np.float32)), wood)
    # A single thin sheet: only visible from both sides because its material is double-sided.
    pos, nrm, uv, idx = box_mesh(np.array([1.5, 0.01, 1.0], np.float32))
    awning = g.mesh("awning", pos[8:12], nrm[8:12], uv[8:12], idx[:6], cloth)

    g.node("ground", ground, translation=[0, -0.1, 0])
    # The colonnade is a hierarchy: moving the parent moves every pillar and the lintel.
    kids = [g.node(f"pillar{i}", pillar, translation=[x, 2.0, 0], root=False) for i, x in enumerate((-4.0, -1.35, 1.35, 4.0))]
    kids.append(g.node("lintel", lintel, translation=[0, 4.3, 0], root=False))
    g.node("colonnade", children=kids, translation=[0, 0, -3.0])
    g.node("crate0", crate, translation=[2.2, 0.5, 1.2], rotation=[0, 0.2588190, 0, 0.9659258])
    g.node("crate1", crate, translation=[2.9, 0.5, 2.4])
    g.node("crate2", crate, translation=[2.5, 1.5, 1.8], rotation=[0, 0.3826834, 0, 0.9238795])
    # Mirrored instance (negative scale): the runtime must flip its winding, not cull it away.
    g.node("crate_mirrored", crate, translation=[-2.6, 0.5, 1.5], scale=[-1, 1, 1])
    g.node("awning", awning, translation=[-2.6, 2.4, 0.2], rotation=[0.1305262, 0, 0, 0.9914449])
    return g


def main(argv):
    if len(argv) != 2:
        print(__doc__.strip().splitlines()[-1], file=sys.stderr)
        return 2
    build_scene().write(Path(argv[1]))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
