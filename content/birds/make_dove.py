"""Author the demo's bird as a glTF 2.0 file: the mesh every member of the temple's flock of
doves is drawn with (a boids spawn's `asset`). Flat-shaded and low-poly (11 triangles): the flock
has dozens of them and each covers a few pixels.

The bird faces +Z with up +Y (what the runtime's boid orientation expects), is 0.55 m long with
a 0.9 m wing span: a diamond body, two swept single-triangle wings raised a little at the tips
(double-sided material, so they are seen from below) and a tail fan.

usage: python make_dove.py OUT.gltf
"""

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from gltf_writer import GltfWriter  # noqa: E402


def dove_triangles() -> np.ndarray:
    """(11, 3, 3) float32: the bird's triangles, counter-clockwise seen from outside."""
    nose, tail = (0.0, 0.0, 0.3), (0.0, 0.0, -0.2)
    top, bottom, left, right = (0.0, 0.06, 0.0), (0.0, -0.05, 0.0), (-0.06, 0.0, 0.0), (0.06, 0.0, 0.0)
    tris = []
    for a, b in ((right, top), (top, left), (left, bottom), (bottom, right)):
        tris += [(nose, a, b), (tail, b, a)]
    tris += [((0.04, 0.0, 0.1), (0.45, 0.06, -0.08), (0.04, 0.0, -0.1)),     # right wing
             ((-0.04, 0.0, 0.1), (-0.04, 0.0, -0.1), (-0.45, 0.06, -0.08)),  # left wing
             ((0.0, 0.0, -0.15), (-0.1, 0.0, -0.25), (0.1, 0.0, -0.25))]     # tail fan
    return np.asarray(tris, dtype=np.float32)


def build_dove() -> GltfWriter:
    tris = dove_triangles()
    # Flat shading: three vertices of their own per triangle, each with the face normal.
    n = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    pos = tris.reshape(-1, 3)
    nrm = np.repeat(n, 3, axis=0).astype(np.float32)
    uv = np.zeros((len(pos), 2), dtype=np.float32)
    idx = np.arange(len(pos), dtype=np.uint32)
    g = GltfWriter("content/birds/make_dove.py")
    feathers = g.material("dove feathers", color=(0.85, 0.85, 0.82, 1.0), double_sided=True, roughness=0.8)
    g.node("dove", mesh=g.mesh("dove", pos, nrm, uv, idx, feathers))
    return g


def main(argv):
    if len(argv) != 2:
        print(__doc__.strip().splitlines()[-1], file=sys.stderr)
        return 2
    build_dove().write(Path(argv[1]))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
