"""Author the project's animated character as a glTF 2.0 file: a stone golem, skinned to a
18-joint skeleton, with a breathing morph target and two clips.

The body is one mesh of capsules, one per bone, so every vertex has a bone it belongs to and
blends into its parent or child bone near the joints (up to 2 influences, weights summing to 1).
The clips use every glTF sampler: `walk` (1 s loop) rotates the legs, arms and spine with LINEAR
keys, bobs the hips with CUBICSPLINE translation and breathes with LINEAR weights; `idle` (4 s
loop) breathes with CUBICSPLINE weights, sways with LINEAR rotations and glances around with a
STEP neck rotation. Vertex count scales with `--detail` (default ~11k vertices, the size the
skinning benchmark asks for).

usage: python make_creature.py OUT.gltf [--detail F]
"""

import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from gltf_writer import GltfWriter  # noqa: E402
from asset_pipeline.procedural_textures import procedural_relief, procedural_texture  # noqa: E402

FLOAT, UBYTE, UINT = 5126, 5121, 5125
ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963

# (name, parent, translation from the parent in the rest pose). The rest pose has no rotations,
# so a joint's inverse bind matrix is the translation by minus its world position.
JOINTS = [
    ("root", None, (0.0, 0.0, 0.0)),
    ("hips", "root", (0.0, 0.95, 0.0)),
    ("spine", "hips", (0.0, 0.15, 0.0)),
    ("chest", "spine", (0.0, 0.2, 0.0)),
    ("neck", "chest", (0.0, 0.24, 0.0)),
    ("head", "neck", (0.0, 0.1, 0.0)),
    *[j for s, x in (("l", 1.0), ("r", -1.0)) for j in (
        (f"upperarm_{s}", "chest", (0.23 * x, 0.17, 0.0)),
        (f"forearm_{s}", f"upperarm_{s}", (0.0, -0.29, 0.0)),
        (f"hand_{s}", f"forearm_{s}", (0.0, -0.26, 0.0)),
        (f"thigh_{s}", "hips", (0.1 * x, -0.05, 0.0)),
        (f"shin_{s}", f"thigh_{s}", (0.0, -0.42, 0.0)),
        (f"foot_{s}", f"shin_{s}", (0.0, -0.42, 0.02)),
    )],
]
NAMES = [j[0] for j in JOINTS]
PARENT = [None if p is None else NAMES.index(p) for _, p, _ in JOINTS]

# (bone that owns the capsule, where it ends: a child joint or an offset from the bone, radius).
# Metres of stone plate per texture repeat (the golem's texture coordinates).
PLATE = 0.6

CAPSULES = [
    ("hips", "spine", 0.16),
    ("spine", "chest", 0.17),
    ("chest", "neck", 0.18),
    ("neck", "head", 0.06),
    ("head", (0.0, 0.13, 0.02), 0.11),
    *[c for s in "lr" for c in (
        (f"upperarm_{s}", f"forearm_{s}", 0.06),
        (f"forearm_{s}", f"hand_{s}", 0.05),
        (f"hand_{s}", (0.0, -0.09, 0.0), 0.045),
        (f"thigh_{s}", f"shin_{s}", 0.085),
        (f"shin_{s}", f"foot_{s}", 0.065),
        (f"foot_{s}", (0.0, -0.02, 0.15), 0.05),
    )],
]
BREATHING = ("spine", "chest")  # bones whose capsules the breathe target swells


def world_positions() -> np.ndarray:
    out = np.zeros((len(JOINTS), 3))
    for i, (_, _, t) in enumerate(JOINTS):
        out[i] = (out[PARENT[i]] if PARENT[i] is not None else 0.0) + np.array(t)
    return out


