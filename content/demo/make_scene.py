"""Author the project's demo scene as a glTF 2.0 file: a paved yard with a colonnade and crates.

This is the project's own content (no third-party assets), generated so that it stays small in
git and exercises the cooker's glTF path: several meshes and materials, textures, a node
hierarchy, a mirrored instance and a double-sided material. Levels authored as CSG brushes
replace it as the demo's main content once the CSG stage lands.

usage: python make_scene.py OUT.gltf
"""

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from gltf_writer import GltfWriter  # noqa: E402


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


def build_scene() -> GltfWriter:
    g = GltfWriter("content/demo/make_scene.py")
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
