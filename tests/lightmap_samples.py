"""Reading baked lightmaps back the way the runtime does, for tests that compare them with ground
truth: cook a glTF scene with the raw baker output, then sample a static instance's lightmap
bilinearly at points spread over its surface, through its lightmap region."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from asset_pipeline import bake, ir
from asset_pipeline.lightmap_post import LightmapPostSettings, read_exr
from asset_pipeline.pipeline import CookSettings, cook
from asset_pipeline.uv2 import place_on_atlas

# Raw baker output: no denoiser (it is allowed to move a chart's mean a little) and no seam
# stitching; dilation only touches texels outside the charts.
RAW = LightmapPostSettings(denoise=False, stitch=False)


def baked(path: Path, samples: int, bounces: int = 3, texels_per_metre: float = 16.0, sky_nits: float = 0.0):
    """Cook and bake `path` (no LODs, no mips, no sky unless asked) with irradiance lightmaps: (the
    scene as written, the lightmap pages as read back from their EXR files, B = H/pi per texel).
    Irradiance, not the default directional: a directional page's RGB is b0, and its L1
    reconstruction b0 (1 + 2 t.n) is not exact for concentrated lights (shading.md section 6d),
    so only irradiance pages can be held to closed forms and references within 1%."""
    out = path.with_suffix(".pack")
    settings = CookSettings(bake=bake.BakeSettings(preset="medium", lightmap_mode="irradiance", samples=samples, bounces=bounces, probe_samples=16,
                                                   post=RAW),
                            lods=False, mips=False, texels_per_metre=texels_per_metre, sky_nits=sky_nits)
    result = cook(path, out, settings)
    pages = [read_exr(out.with_name(f"{out.stem}.lightmap{p}.exr")) for p in range(len(result.scene.lightmap.pages))]
    return result.scene, pages


def surface_samples(scene: ir.Scene, pages: list[np.ndarray], node_name: str, count: int = 4096, seed: int = 1):
    """`count` points spread uniformly (stratified) over a static instance's LOD 0: (world
    positions (k, 3), B from its lightmap, bilinear (k, 3))."""
    world = scene.world_matrices()
    n = next(i for i, nd in enumerate(scene.nodes) if nd.name == node_name)
    node = scene.nodes[n]
    lod = place_on_atlas(scene.meshes[node.mesh].lods[0], node.lightmap)
    pos = lod.attributes["position"].astype(np.float64) @ world[n][:3, :3].T + world[n][:3, 3]
    tris = lod.triangles
    a, b, c = (pos[tris[:, k]] for k in range(3))
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    rng = np.random.default_rng(seed)
    pick = rng.choice(len(tris), size=count, p=area / area.sum())
    u = (np.arange(count) + rng.random(count)) / count
    v = rng.random(count)
    su = np.sqrt(u)
    bary = np.stack([1 - su, su * (1 - v), su * v], 1)
    rng.shuffle(bary)
    corners = tris[pick]
    p = np.einsum("kj,kjd->kd", bary, pos[corners])
    uv = np.einsum("kj,kjd->kd", bary, lod.attributes["uv1"].astype(np.float64)[corners])
    page = lod.lightmap_blocks[pick]
    values = np.zeros((count, 3))
    for pg in np.unique(page):
        img = pages[int(pg)]
        h, w, _ = img.shape
        sel = page == pg
        x, y = uv[sel, 0] * w - 0.5, uv[sel, 1] * h - 0.5
        x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
        fx, fy = (x - x0)[:, None], (y - y0)[:, None]
        at = lambda yy, xx: img[np.clip(yy, 0, h - 1), np.clip(xx, 0, w - 1)].astype(np.float64)  # noqa: E731
        values[sel] = (at(y0, x0) * (1 - fx) * (1 - fy) + at(y0, x0 + 1) * fx * (1 - fy)
                       + at(y0 + 1, x0) * (1 - fx) * fy + at(y0 + 1, x0 + 1) * fx * fy)
    return p, values


def polygon_irradiance(x: np.ndarray, n: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Irradiance at points x (k, 3) with normal n from a uniform Lambertian polygon of unit
    radiance facing them (Lambert's closed form, notes/pathtracing.md): (1/2) sum_i theta_i
    (n . unit(a_i x a_i+1)), a_i the unit directions to the vertices."""
    out = np.zeros(len(x))
    for i in range(len(polygon)):
        a = polygon[i] - x
        b = polygon[(i + 1) % len(polygon)] - x
        a /= np.linalg.norm(a, axis=1, keepdims=True)
        b /= np.linalg.norm(b, axis=1, keepdims=True)
        theta = np.arccos(np.clip((a * b).sum(1), -1, 1))
        g = np.cross(a, b)
        g /= np.linalg.norm(g, axis=1, keepdims=True)
        out += theta * (g @ n)
    return np.abs(out) / 2