def capsule(a: np.ndarray, b: np.ndarray, r: float, sides: int, cap_rings: int, body_rings: int):
    """A capsule around segment a-b: positions, normals, axis parameter t in [0, 1] (clamped),
    texture coordinates, triangles (counter-clockwise from outside). Poles are single vertices
    with triangle fans. Each ring has a seam vertex (theta = 2 pi, the first one again with u at
    the end of the repeat); u wraps a whole number of texture repeats of `PLATE` metres around
    the capsule and v runs PLATE metres a repeat along it, so the stone plates are about the
    same size on every limb and tile across the seam."""
    axis = b - a
    length = float(np.linalg.norm(axis))
    d = axis / length
    u = np.cross(d, [0.0, 0.0, 1.0] if abs(d[2]) < 0.9 else [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(d, u)
    # Rings: (position along the axis, radius), cap a, body, cap b; poles excluded.
    alpha = np.linspace(0.0, math.pi / 2, cap_rings + 1)[1:]
    s = np.concatenate([-r * np.cos(alpha), np.linspace(0.0, length, body_rings + 2)[1:-1], length + r * np.cos(alpha[::-1])])
    rad = np.concatenate([r * np.sin(alpha), np.full(body_rings, r), r * np.sin(alpha[::-1])])
    theta = np.linspace(0.0, 2 * math.pi, sides + 1)
    ring = np.cos(theta)[:, None] * u + np.sin(theta)[:, None] * v  # (sides + 1, 3)
    pos = a + s[:, None, None] * d + rad[:, None, None] * ring[None]  # (rings, sides + 1, 3)
    pos = np.concatenate([pos.reshape(-1, 3), [a - r * d, b + r * d]])
    repeats = max(1, round(2 * math.pi * r / PLATE))
    uv = np.stack(np.broadcast_arrays(theta[None, :] / (2 * math.pi) * repeats, s[:, None] / PLATE), -1).reshape(-1, 2)
    uv = np.concatenate([uv, [[0.5 * repeats, -r / PLATE], [0.5 * repeats, (length + r) / PLATE]]])
    # A capsule's normal points away from the closest point of its axis segment.
    t = np.clip(((pos - a) @ d) / length, 0.0, 1.0)
    nrm = pos - (a + t[:, None] * axis)
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    rings, per_ring = len(s), sides + 1
    k = np.arange(rings - 1)[:, None] * per_ring
    j = np.arange(sides)[None, :]
    j1 = j + 1
    # Rings run from a to b and theta turns from u toward v = d x u, so seen from outside
    # (k, k + 1, k + per_ring) is counter-clockwise.
    quads = np.stack([k + j, k + j1, k + per_ring + j, k + j1, k + per_ring + j1, k + per_ring + j], -1).reshape(-1, 3)
    pole_a, pole_b, last = rings * per_ring, rings * per_ring + 1, (rings - 1) * per_ring
    fan_a = np.stack([np.full(sides, pole_a), j1[0], j[0]], -1)
    fan_b = np.stack([np.full(sides, pole_b), last + j[0], last + j1[0]], -1)
    return pos, nrm, t, uv, np.concatenate([quads, fan_a, fan_b])


def smoothstep(e0: float, e1: float, x: np.ndarray) -> np.ndarray:
    y = np.clip((x - e0) / (e1 - e0), 0.0, 1.0)
    return y * y * (3 - 2 * y)


def build_body(detail: float):
    """The skinned body: positions, normals, texture coordinates, joints (u8 x4), weights (f32
    x4), indices, and the breathe target's position deltas."""
    world = world_positions()
    sides = max(8, round(24 * detail))
    cap_rings, body_rings = max(2, round(6 * detail)), max(2, round(16 * detail))
    parts = {k: [] for k in ("pos", "nrm", "uv", "joints", "weights", "idx", "breathe")}
    base = 0
    for owner, end, r in CAPSULES:
        o = NAMES.index(owner)
        a = world[o]
        child = NAMES.index(end) if isinstance(end, str) else None
        b = world[child] if child is not None else a + np.array(end)
        pos, nrm, t, uv, tri = capsule(a, b, r, sides, cap_rings, body_rings)
        n = len(pos)
        # The owner bone, blended into its parent near the start and into the child near the end
        # (so elbows and knees bend smoothly); the two blends never overlap, so at most 2 influences.
        w_parent = 0.5 * smoothstep(0.25, 0.0, t) if PARENT[o] is not None and owner != "hips" else np.zeros(n)
        w_child = 0.5 * smoothstep(0.75, 1.0, t) if child is not None else np.zeros(n)
        w = np.stack([1.0 - w_parent - w_child, w_parent, w_child, np.zeros(n)], -1)
        j = np.stack([np.full(n, o), np.full(n, PARENT[o] or 0), np.full(n, child if child is not None else 0), np.zeros(n, int)], -1)
        w /= w.sum(1, keepdims=True)
        j = np.where(w > 0, j, 0)  # unused influences point at joint 0 (validators flag others)
        # Breathing swells the ribcage sideways and forward, most at mid-chest.
        swell = np.zeros((n, 3))
        if owner in BREATHING:
            height = np.exp(-(((pos[:, 1] - 1.35) / 0.12) ** 2))
            swell = 0.03 * height[:, None] * nrm * np.array([1.0, 0.3, 1.2])
        for key, value in (("pos", pos), ("nrm", nrm), ("uv", uv), ("joints", j), ("weights", w), ("idx", tri + base), ("breathe", swell)):
            parts[key].append(value)
        base += n
    out = {k: np.concatenate(v) for k, v in parts.items()}
    return (out["pos"].astype(np.float32), out["nrm"].astype(np.float32), out["uv"].astype(np.float32), out["joints"].astype(np.uint8),
            out["weights"].astype(np.float32), out["idx"].astype(np.uint32).reshape(-1), out["breathe"].astype(np.float32))


def quat_axis_angle(axis, degrees: np.ndarray) -> np.ndarray:
    """Quaternions (x, y, z, w) for rotations by `degrees` about a unit `axis`."""
    h = np.radians(degrees) / 2
    return np.concatenate([np.sin(h)[:, None] * np.asarray(axis, float), np.cos(h)[:, None]], 1).astype(np.float32)


class Clip:
    """Samplers and channels of one animation, written into the writer's buffer."""

    def __init__(self, g: GltfWriter, name: str):
        self.g, self.anim = g, {"name": name, "samplers": [], "channels": []}

    def channel(self, node: int, path: str, times: np.ndarray, values: np.ndarray, interpolation: str, kind: str):
        times = np.asarray(times, np.float32)
        inp = self.g.accessor(times, "SCALAR", FLOAT)
        self.g.doc["accessors"][inp].update(min=[float(times.min())], max=[float(times.max())])
        out = self.g.accessor(np.asarray(values, np.float32), kind, FLOAT)
        self.anim["samplers"].append({"input": inp, "output": out, "interpolation": interpolation})
        self.anim["channels"].append({"sampler": len(self.anim["samplers"]) - 1, "target": {"node": node, "path": path}})

    def cubic(self, node: int, path: str, times: np.ndarray, values: np.ndarray, slopes: np.ndarray, kind: str):
        """CUBICSPLINE: per key (in-tangent, value, out-tangent), tangents in units per second."""
        v = np.asarray(values, np.float32).reshape(len(times), -1)
        m = np.asarray(slopes, np.float32).reshape(len(times), -1)
        out = np.stack([m, v, m], 1).reshape(3 * len(times), -1)
        self.channel(node, path, times, out if kind != "SCALAR" else out.reshape(-1), "CUBICSPLINE", kind)

    def finish(self):
        self.g.doc.setdefault("animations", []).append(self.anim)


def walk_clip(g: GltfWriter, node: dict[str, int], mesh_node: int):
    clip = Clip(g, "walk")
    t = np.linspace(0.0, 1.0, 17)
    phase = 2 * math.pi * t
    x = (1.0, 0.0, 0.0)
    for s, sign in (("l", 1.0), ("r", -1.0)):
        clip.channel(node[f"thigh_{s}"], "rotation", t, quat_axis_angle(x, -28.0 * sign * np.sin(phase)), "LINEAR", "VEC4")
        # The knee bends while the leg swings back and lifts.
        knee = 45.0 * np.maximum(0.0, np.sin(phase + (0.0 if sign > 0 else math.pi) - 0.6)) ** 2
        clip.channel(node[f"shin_{s}"], "rotation", t, quat_axis_angle(x, knee), "LINEAR", "VEC4")
        clip.channel(node[f"upperarm_{s}"], "rotation", t, quat_axis_angle(x, 22.0 * sign * np.sin(phase)), "LINEAR", "VEC4")
        clip.channel(node[f"forearm_{s}"], "rotation", t, quat_axis_angle(x, -15.0 - 10.0 * sign * np.sin(phase)), "LINEAR", "VEC4")
    clip.channel(node["spine"], "rotation", t, quat_axis_angle((0.0, 1.0, 0.0), 6.0 * np.sin(phase)), "LINEAR", "VEC4")
    # Two bobs per cycle (one per step), as a cubic spline with exact slopes.
    keys = np.linspace(0.0, 1.0, 5)
    bob = np.stack([np.zeros(5), 0.95 + 0.025 * np.cos(4 * math.pi * keys), np.zeros(5)], 1)
    slope = np.stack([np.zeros(5), -0.025 * 4 * math.pi * np.sin(4 * math.pi * keys), np.zeros(5)], 1)
    clip.cubic(node["hips"], "translation", keys, bob, slope, "VEC3")
    clip.channel(mesh_node, "weights", t, 0.4 + 0.3 * np.sin(2 * phase), "LINEAR", "SCALAR")
    clip.finish()


def idle_clip(g: GltfWriter, node: dict[str, int], mesh_node: int):
    clip = Clip(g, "idle")
    keys = np.arange(5.0)
    # Breathe in and out over 4 s: 0.5 - 0.5 cos(pi t / 2) with its exact slope.
    clip.cubic(mesh_node, "weights", keys, 0.5 - 0.5 * np.cos(math.pi * keys / 2), 0.5 * (math.pi / 2) * np.sin(math.pi * keys / 2), "SCALAR")
    t = np.linspace(0.0, 4.0, 9)
    sway = np.sin(2 * math.pi * t / 4)
    clip.channel(node["spine"], "rotation", t, quat_axis_angle((0.0, 0.0, 1.0), 2.5 * sway), "LINEAR", "VEC4")
    for s, sign in (("l", 1.0), ("r", -1.0)):
        clip.channel(node[f"upperarm_{s}"], "rotation", t, quat_axis_angle((0.0, 0.0, 1.0), sign * (4.0 + 2.0 * sway)), "LINEAR", "VEC4")
    # Glances: the head snaps between looking ahead, left and right (STEP holds each key).
    clip.channel(node["neck"], "rotation", [0.0, 1.5, 2.2, 3.4, 4.0], quat_axis_angle((0.0, 1.0, 0.0), np.array([0.0, 25.0, 0.0, -20.0, 0.0])), "STEP", "VEC4")
    clip.finish()


def golem_stone(g: GltfWriter) -> int:
    """The golem's material: weathered stone plates with dark seams, from the cooker's
    procedural flagstones: base colour, a normal map (the seams sunk, the plates' edges
    bevelled) and an occlusion-roughness map (rough seams, smoother worn plates). No tangents
    are written: the cooker computes MikkTSpace ones, as for any normal-mapped glTF without."""
    params = {"procedural": "flagstones", "size": 256, "count": 4, "mortar": 0.07, "colors": [[0.62, 0.58, 0.52], [0.2, 0.18, 0.16]],
              "seed": 11, "relief": 1.5}
    normal, orm = procedural_relief(params)
    return g.material("golem stone", texture=g.texture("golem stone", procedural_texture(params)), roughness=0.9,
                      normal=g.texture("golem stone normal", normal), occlusion_roughness=g.texture("golem stone orm", orm))


def build_creature(detail: float = 1.0) -> GltfWriter:
    g = GltfWriter("content/characters/make_creature.py")
    stone = golem_stone(g)
    pos, nrm, uv, joints, weights, idx, breathe = build_body(detail)
    attrs = {
        "POSITION": g.accessor(pos, "VEC3", FLOAT, ARRAY_BUFFER, minmax=True),
        "NORMAL": g.accessor(nrm, "VEC3", FLOAT, ARRAY_BUFFER),
        "TEXCOORD_0": g.accessor(uv, "VEC2", FLOAT, ARRAY_BUFFER),
        "JOINTS_0": g.accessor(joints, "VEC4", UBYTE, ARRAY_BUFFER),
        "WEIGHTS_0": g.accessor(weights, "VEC4", FLOAT, ARRAY_BUFFER),
    }
    target = {"POSITION": g.accessor(breathe, "VEC3", FLOAT, ARRAY_BUFFER, minmax=True)}
    prim = {"attributes": attrs, "indices": g.accessor(idx, "SCALAR", UINT, ELEMENT_ARRAY_BUFFER), "material": stone, "targets": [target]}
    g.doc["meshes"].append({"name": "golem", "primitives": [prim], "weights": [0.0], "extras": {"targetNames": ["breathe"]}})
    mesh = len(g.doc["meshes"]) - 1

    # Joint nodes, parents before children; children lists filled in afterwards.
    node = {}
    for name, parent, t in JOINTS:
        node[name] = g.node(name, translation=list(t), root=False)
    for i, (name, parent, _) in enumerate(JOINTS):
        if parent is not None:
            g.doc["nodes"][node[parent]].setdefault("children", []).append(node[name])
    world = world_positions()
    inverse_bind = np.zeros((len(JOINTS), 16), np.float32)
    for i in range(len(JOINTS)):
        m = np.eye(4)
        m[:3, 3] = -world[i]
        inverse_bind[i] = m.T.reshape(-1)  # column-major
    g.doc["skins"] = [{"name": "golem", "joints": [node[n] for n in NAMES], "skeleton": node["root"], "inverseBindMatrices": g.accessor(inverse_bind, "MAT4", FLOAT)}]
    # The skinned mesh node sits at the scene root: its own transform is ignored (the joints
    # place it), so parenting it would only mislead.
    body = g.node("golem body", mesh=mesh)
    g.doc["nodes"][body]["skin"] = 0
    g.node("golem", children=[node["root"]])
    walk_clip(g, node, body)
    idle_clip(g, node, body)
    return g


def main(argv):
    args = argv[1:]
    detail = 1.0
    if "--detail" in args:
        i = args.index("--detail")
        try:
            detail = float(args[i + 1])
        except (IndexError, ValueError):
            print("make_creature: --detail needs a number", file=sys.stderr)
            return 2
        del args[i:i + 2]
        if not 0.25 <= detail <= 8.0:
            print(f"make_creature: --detail {detail} is out of range (0.25..8)", file=sys.stderr)
            return 2
    if len(args) != 1:
        print(__doc__.strip().splitlines()[-1], file=sys.stderr)
        return 2
    build_creature(detail).write(Path(args[0]))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
