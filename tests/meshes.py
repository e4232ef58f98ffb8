"""Geometry generators shared by tests (plain lists; each test wraps them as it needs)."""

import math


def cylinder(radius: float, height: float, segments: int = 24, caps: bool = True):
    """A cylinder along +Y from y=0 to `height`: (positions, normals, triangles), counter-clockwise
    seen from outside. The side's wrap-around column is duplicated, which makes a UV seam."""
    pos, nrm, tris = [], [], []
    for i in range(segments + 1):
        a = 2 * math.pi * i / segments
        for y in (0.0, height):
            pos.append([radius * math.cos(a), y, radius * math.sin(a)])
            nrm.append([math.cos(a), 0, math.sin(a)])
    for i in range(segments):
        a, b, c, d = 2 * i, 2 * i + 1, 2 * i + 2, 2 * i + 3
        tris += [[a, b, d], [a, d, c]]
    if caps:
        for y, ny in ((0.0, -1.0), (height, 1.0)):
            centre = len(pos)
            pos.append([0, y, 0])
            nrm.append([0, ny, 0])
            for i in range(segments):
                a = 2 * math.pi * i / segments
                pos.append([radius * math.cos(a), y, radius * math.sin(a)])
                nrm.append([0, ny, 0])
            for i in range(segments):
                p, q = centre + 1 + i, centre + 1 + (i + 1) % segments
                tris.append([centre, q, p] if ny > 0 else [centre, p, q])
    return pos, nrm, tris
