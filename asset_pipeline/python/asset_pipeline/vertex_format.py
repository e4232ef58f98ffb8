"""What the pack's 16-bit texture coordinates can hold (engine/pack/src/vertex.rs): each set of a
mesh (uv0, texcoord1) is stored as unorm16 over the bounds of all its LODs (its whole mesh's for a
chunk), so a set spanning R units is off by up to R / 131070; over a texture of S texels a unit
(its size times the slot's KHR_texture_transform scale) that is R * S / 131070 texels. The cook
warns where that passes a quarter texel: a tiled floor whose coordinates run to a few hundred
on a 2048² texture, say. (uv1, the lightmap's, is in page texels or a block's unit square and
stays far below.)"""

from __future__ import annotations

import numpy as np

from asset_pipeline import ir

QUARTER_TEXEL = 0.25
STEPS = 65535  # unorm16: the range is cut into this many steps; rounding is off by half a step


def _span(mesh: ir.Mesh, k: int, name: str) -> float:
    """The largest extent (u or v) of set `name` over the mesh's LODs and its `uv_bounds`."""
    boxes = [ir.uv_bounds(lod)[k] for lod in mesh.lods if name in lod.attributes]
    if mesh.uv_bounds is not None:
        boxes.append(mesh.uv_bounds[k])
    if not boxes:
        return 0.0
    b = np.array(boxes, np.float64)
    return float(max(b[:, 2].max() - b[:, 0].min(), b[:, 3].max() - b[:, 1].min()))


def uv_precision_warnings(scene: ir.Scene) -> list[str]:
    """One line per (mesh, coordinate set) whose 16-bit storage misses a quarter texel of the
    densest texture its materials sample through that set."""
    out = []
    for mesh in scene.meshes:
        used = sorted({int(k) for lod in mesh.lods for k in np.unique(lod.materials)})
        for k, tex_coord, name in ((0, 0, "uv0"), (2, 1, "texcoord1")):
            densest: tuple[float, str] | None = None
            for m in (scene.materials[i] for i in used if i < len(scene.materials)):
                for slot in ir.UV_SLOTS:
                    t = getattr(m, f"{slot}_texture")
                    uv = m.uv(slot)
                    if t is None or uv["tex_coord"] != tex_coord or t >= len(scene.textures):
                        continue
                    tex = scene.textures[t]
                    density = max(tex.width, tex.height) * max(abs(uv["scale"][0]), abs(uv["scale"][1]))
                    if densest is None or density > densest[0]:
                        densest = (density, tex.name)
            if densest is None:
                continue
            span = _span(mesh, k, name)
            texels = span / STEPS * 0.5 * densest[0]
            if texels > QUARTER_TEXEL:
                out.append(f"mesh '{mesh.name}': its {name} spans {span:.1f} units, so its 16-bit coordinates are off by up to "
                           f"{texels:.2f} texels of texture '{densest[1]}' (more than a quarter texel; keep them within "
                           f"{QUARTER_TEXEL * 2 * STEPS / densest[0]:.0f} units, or split the mesh)")
    return out
