"""Author the demo level's glass lantern as a glTF 2.0 file: a bronze post carrying a box of
amber glass (a BLEND material: the renderer's transparent phase; the baker lets light through
it stochastically by its alpha) around a glowing core (emission in nits through
KHR_materials_emissive_strength). The level places two by the portico (`temple.toml`, props).

usage: python make_lantern.py OUT.gltf
"""

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from gltf_writer import GltfWriter  # noqa: E402


def box(size, centre):
    """An axis-aligned box: positions, per-face normals, uvs (0..1 per face) and
    counter-clockwise triangles seen from outside."""
    half, c = np.asarray(size, float) / 2, np.asarray(centre, float)
    pos, nrm, uv, idx = [], [], [], []
    for axis in range(3):
        for sign in (1.0, -1.0):
            n = np.zeros(3)
            n[axis] = sign
            u = np.zeros(3)
            u[(axis + 1) % 3] = 1.0
            w = np.cross(n, u)
            base = len(pos)
            for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                pos.append(c + half * (n + a * u + b * w))
                nrm.append(n)
                uv.append(((a + 1) / 2, (1 - b) / 2))
            idx += [base, base + 1, base + 2, base, base + 2, base + 3]
    f = np.float32
    return np.array(pos, f), np.array(nrm, f), np.array(uv, f), np.array(idx, np.uint32)


def build_lantern() -> GltfWriter:
    g = GltfWriter("content/props/make_lantern.py")
    bronze = g.material("lantern bronze", color=(0.45, 0.3, 0.18, 1.0), roughness=0.45)
    g.doc["materials"][bronze]["pbrMetallicRoughness"]["metallicFactor"] = 1.0
    glass = g.material("lantern glass", color=(1.0, 0.8, 0.55, 0.3), roughness=0.05, double_sided=True)
    g.doc["materials"][glass]["alphaMode"] = "BLEND"
    flame = g.material("lantern flame", color=(1.0, 0.7, 0.35, 1.0), roughness=1.0)
    g.doc["materials"][flame].update(emissiveFactor=[1.0, 0.55, 0.2], extensions={"KHR_materials_emissive_strength": {"emissiveStrength": 4000.0}})
    g.doc["extensionsUsed"] = ["KHR_materials_emissive_strength"]
    parts = [
        ("post", bronze, box((0.1, 1.3, 0.1), (0.0, 0.65, 0.0))),
        ("cap", bronze, box((0.5, 0.06, 0.5), (0.0, 1.93, 0.0))),
        ("flame", flame, box((0.1, 0.16, 0.1), (0.0, 1.52, 0.0))),
        ("glass", glass, box((0.42, 0.6, 0.42), (0.0, 1.6, 0.0))),
    ]
    children = [g.node(name, mesh=g.mesh(name, *geometry, material), root=False) for name, material, geometry in parts]
    g.node("lantern", children=children)
    return g


def main(argv):
    if len(argv) != 2:
        print(__doc__.strip().splitlines()[-1], file=sys.stderr)
        return 2
    build_lantern().write(Path(argv[1]))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
