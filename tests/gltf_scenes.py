"""Synthetic glTF scenes for the tests: quads, boxes and their materials, lights and cameras, built
on content/gltf_writer.py, with the extensions real files use written as glTF spells them.

    s = Scene()
    floor = s.quad_mesh("floor", size=(4, 4), material=s.material("grey", color=(0.5, 0.5, 0.5, 1)))
    s.node("floor", mesh=floor)
    s.point_light("lamp", position=(0, 2, 0), intensity=100)
    s.write(tmp_path / "scene.gltf")

Geometry helpers make +Y-up quads (front face = +Y unless turned by the node's rotation) and
boxes; every mesh has POSITION, NORMAL and TEXCOORD_0 (and TEXCOORD_1 when asked).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "content"))
from gltf_writer import GltfWriter, png_bytes  # noqa: E402,F401

FLOAT, UINT = 5126, 5125


def quaternion(axis, degrees: float) -> list[float]:
    """Unit quaternion (x, y, z, w) of a rotation about `axis`."""
    a = np.asarray(axis, np.float64)
    a = a / np.linalg.norm(a)
    h = math.radians(degrees) / 2
    return [*(a * math.sin(h)).tolist(), math.cos(h)]


class Scene(GltfWriter):
    """A GltfWriter with the pieces the tests need."""

    def __init__(self):
        super().__init__("tests/gltf_scenes.py")
        self.used: set[str] = set()

    def extension(self, name: str, required: bool = False) -> None:
        self.used.add(name)
        self.doc.setdefault("extensionsUsed", [])
        if name not in self.doc["extensionsUsed"]:
            self.doc["extensionsUsed"].append(name)
        if required:
            self.doc.setdefault("extensionsRequired", [])
            if name not in self.doc["extensionsRequired"]:
                self.doc["extensionsRequired"].append(name)

    # ---- geometry -------------------------------------------------------------------------------

    def mesh_arrays(self, name: str, pos, nrm, uv0, idx, material: int, uv1=None, color=None) -> int:
        f = lambda a: np.ascontiguousarray(a, np.float32)  # noqa: E731
        attrs = {
            "POSITION": self.accessor(f(pos), "VEC3", FLOAT, 34962, minmax=True),
            "NORMAL": self.accessor(f(nrm), "VEC3", FLOAT, 34962),
            "TEXCOORD_0": self.accessor(f(uv0), "VEC2", FLOAT, 34962),
        }
        if uv1 is not None:
            attrs["TEXCOORD_1"] = self.accessor(f(uv1), "VEC2", FLOAT, 34962)
        if color is not None:
            attrs["COLOR_0"] = self.accessor(f(color), "VEC4", FLOAT, 34962)
        prim = {"attributes": attrs, "indices": self.accessor(np.asarray(idx, np.uint32), "SCALAR", UINT, 34963), "material": material}
        self.doc["meshes"].append({"name": name, "primitives": [prim]})
        return len(self.doc["meshes"]) - 1

    def quad_mesh(self, name: str, size=(1.0, 1.0), material: int = 0, uv1=False, color=None, facing_down: bool = False) -> int:
        """A w x d quad in the XZ plane centred on the origin, facing +Y (or -Y). uv0 (0, 0) at
        (-w/2, -d/2), u along +X, v along +Z; uv1 is uv0 mirrored in u (1 - u, v)."""
        w, d = size
        pos = np.array([[-w / 2, 0, -d / 2], [w / 2, 0, -d / 2], [w / 2, 0, d / 2], [-w / 2, 0, d / 2]])
        uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float64)
        idx = [0, 2, 1, 0, 3, 2] if not facing_down else [0, 1, 2, 0, 2, 3]
        nrm = np.tile([0, -1 if facing_down else 1, 0], (4, 1))
        return self.mesh_arrays(name, pos, nrm, uv, idx, material, uv1=np.column_stack([1 - uv[:, 0], uv[:, 1]]) if uv1 else None,
                                color=None if color is None else np.tile(color, (4, 1)))

    def box_mesh(self, name: str, size=(1.0, 1.0, 1.0), material: int = 0, inward: bool = False) -> int:
        """An axis-aligned box centred on the origin, 4 vertices per face (hard edges), faces
        outward (or inward: a room seen from inside)."""
        half = np.asarray(size, np.float64) / 2
        pos, nrm, uv, idx = [], [], [], []
        for axis in range(3):
            for sign in (-1.0, 1.0):
                n = np.zeros(3)
                n[axis] = sign
                u = np.zeros(3)
                u[(axis + 1) % 3] = 1
                v = np.cross(n, u)
                base = len(pos)
                for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                    pos.append(half * (n + a * u + b * v))
                    nrm.append(-n if inward else n)
                    uv.append([(a + 1) / 2, (b + 1) / 2])
                idx += [base, base + 2, base + 1, base, base + 3, base + 2] if inward else [base, base + 1, base + 2, base, base + 2, base + 3]
        return self.mesh_arrays(name, pos, nrm, uv, idx, material)

    # ---- materials ------------------------------------------------------------------------------

    def material(self, name: str, color=(1, 1, 1, 1), texture: int | None = None, emissive=None, emissive_strength: float | None = None,
                 emissive_texture: int | None = None, double_sided: bool = False, alpha_mode: str | None = None, alpha_cutoff: float | None = None,
                 base_uv: dict | None = None, emissive_uv: dict | None = None) -> int:
        """A material; `base_uv` / `emissive_uv` are extra textureInfo fields for the slot, e.g.
        {"texCoord": 1} or {"extensions": {"KHR_texture_transform": {...}}}."""
        pbr = {"baseColorFactor": list(color), "metallicFactor": 0.0, "roughnessFactor": 1.0}
        if texture is not None:
            pbr["baseColorTexture"] = {"index": texture, **(base_uv or {})}
        m = {"name": name, "pbrMetallicRoughness": pbr, "doubleSided": double_sided}
        if emissive is not None:
            m["emissiveFactor"] = list(emissive)
        if emissive_texture is not None:
            m["emissiveTexture"] = {"index": emissive_texture, **(emissive_uv or {})}
        if emissive_strength is not None:
            self.extension("KHR_materials_emissive_strength")
            m["extensions"] = {"KHR_materials_emissive_strength": {"emissiveStrength": emissive_strength}}
        if alpha_mode is not None:
            m["alphaMode"] = alpha_mode
        if alpha_cutoff is not None:
            m["alphaCutoff"] = alpha_cutoff
        for slot in (base_uv, emissive_uv):
            if slot and "KHR_texture_transform" in slot.get("extensions", {}):
                self.extension("KHR_texture_transform")
        self.doc["materials"].append(m)
        return len(self.doc["materials"]) - 1

    def image_texture(self, name: str, rgba: np.ndarray, sampler: dict | None = None) -> int:
        """A texture of an (h, w, 4) uint8 image with its own sampler (default: repeat, linear)."""
        t = self.texture(name, np.ascontiguousarray(rgba, np.uint8))
        if sampler is not None:
            self.doc["samplers"].append(sampler)
            self.doc["textures"][t]["sampler"] = len(self.doc["samplers"]) - 1
        return t

    # ---- lights and cameras -----------------------------------------------------------------------

    def light(self, name: str, kind: str, intensity: float, color=(1, 1, 1), node: dict | None = None, **fields) -> int:
        """A KHR_lights_punctual light on a new root node (`node`: its translation/rotation)."""
        self.extension("KHR_lights_punctual")
        ext = self.doc.setdefault("extensions", {}).setdefault("KHR_lights_punctual", {"lights": []})
        ext["lights"].append({"name": name, "type": kind, "intensity": intensity, "color": list(color), **fields})
        n = self.node(name, **(node or {}))
        self.doc["nodes"][n]["extensions"] = {"KHR_lights_punctual": {"light": len(ext["lights"]) - 1}}
        return n

    def camera(self, name: str, yfov: float, znear: float = 0.1, **node) -> int:
        self.doc.setdefault("cameras", []).append({"name": name, "type": "perspective", "perspective": {"yfov": yfov, "znear": znear}})
        n = self.node(name, **node)
        self.doc["nodes"][n]["camera"] = len(self.doc["cameras"]) - 1
        return n

    def write(self, path: Path, external: bool = False) -> Path:
        super().write(path, external)
        return path
