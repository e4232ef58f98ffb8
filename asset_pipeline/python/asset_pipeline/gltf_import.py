"""glTF 2.0 (.gltf/.glb) -> scene IR, through the Rust core's importer."""

from __future__ import annotations

import dataclasses
import json
import math
import os
import struct
from pathlib import Path

import numpy as np

from asset_pipeline import _core, ir
from asset_pipeline._core import CookError


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


def import_gltf_scene(path: str | os.PathLike, allow_external_uris: bool = False) -> ir.Scene:
    """A glTF file cooked as a scene of its own (not as a level's prop): import_gltf and its
    reflection probes (``reflection_probes``)."""
    scene = import_gltf(path, allow_external_uris=allow_external_uris)
    return dataclasses.replace(scene, reflection_probes=reflection_probes(path, scene))


# How much a glTF scene's default reflection probe box is larger than the static bounds: on
# every axis by this fraction of the bounds' largest size (half on each side), so surfaces on
# the bounds are inside and a flat scene still gets a box with a volume.
PROBE_BOX_GROWTH = 0.01


def static_bounds(scene: ir.Scene) -> tuple[np.ndarray, np.ndarray] | None:
    """(min, max) in world space of every static instance's LOD 0 (what the bake traces), or None."""
    world = scene.world_matrices()
    pts = [scene.meshes[scene.nodes[k].mesh].base.attributes["position"].astype(np.float64) @ world[k][:3, :3].T + world[k][:3, 3]
           for k in scene.static_nodes()]
    pts = [p for p in pts if len(p)]
    if not pts:
        return None
    allp = np.concatenate(pts)
    return allp.min(axis=0), allp.max(axis=0)


