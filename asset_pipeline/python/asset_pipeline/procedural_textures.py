"""Procedural, seamlessly tiling textures for levels (checker, bricks, planks, flagstones).

``procedural_texture(params) -> (size, size, 4) uint8`` in sRGB, from the validated ``texture =
{ procedural = ... }`` table of a level material (see level.py), and for bricks, planks and
flagstones ``procedural_relief(params)``: the same pattern's tangent-space normal map and its
occlusion-roughness-metalness map (glTF's channels: R occlusion, G roughness, B metalness), from
a height field in which the joints are sunk and the faces' edges bevelled. Deterministic for a
given table, so cooking is reproducible and cacheable.
"""

from __future__ import annotations

import numpy as np


def _noise(size: int, cells: int, rng: np.random.Generator) -> np.ndarray:
    """Periodic value noise in [0, 1]: a random cells x cells grid, smoothly interpolated with wrap."""
    grid = rng.random((cells, cells))
    x = np.arange(size) * cells / size
    i0 = np.floor(x).astype(int)
    f = x - i0
    f = f * f * (3 - 2 * f)
    i0, i1 = i0 % cells, (i0 + 1) % cells
    rows = grid[i0] * (1 - f)[:, None] + grid[i1] * f[:, None]
    return rows[:, i0] * (1 - f)[None, :] + rows[:, i1] * f[None, :]


def _cells(coord: np.ndarray, n: int, size: int, joint: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cell index of each pixel coordinate (n cells per `size`), whether it lies in a joint of
    half-width `joint` pixels at the cell's edges, and its distance in pixels from the joint
    (0 inside it)."""
    w = size / n
    idx = np.floor(coord / w).astype(int)
    r = coord - idx * w
    return idx % n, (r < joint) | (r >= w - joint), np.maximum(np.minimum(r, w - r) - joint, 0.0)


def procedural_texture(p: dict) -> np.ndarray:
    return _pack(_pattern(p)[0])


def _pattern(p: dict) -> tuple[np.ndarray, np.ndarray | None, np.ndarray, np.ndarray, float]:
    """The pattern: linear-ish RGB albedo, the distance of each pixel from the nearest joint
    (None for the checker, which has none), each pixel's stone/plank tone and grain, and the
    joints' half-width in pixels."""
    size, n, kind = p["size"], p["count"], p["procedural"]
    face, joint_color = (np.asarray(c, dtype=np.float64) for c in p["colors"])
    rng = np.random.default_rng(p["seed"])
    y, x = np.mgrid[0:size, 0:size].astype(np.float64) + 0.5
    grain = 0.85 + 0.3 * (0.6 * _noise(size, 8, rng) + 0.4 * _noise(size, 32, rng))

    if kind == "checker":
        tone = ((np.floor(x * n / size) + np.floor(y * n / size)) % 2).astype(bool)
        img = np.where(tone[..., None], joint_color, face) * grain[..., None]
        return img, None, np.ones_like(grain), grain, 0.0

    if kind == "bricks":  # n rows (made even so the half-brick offset tiles), bricks twice as wide as tall
        rows = n + n % 2
        cols = max(1, rows // 2)
        bh = size / rows
        half = p["mortar"] * bh / 2
        row, jy, dy = _cells(y, rows, size, half)
        col, jx, dx = _cells(x + (row % 2) * size / cols / 2, cols, size, half)
        tone = 0.75 + 0.4 * rng.random((rows, cols))[row, col]
        joint, dist = jx | jy, np.minimum(dx, dy)
    elif kind == "planks":  # n vertical planks, each with one butt joint at a random height
        pw = size / n
        half = p["mortar"] * pw / 2
        col, jx, dx = _cells(x, n, size, half)
        offset = rng.random(n)[col] * size
        yy = (y + offset) % size
        jy = (yy < half) | (yy >= size - half)
        dy = np.maximum(np.minimum(yy, size - yy) - half, 0.0)
        seg = (yy >= size / 2).astype(int)
        tone = 0.7 + 0.45 * rng.random((n, 2))[col, seg]
        streaks = 0.9 + 0.1 * np.sin((x / pw * 7 + 3 * _noise(size, 4, rng)) * np.pi * 2)
        grain = grain * streaks
        joint, dist = jx | jy, np.minimum(dx, dy)
    elif kind == "flagstones":  # n x n stones, each row shifted by a random amount
        sw = size / n
        half = p["mortar"] * sw / 2
        row, jy, dy = _cells(y, n, size, half)
        col, jx, dx = _cells(x + rng.random(n)[row] * size, n, size, half)
        tone = 0.7 + 0.45 * rng.random((n, n))[row, col]
        joint, dist = jx | jy, np.minimum(dx, dy)
    else:
        raise ValueError(f"unknown procedural texture {kind!r}")
    img = np.where(joint[..., None], joint_color * (0.9 + 0.2 * grain[..., None]), face * (tone * grain)[..., None])
    return img, np.where(joint, 0.0, dist), tone, grain, half


def procedural_relief(p: dict) -> tuple[np.ndarray, np.ndarray] | None:
    """The pattern's normal map and occlusion-roughness-metalness map, both (size, size, 4)
    uint8 and linear (Rgba8Unorm), or None for a pattern without joints (the checker) or with
    ``relief = 0``.

    Height, in pixels: the joints lie `depth` below the faces, whose edges are bevelled over
    one joint width (smoothstep) and whose surface carries the grain as a fine bump. The normal
    is glTF's tangent-space one: x along +u (the image's columns), y along -v (up the image),
    from the height's periodic central differences, so it tiles like the albedo. Roughness is
    a multiplier of the material's factor: 1 in the joints, lower and varying on the faces (a
    worn stone or plank is smoother than its mortar); occlusion dims the joints' bottoms."""
    relief = p.get("relief", 1.0)
    _, dist, tone, grain, half = _pattern(p)
    if dist is None or relief <= 0:
        return None
    bevel = max(2.0 * half, 1.0)
    depth = relief * max(1.5, bevel)
    t = np.clip(dist / bevel, 0.0, 1.0)
    face = t * t * (3 - 2 * t)
    height = depth * face + relief * 0.8 * (grain - 1.0)
    hx = (np.roll(height, -1, axis=1) - np.roll(height, 1, axis=1)) / 2
    hy = (np.roll(height, -1, axis=0) - np.roll(height, 1, axis=0)) / 2
    # Rows grow down the image (+v); glTF's normal-map y points up it (-v): +hy, not -hy.
    n = np.stack([-hx, hy, np.ones_like(height)], axis=-1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    normal = _pack(n * 0.5 + 0.5)
    rough = np.clip(1.0 - face * (0.35 - 0.25 * (tone - tone.min()) / max(np.ptp(tone), 1e-9) - 0.1 * (grain - 1.0)), 0.0, 1.0)
    occlusion = 0.55 + 0.45 * face
    orm = _pack(np.stack([occlusion, rough, np.ones_like(rough)], axis=-1))
    return normal, orm


def _pack(rgb: np.ndarray) -> np.ndarray:
    out = np.full(rgb.shape[:2] + (4,), 255, dtype=np.uint8)
    out[..., :3] = np.clip(np.rint(rgb * 255), 0, 255).astype(np.uint8)
    return out
