"""glTF seeds for the gltf_import fuzz target that use the extensions the importer supports
(cook_core::SUPPORTED_EXTENSIONS: KHR_lights_punctual, KHR_materials_emissive_strength,
KHR_texture_transform), which none of the samples in ../shared/gltf-samples use: a textured quad
(self-contained, data: URIs) with one extension each, and one with all three, required.

    python3 tools/fuzz_gltf_ext_seeds.py OUT_DIR

Standard library only; run by tools/fuzz_seed.sh, which hands the files to the fuzz_seeds example
(that also writes them as .glb and cooks them, so a seed that no longer imports is reported there).
"""

from __future__ import annotations

import base64
import copy
import json
import math
import struct
import sys
import zlib
from pathlib import Path


def png(w: int, h: int) -> bytes:
    """An RGBA8 PNG of a small gradient."""
    raw = b"".join(b"\0" + b"".join(bytes((x * 100 % 256, y * 100 % 256, 7, 255)) for x in range(w)) for y in range(h))

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 6, 0, 0, 0)) + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b"")


def f32s(v) -> bytes:
    return struct.pack(f"<{len(v)}f", *v)


def quad() -> dict:
    """A unit quad with normals and two UV sets, a PNG base colour, under a root node."""
    bin_ = struct.pack("<6H", 0, 1, 2, 2, 1, 3)
    bin_ += f32s([0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0])
    bin_ += f32s([0, 0, 1] * 4)
    bin_ += f32s([0, 0, 1, 0, 0, 1, 1, 1])
    bin_ += f32s([0, 0, 0.5, 0, 0, 0.5, 0.5, 0.5])
    return {
        "asset": {"version": "2.0", "generator": "tools/fuzz_gltf_ext_seeds.py"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"name": "root", "children": [1], "translation": [1.0, 2.0, 3.0]}, {"name": "quad", "mesh": 0}],
        "meshes": [{"name": "Quad", "primitives": [{"attributes": {"POSITION": 1, "NORMAL": 2, "TEXCOORD_0": 3, "TEXCOORD_1": 4},
                                                    "indices": 0, "material": 0}]}],
        "materials": [{"name": "mat", "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}, "metallicFactor": 0.25,
                                                               "roughnessFactor": 0.75}}],
        "textures": [{"source": 0, "sampler": 0}],
        "samplers": [{"wrapS": 33648, "wrapT": 10497}],
        "images": [{"uri": "data:image/png;base64," + base64.b64encode(png(4, 4)).decode()}],
        "accessors": [
            {"bufferView": 0, "componentType": 5123, "count": 6, "type": "SCALAR"},
            {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]},
            {"bufferView": 2, "componentType": 5126, "count": 4, "type": "VEC3"},
            {"bufferView": 3, "componentType": 5126, "count": 4, "type": "VEC2"},
            {"bufferView": 4, "componentType": 5126, "count": 4, "type": "VEC2"},
        ],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 12},
            {"buffer": 0, "byteOffset": 12, "byteLength": 48},
            {"buffer": 0, "byteOffset": 60, "byteLength": 48},
            {"buffer": 0, "byteOffset": 108, "byteLength": 32},
            {"buffer": 0, "byteOffset": 140, "byteLength": 32},
        ],
        "buffers": [{"byteLength": len(bin_), "uri": "data:application/octet-stream;base64," + base64.b64encode(bin_).decode()}],
    }


def uses(j: dict, ext: str, required: bool = False) -> None:
    j.setdefault("extensionsUsed", []).append(ext)
    if required:
        j.setdefault("extensionsRequired", []).append(ext)


def lights_punctual(j: dict, required: bool = False) -> None:
    """A sun, a point light with a range and a spot, on nodes turned and scaled."""
    uses(j, "KHR_lights_punctual", required)
    h = math.sqrt(0.5)
    j.setdefault("extensions", {})["KHR_lights_punctual"] = {"lights": [
        {"name": "Sun", "type": "directional", "color": [1.0, 0.9, 0.8], "intensity": 3.0},
        {"name": "Lamp", "type": "point", "intensity": 100.0, "range": 5.0},
        {"name": "Spot", "type": "spot", "color": [0.5, 0.5, 1.0], "intensity": 50.0, "spot": {"innerConeAngle": 0.1, "outerConeAngle": 0.6}},
    ]}
    root = j["nodes"][0]
    root["rotation"] = [0.0, h, 0.0, h]
    n = len(j["nodes"])
    j["nodes"] += [
        {"name": "lamp", "translation": [0.0, 0.0, 2.0], "extensions": {"KHR_lights_punctual": {"light": 1}}},
        {"name": "sky", "rotation": [-h, 0.0, 0.0, h], "extensions": {"KHR_lights_punctual": {"light": 0}}},
        {"name": "spot holder", "scale": [3.0, 3.0, 3.0], "extensions": {"KHR_lights_punctual": {"light": 2}}},
    ]
    root["children"] += [n, n + 2]
    j["scenes"][0]["nodes"].append(n + 1)


def emissive_strength(j: dict, required: bool = False) -> None:
    uses(j, "KHR_materials_emissive_strength", required)
    m = j["materials"][0]
    m["emissiveFactor"] = [1.0, 0.5, 0.0]
    m["emissiveTexture"] = {"index": 0, "texCoord": 1}
    m.setdefault("extensions", {})["KHR_materials_emissive_strength"] = {"emissiveStrength": 4.0}


def texture_transform(j: dict, required: bool = False) -> None:
    """A transform on every texture slot, one of them overriding the slot's texCoord."""
    uses(j, "KHR_texture_transform", required)
    t = lambda **kw: {"KHR_texture_transform": kw}  # noqa: E731
    m = j["materials"][0]
    pbr = m["pbrMetallicRoughness"]
    pbr["baseColorTexture"] = {"index": 0, "texCoord": 1, "extensions": t(offset=[0.5, 0.25], rotation=0.3, scale=[2.0, 3.0])}
    pbr["metallicRoughnessTexture"] = {"index": 0, "extensions": t(scale=[0.5, 0.5])}
    m["normalTexture"] = {"index": 0, "scale": 0.5, "extensions": t(texCoord=1, scale=[4.0, 4.0])}
    m["occlusionTexture"] = {"index": 0, "texCoord": 1, "strength": 0.8, "extensions": t(offset=[1.0, 0.0], texCoord=0)}
    if "emissiveTexture" in m:
        m["emissiveTexture"]["extensions"] = t(rotation=-1.0)


def main() -> int:
    if len(sys.argv) != 2:
        print(__doc__, file=sys.stderr)
        return 2
    out = Path(sys.argv[1])
    out.mkdir(parents=True, exist_ok=True)
    seeds = {"ext_lights_punctual": [lights_punctual], "ext_emissive_strength": [emissive_strength],
             "ext_texture_transform": [texture_transform], "ext_all_required": [lights_punctual, emissive_strength, texture_transform]}
    for name, parts in seeds.items():
        j = copy.deepcopy(quad())
        for part in parts:
            part(j, required=name.endswith("required"))
        (out / f"{name}.gltf").write_text(json.dumps(j, separators=(",", ":")))
    print(f"fuzz_gltf_ext_seeds: {len(seeds)} glTF seeds using {', '.join(sorted({e for p in out.glob('ext_*.gltf') for e in json.loads(p.read_text()).get('extensionsUsed', [])}))}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