def _grown(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    pad = 0.5 * PROBE_BOX_GROWTH * max(float((hi - lo).max()), 1e-3)
    return lo - pad, hi + pad


def _gltf_json(path: Path) -> dict:
    """The JSON document of a .gltf or .glb (the importer has already read and checked the file)."""
    raw = path.read_bytes()
    if raw[:4] == b"glTF":
        length, kind = struct.unpack_from("<II", raw, 12)
        if kind != 0x4E4F534A:  # "JSON"
            raise CookError(f"{path}: the GLB's first chunk is not JSON")
        raw = raw[20:20 + length]
    return json.loads(raw)


def _local_matrix(node: dict) -> np.ndarray:
    """A glTF node's local transform, row-major (column vectors), float64."""
    if "matrix" in node:
        return np.array(node["matrix"], np.float64).reshape(4, 4).T
    x, y, z, w = node.get("rotation", (0.0, 0.0, 0.0, 1.0))
    r = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                  [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                  [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    m = np.eye(4)
    m[:3, :3] = r * np.asarray(node.get("scale", (1.0, 1.0, 1.0)), np.float64)
    m[:3, 3] = node.get("translation", (0.0, 0.0, 0.0))
    return m


def _scene_nodes(doc: dict):
    """(glTF node index, world matrix) of every node of the scene the importer takes (the default
    scene, else the first, else every node that is nobody's child), parents first."""
    nodes = doc.get("nodes", [])
    scenes = doc.get("scenes", [])
    if scenes:
        roots = scenes[doc.get("scene", 0)].get("nodes", [])
    else:
        children = {c for n in nodes for c in n.get("children", [])}
        roots = [i for i in range(len(nodes)) if i not in children]
    stack = [(i, np.eye(4)) for i in reversed(roots)]
    while stack:
        i, parent = stack.pop()
        world = parent @ _local_matrix(nodes[i])
        yield i, world
        stack.extend((c, world) for c in reversed(nodes[i].get("children", [])))


def reflection_probes(path: str | os.PathLike, scene: ir.Scene) -> list[ir.ReflectionProbe]:
    """The reflection probes of the glTF scene at `path` (imported as `scene`): one per node whose
    extras hold ``{"reflection_probe": {"size": [sx, sy, sz], "blend_distance": b}}``, at the
    node's world translation with its box of that size centred there on the world axes (size
    default: the static bounds' size, grown as the default probe's; blend_distance default 0.5);
    without such nodes, one probe at the centre of the static bounds with those bounds grown by
    PROBE_BOX_GROWTH, named "reflection_probe_0" (none when nothing is static: nothing is
    baked). Raises CookError naming the file and the node."""
    path = Path(path)
    bounds = static_bounds(scene)
    grown = None if bounds is None else _grown(*bounds)
    probes: list[ir.ReflectionProbe] = []
    doc = _gltf_json(path)
    for i, world in _scene_nodes(doc):
        node = doc["nodes"][i]
        extras = node.get("extras")
        if not isinstance(extras, dict) or "reflection_probe" not in extras:
            continue
        name = node.get("name") or f"node{i}"
        what = f"{path}: node {i} '{name}': extras reflection_probe"
        spec = extras["reflection_probe"]
        if not isinstance(spec, dict):
            raise CookError(f"{what}: expected an object {{\"size\": [x, y, z], \"blend_distance\": b}}, got {json.dumps(spec)}")
        for k in spec:
            if k not in ("size", "blend_distance"):
                raise CookError(f"{what}: unknown key '{k}' (expected size, blend_distance)")
        if "size" in spec:
            size = spec["size"]
            if (not isinstance(size, list) or len(size) != 3
                    or not all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in size)):
                raise CookError(f"{what}: size must be 3 finite numbers, got {json.dumps(size)}")
            if not all(x > 0 for x in size):
                raise CookError(f"{what}: the box is empty (size {json.dumps(size)} must be > 0 on every axis)")
            size = np.asarray(size, np.float64)
        elif grown is not None:
            size = grown[1] - grown[0]
        else:
            raise CookError(f"{what}: no size, and the scene has no static geometry to take it from")
        blend = spec.get("blend_distance", 0.5)
        if not isinstance(blend, (int, float)) or isinstance(blend, bool) or not math.isfinite(blend) or blend < 0:
            raise CookError(f"{what}: blend_distance must be a finite number >= 0, got {json.dumps(blend)}")
        at = world[:3, 3]
        if not np.isfinite(at).all():
            raise CookError(f"{what}: its world position is not finite")
        probes.append(ir.ReflectionProbe(name=name, position=tuple(float(x) for x in at), box_min=tuple(float(x) for x in at - size / 2),
                                         box_max=tuple(float(x) for x in at + size / 2), blend_distance=float(blend)))
    seen: dict[str, int] = {}
    for p in probes:
        seen[p.name] = seen.get(p.name, 0) + 1
    if any(n > 1 for n in seen.values()):
        # Names label the probes in the pack and the report: make repeated node names unique.
        count: dict[str, int] = {}
        for k, p in enumerate(probes):
            if seen[p.name] > 1:
                count[p.name] = count.get(p.name, 0) + 1
                probes[k] = dataclasses.replace(p, name=f"{p.name}[{count[p.name] - 1}]")
    if not probes and grown is not None:
        lo, hi = grown
        probes.append(ir.ReflectionProbe(name="reflection_probe_0", position=tuple(float(x) for x in (bounds[0] + bounds[1]) / 2),
                                         box_min=tuple(float(x) for x in lo), box_max=tuple(float(x) for x in hi)))
    return probes


def write_pack(scene: ir.Scene, out: str | os.PathLike) -> dict:
    """Write the pack for `scene` atomically; returns the Rust core's summary."""
    text, arrays = ir.to_wire(scene)
    return _core.write_pack(text, arrays_to_wire(arrays), os.fspath(out))


def decode_image(path: str | os.PathLike) -> np.ndarray:
    """A PNG/JPEG file as an (h, w, 4) uint8 RGBA array."""
    w, h, data = _core.decode_image(os.fspath(path))
    return np.frombuffer(data, dtype=np.uint8).reshape(h, w, 4)
