"""No crack between level chunks at grazing angles (issue 23).

A bumpy 64 m terrain (8192 triangles, one static glTF mesh) is cooked into chunks, each with its
own LOD chain (borders locked), and rendered by `demo` from a glTF camera 1.2 m above it looking
along it, 4 degrees down: near chunks draw at LOD 0 and far ones at their coarse levels, so
chunks at different LODs meet all over the view. Every pixel whose view ray goes below the
terrain's lowest point inside its extent must show the terrain: a crack between two chunks would
let the background (the clear colour, which the upper part of the frame shows) through.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
from PIL import Image

from asset_pipeline import _core
from conftest import cook_ok, run_demo
from gltf_scenes import Scene, quaternion

SIZE_M = 64.0
CELLS = 64
EYE = np.array([-30.0, 1.2, 0.0])
YAW_DEG, PITCH_DEG, YFOV = -90.0, -4.0, 0.9
WIDTH, HEIGHT = 640, 360


def height(x, z):
    return 0.4 * np.sin(x / 3.1) * np.cos(z / 2.3) + 0.2 * np.sin(x / 1.7 + z / 2.9)


def terrain_scene(path: Path) -> Path:
    n = CELLS + 1
    xs = np.linspace(-SIZE_M / 2, SIZE_M / 2, n)
    x, z = np.meshgrid(xs, xs, indexing="ij")
    y = height(x, z)
    pos = np.stack([x, y, z], -1).reshape(-1, 3)
    # Normals from the height field's gradient (central differences).
    e = 1e-3
    dx = (height(x + e, z) - height(x - e, z)) / (2 * e)
    dz = (height(x, z + e) - height(x, z - e)) / (2 * e)
    nrm = np.stack([-dx, np.ones_like(dx), -dz], -1).reshape(-1, 3)
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    uv = np.stack([x / 4.0, z / 4.0], -1).reshape(-1, 2)
    i, j = np.meshgrid(np.arange(CELLS), np.arange(CELLS), indexing="ij")
    a = (i * n + j).ravel()
    b, c, d = a + n, a + n + 1, a + 1
    # Counter-clockwise seen from above (+Y).
    idx = np.concatenate([np.stack([a, d, c], 1), np.stack([a, c, b], 1)]).astype(np.uint32)
    s = Scene()
    grey = s.material("ground", color=(0.45, 0.5, 0.4, 1.0))
    mesh = s.mesh_arrays("terrain", pos, nrm, uv, idx.ravel(), grey)
    s.node("terrain", mesh=mesh)
    q = quaternion((0, 1, 0), YAW_DEG)
    p = quaternion((1, 0, 0), PITCH_DEG)
    # Yaw after pitch: q * p (xyzw).
    qv, qw, pv, pw = np.array(q[:3]), q[3], np.array(p[:3]), p[3]
    rot = [*(qw * pv + pw * qv + np.cross(qv, pv)).tolist(), qw * pw - qv @ pv]
    s.camera("view", yfov=YFOV, znear=0.05, translation=EYE.tolist(), rotation=rot)
    return s.write(path)


def view_rays() -> np.ndarray:
    """Each pixel's world-space view direction (the engine's camera: yaw and pitch, +Y up)."""
    yaw, pitch = math.radians(YAW_DEG), math.radians(PITCH_DEG)
    forward = np.array([-math.sin(yaw) * math.cos(pitch), math.sin(pitch), -math.cos(yaw) * math.cos(pitch)])
    right = np.cross(forward, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    t = math.tan(YFOV / 2)
    px = (np.arange(WIDTH) + 0.5) / WIDTH * 2 - 1
    py = (np.arange(HEIGHT) + 0.5) / HEIGHT * 2 - 1
    gx, gy = np.meshgrid(px, py)
    return forward + (gx * t * WIDTH / HEIGHT)[..., None] * right + (-gy * t)[..., None] * up


def test_chunks_at_different_lods_leave_no_crack_at_a_grazing_angle(tmp_path):
    src = terrain_scene(tmp_path / "terrain.gltf")
    pack = tmp_path / "terrain.pack"
    cook_ok(src, pack, "--no-bake")
    doc = json.loads(_core.read_pack_manifest(pack))
    chunks = [m for m in doc["meshes"] if re.fullmatch(r"terrain#\d+", m["name"])]
    assert len(chunks) >= 16, [m["name"] for m in doc["meshes"]]
    assert sum(len(m["lods"]) > 1 for m in chunks) >= len(chunks) // 2, "chunks without LOD chains test nothing"

    shot = tmp_path / "view.png"
    r = run_demo([pack, "--headless", "--validation", "--flight", "0", "--frames", "1", "--width", WIDTH, "--height", HEIGHT,
                  "--render-scale", "1", "--screenshot", shot])
    assert r.returncode == 0 and "validation errors: 0" in r.stdout, r.stdout + r.stderr
    histogram = [int(v) for v in re.search(r"LOD histogram \[([0-9, ]+)\]", r.stdout).group(1).split(",")]
    assert sum(h > 0 for h in histogram) >= 2, f"the view should draw chunks at different LODs: {histogram}"

    img = np.asarray(Image.open(shot).convert("RGB")).astype(np.int16)
    rays = view_rays()
    # The background: what the rays going up show (nothing is above the terrain).
    sky = rays[..., 1] > 0.02
    background = img[sky][0]
    assert (np.abs(img[sky] - background).max(axis=1) == 0).all(), "the upper part of the frame is not plain background"
    # Rays that reach below the terrain's lowest point inside its extent (2 m in from the edge)
    # pass through its surface: those pixels must show the terrain.
    low = float(height(np.linspace(-40, 40, 801)[:, None], np.linspace(-40, 40, 801)[None, :]).min()) - 0.01
    down = rays[..., 1] < -1e-4
    t = np.where(down, (low - EYE[1]) / np.where(down, rays[..., 1], -1.0), np.inf)
    hit = EYE + t[..., None] * rays
    inner = SIZE_M / 2 - 2.0
    through = down & (np.abs(hit[..., 0]) < inner) & (np.abs(hit[..., 2]) < inner)
    assert through.mean() > 0.25, "the terrain should fill much of the view"
    holes = through & (np.abs(img - background).max(axis=-1) == 0)
    assert not holes.any(), f"{holes.sum()} background pixels through the terrain, first at (row, col) {np.argwhere(holes)[:5].tolist()}"
