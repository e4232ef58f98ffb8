"""Procedural, seamlessly tiling albedo textures for levels (checker, bricks, planks, flagstones).

``procedural_texture(params) -> (size, size, 4) uint8`` in sRGB, from the validated ``texture =
{ procedural = ... }`` table of a level material (see level.py). Deterministic for a given table,
so cooking is reproducible and cacheable.
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


def _cells(coord: np.ndarray, n: int, size: int, joint: float) -> tuple[np.ndarray, np.ndarray]:
    """Cell index of each pixel coordinate (n cells per `size`) and whether it lies in a joint
    of half-width `joint` pixels at the cell's edges."""
    w = size / n
    idx = np.floor(coord / w).astype(int)
    r = coord - idx * w
    return idx % n, (r < joint) | (r >= w - joint)


def procedural_texture(p: dict) -> np.ndarray:
    size, n, kind = p["size"], p["count"], p["procedural"]
    face, joint_color = (np.asarray(c, dtype=np.float64) for c in p["colors"])
    rng = np.random.default_rng(p["seed"])
    y, x = np.mgrid[0:size, 0:size].astype(np.float64) + 0.5
    grain = 0.85 + 0.3 * (0.6 * _noise(size, 8, rng) + 0.4 * _noise(size, 32, rng))

    if kind == "checker":
        tone = ((np.floor(x * n / size) + np.floor(y * n / size)) % 2).astype(bool)
        img = np.where(tone[..., None], joint_color, face) * grain[..., None]
        return _pack(img)

    if kind == "bricks":  # n rows (made even so the half-brick offset tiles), bricks twice as wide as tall
        rows = n + n % 2
        cols = max(1, rows // 2)
        bh = size / rows
        row, jy = _cells(y, rows, size, p["mortar"] * bh / 2)
        col, jx = _cells(x + (row % 2) * size / cols / 2, cols, size, p["mortar"] * bh / 2)
        tone = 0.75 + 0.4 * rng.random((rows, cols))[row, col]
        joint = jx | jy
    elif kind == "planks":  # n vertical planks, each with one butt joint at a random height
        pw = size / n
        col, jx = _cells(x, n, size, p["mortar"] * pw / 2)
        offset = rng.random(n)[col] * size
        yy = (y + offset) % size
        jy = (yy < p["mortar"] * pw / 2) | (yy >= size - p["mortar"] * pw / 2)
        seg = (yy >= size / 2).astype(int)
        tone = 0.7 + 0.45 * rng.random((n, 2))[col, seg]
        streaks = 0.9 + 0.1 * np.sin((x / pw * 7 + 3 * _noise(size, 4, rng)) * np.pi * 2)
        grain = grain * streaks
        joint = jx | jy
    elif kind == "flagstones":  # n x n stones, each row shifted by a random amount
        sw = size / n
        row, jy = _cells(y, n, size, p["mortar"] * sw / 2)
        col, jx = _cells(x + rng.random(n)[row] * size, n, size, p["mortar"] * sw / 2)
        tone = 0.7 + 0.45 * rng.random((n, n))[row, col]
        joint = jx | jy
    else:
        raise ValueError(f"unknown procedural texture {kind!r}")
    img = np.where(joint[..., None], joint_color * (0.9 + 0.2 * grain[..., None]), face * (tone * grain)[..., None])
    return _pack(img)


def _pack(rgb: np.ndarray) -> np.ndarray:
    out = np.full(rgb.shape[:2] + (4,), 255, dtype=np.uint8)
    out[..., :3] = np.clip(np.rint(rgb * 255), 0, 255).astype(np.uint8)
    return out
