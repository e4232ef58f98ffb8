"""A small glTF 2.0 writer for the project's generated content: one self-contained .gltf with
the binary data and images as data: URIs. Used by content/demo/make_scene.py and
content/characters/make_creature.py (standard library + numpy only, so `make cook` needs nothing
else).
"""

import base64
import json
import struct
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


class GltfWriter:
    """Collects meshes, materials and images into one self-contained .gltf (data: URIs)."""

    def __init__(self, generator: str):
        self.blob = bytearray()
        self.doc = {
            "asset": {"version": "2.0", "generator": generator},
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

    def accessor(self, array: np.ndarray, kind: str, component: int, target: int | None = None, minmax=False) -> int:
        """One accessor over a new buffer view of `array` (rows = elements)."""
        acc = {"bufferView": self._view(np.ascontiguousarray(array).tobytes(), target), "componentType": component, "count": len(array), "type": kind}
        if minmax:
            acc["min"] = array.min(0).tolist()
            acc["max"] = array.max(0).tolist()
        self.doc["accessors"].append(acc)
        return len(self.doc["accessors"]) - 1

    def mesh(self, name, pos, nrm, uv, idx, material) -> int:
        attrs = {
            "POSITION": self.accessor(pos, "VEC3", 5126, 34962, minmax=True),
            "NORMAL": self.accessor(nrm, "VEC3", 5126, 34962),
            "TEXCOORD_0": self.accessor(uv, "VEC2", 5126, 34962),
        }
        prim = {"attributes": attrs, "indices": self.accessor(idx, "SCALAR", 5125, 34963), "material": material}
        self.doc["meshes"].append({"name": name, "primitives": [prim]})
        return len(self.doc["meshes"]) - 1

    def texture(self, name, rgba) -> int:
        self.doc["images"].append({"name": name, "uri": "data:image/png;base64," + base64.b64encode(png_bytes(rgba)).decode()})
        self.doc["textures"].append({"source": len(self.doc["images"]) - 1, "sampler": 0})
        return len(self.doc["textures"]) - 1

    def material(self, name, color=(1, 1, 1, 1), texture=None, double_sided=False, roughness=0.9, normal=None, occlusion_roughness=None) -> int:
        """A metallic-roughness material; `normal` a normal map's texture, `occlusion_roughness`
        one texture as both the occlusion (R) and the metallic-roughness (G, B) map."""
        pbr = {"baseColorFactor": list(color), "metallicFactor": 0.0, "roughnessFactor": roughness}
        if texture is not None:
            pbr["baseColorTexture"] = {"index": texture}
        material = {"name": name, "pbrMetallicRoughness": pbr, "doubleSided": double_sided}
        if normal is not None:
            material["normalTexture"] = {"index": normal}
        if occlusion_roughness is not None:
            pbr["metallicRoughnessTexture"] = {"index": occlusion_roughness}
            material["occlusionTexture"] = {"index": occlusion_roughness}
        self.doc["materials"].append(material)
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

    def write(self, path: Path, external: bool = False):
        """Write the .gltf at `path`: self-contained (data: URIs), or with `external` the buffer as
        `<stem>.bin` and each image as `<stem>.image<N>.png` beside it."""
        path.parent.mkdir(parents=True, exist_ok=True)
        if external:
            (path.parent / f"{path.stem}.bin").write_bytes(bytes(self.blob))
            self.doc["buffers"] = [{"byteLength": len(self.blob), "uri": f"{path.stem}.bin"}]
            for i, image in enumerate(self.doc["images"]):
                if image.get("uri", "").startswith("data:"):
                    (path.parent / f"{path.stem}.image{i}.png").write_bytes(base64.b64decode(image["uri"].split(",", 1)[1]))
                    image["uri"] = f"{path.stem}.image{i}.png"
        else:
            self.doc["buffers"] = [{"byteLength": len(self.blob), "uri": "data:application/octet-stream;base64," + base64.b64encode(bytes(self.blob)).decode()}]
        if not self.doc["textures"]:
            self.doc["samplers"] = []
        self.doc = {k: v for k, v in self.doc.items() if v != []}
        tmp = path.with_suffix(path.suffix + ".tmp")
        tmp.write_text(json.dumps(self.doc, indent=1))
        tmp.replace(path)
