"""Obstacles the runtime's flocks steer around, read from a level's authored brushes.

The CSG merges a level's columns into one mesh per object, where a cylinder is no longer a
cylinder; but the authored brushes still say exactly where each one stands. ``pillars(spec)``
returns a :class:`ir.Pillar` for every copy of every vertical cylinder brush that adds solid to
the level's geometry:

- *adds solid*: on some path to an output object the brush is only ever a union or
  intersection operand, or the first operand of a difference. On a path through a subtracted
  operand it is a cutter (a doorway's arch, the oculus, a basin's hollow), and that includes
  the cutter's own first operand. Intersection operands count: the result lies inside each of
  them, so the cylinder bounds it (a conservative obstacle).
- *vertical*: its transform keeps the local +Y axis on the world Y axis and maps the local XZ
  plane to the world XZ plane with equal scale in both directions, so its section stays a
  horizontal circle. Tilted cylinders (arches lying on their side) are left out.
- A tapered cylinder is recorded with its larger radius (the obstacle bounds the cone), and a
  pillar wholly inside another (the water in a basin, coals in a brazier) is dropped: it
  changes nothing the larger one does not already do.

The polygonal mesh (``segments`` sides) is inscribed in the circle of ``radius``, so the pillar
always contains the geometry it stands for.
"""

from __future__ import annotations

import numpy as np

from asset_pipeline import ir
from asset_pipeline.level import BrushSpec, LevelSpec

# How far (relative) the transform may be from vertical / circular and still count as a pillar:
# float noise of Euler angles like (0, 90, 0), not a real tilt.
_TOLERANCE = 1e-6


def _solid_brushes(spec: LevelSpec) -> set[str]:
    """Names of the brushes that add solid to some output object (see the module doc)."""
    objects = {o.name: o for o in spec.objects}
    solid: set[str] = set()

    def walk(name: str) -> None:
        o = objects.get(name)
        if o is None:  # a brush
            solid.add(name)
            return
        for operand in o.operands[:1] if o.op == "difference" else o.operands:
            walk(operand)

    for i in spec.outputs:
        walk(spec.objects[i].name)
    return solid


def _pillar_shape(b: BrushSpec) -> tuple[float, float] | None:
    """(world radius, world half height) of a cylinder brush whose axis is vertical and whose
    section is a circle, else None."""
    m = b.transform[:3, :3]
    x, y, z = m[:, 0], m[:, 1], m[:, 2]
    sx, sy, sz = (float(np.linalg.norm(v)) for v in (x, y, z))
    tol = _TOLERANCE * max(sx, sy, sz)
    vertical = abs(y[0]) <= tol and abs(y[2]) <= tol and abs(x[1]) <= tol and abs(z[1]) <= tol
    if not vertical or abs(sx - sz) > tol or abs(float(x @ z)) > tol * max(sx, sz):
        return None
    s = b.shape
    radius = max(s["radius"], s["radius"] if s["radius_top"] is None else s["radius_top"])
    return radius * sx, 0.5 * s["height"] * sy


def _contains(outer: ir.Pillar, inner: ir.Pillar) -> bool:
    gap = float(np.hypot(inner.centre[0] - outer.centre[0], inner.centre[1] - outer.centre[1]))
    return gap + inner.radius <= outer.radius and outer.y_min <= inner.y_min and inner.y_max <= outer.y_max


def pillars(spec: LevelSpec) -> list[ir.Pillar]:
    """The level's vertical solid cylinders, one per copy of a repeated brush, in brush order."""
    solid = _solid_brushes(spec)
    found: list[ir.Pillar] = []
    for b in spec.brushes:
        if b.kind != "cylinder" or b.name not in solid:
            continue
        shape = _pillar_shape(b)
        if shape is None:
            continue
        radius, half = shape
        count, step = b.repeat
        for k in range(count):
            c = b.transform[:3, 3] + k * np.asarray(step, dtype=np.float64)
            name = b.name if count == 1 else f"{b.name}[{k}]"
            found.append(ir.Pillar(name=name, centre=(float(c[0]), float(c[2])), radius=float(radius),
                                   y_min=float(c[1] - half), y_max=float(c[1] + half)))
    # Drop pillars inside another; of two identical ones keep the first.
    return [p for i, p in enumerate(found)
            if not any(j != i and _contains(q, p) and (not _contains(p, q) or j < i) for j, q in enumerate(found))]
