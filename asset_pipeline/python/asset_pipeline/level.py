"""Level specs: a TOML file of CSG brushes, materials, props, lights and spawn points.

``load_level(path) -> LevelSpec`` parses and validates; ``csg.build_level`` turns the spec into
a scene. Every problem is a :class:`CookError` of one line, ``<file>:<line>: <key path>: <reason>``
(``<file>: <key path>: <reason>`` when the line cannot be found; TOML syntax errors give
``<file>:<line>:<col>: <reason>``).

Schema (metres, degrees, +Y up; colours linear RGB(A) in 0..1 unless said otherwise; every key not
listed is an error; ``name`` is unique within its section, brushes and objects share one namespace):

    [level]
    name = "temple"                 # default: the file's stem
    texels_per_metre = 16           # lightmap density of static objects (default 16); it goes to
                                    # scene.lightmap (a layout with no pages until the uv2 stage)
    sky = { color = [0.5, 0.7, 1.0], intensity = 5000 }   # intensity: luminance in nits; optional

    [[materials]]
    name = "stone"                  # required
    base_color = [1, 1, 1]          # linear RGB, multiplies the texture (opaque)
    texture = "stone.png"           # a PNG beside the toml, or a procedural texture (sRGB colours):
    # texture = { procedural = "checker"|"bricks"|"planks"|"flagstones", size = 256 (pixels, power
    #             of two), count = 8 (cells/rows/planks per repeat), mortar = 0.06 (joint width as a
    #             fraction of a cell), colors = [[r,g,b], [r,g,b]] (sRGB; face and joint), seed = 0,
    #             relief = 1.0 (bricks, planks, flagstones: the depth of the joints, which also
    #             gives the material a normal map and an occlusion-roughness map; 0: none) }
    uv_scale = 1.0                  # metres per texture repeat (world-space box projection)
    roughness = 0.8                 # 0..1
    metallic = 0.0                  # 0..1
    emissive = [0, 0, 0]            # emitted radiance in nits per channel
    double_sided = false

    [[brushes]]                     # a solid primitive, centred on its local origin
    name = "hall"                   # required
    kind = "box"                    # box: size = [x, y, z]
                                    # cylinder: radius, height, radius_top (default radius; 0 = cone),
                                    #           segments (default 32); axis +Y
                                    # sphere: radius, segments (default 32)
                                    # extrude: points = [[x, y], ...] (a simple polygon in the local XY
                                    #          plane, either winding), extruded from z = -height/2
                                    #          to +height/2
    material = "stone"              # required: faces of this brush get this material, also where
                                    # the brush cuts another (a doorway's reveal is the cutter's)
    translation = [0, 0, 0]
    rotation = [0, 0, 0]            # Euler degrees about X, then Y, then Z (R = Rz Ry Rx)
    scale = [1, 1, 1]               # > 0; applied first (p' = T R S p)
    repeat = { count = 6, step = [0, 0, 3] }   # optional: count copies, each `step` further on

    [[objects]]                     # a CSG combination of brushes and earlier objects
    name = "temple"
    op = "difference"               # union | difference (first minus the rest) | intersection
    operands = ["shell", "hall", "door"]   # names of brushes or of objects defined above
    static = true                   # static geometry gets lightmaps (default true)
    texels_per_metre = 32           # optional override of the level's density (static objects)
    # The level's geometry is every object that is not an operand of another object: one mesh each.
    # A level needs at least one object or one prop.

    [[props]]                       # a placed glTF model
    name = "statue"
    gltf = "props/statue.glb"       # relative to the toml, inside its folder tree (as are textures
                                    # and characters' assets, and the props' own buffers and images)
    translation = [0, 0, 0]
    rotation = [0, 0, 0]
    scale = [1, 1, 1]
    static = false                  # static props are baked into the lightmaps (this switch decides
                                    # for every mesh node of the prop)

    [[lights]]                      # physical units, as ir.Light
    name = "sun"
    kind = "sun"                    # sun: direction, intensity in lux, angular_radius_deg
                                    # point: position, intensity in candela, range (optional)
                                    # spot: point's keys + direction, inner_cone_deg, outer_cone_deg
                                    # rect: position, direction (the way it emits), size = [w, h],
                                    #       intensity in nits, range (optional)
    color = [1, 1, 1]

    [[reflection_probes]]           # a baked cube of the radiance around a point, for glossy
                                    # surfaces (only a baked level gets them)
    name = "hall"                   # default: reflection_probe_<i>
    position = [0, 2, 0]            # the capture point, inside the box
    box_min = [-5, 0, -5]           # the world-space box of what it reflects: the room's walls
    box_max = [5, 4, 5]             # (parallax correction) and where it applies (influence)
    blend_distance = 1.0            # metres inside the box's faces over which it fades out
                                    # (default 0.5; >= 0)

    [[spawns]]
    name = "player"
    kind = "player"                 # player | character | boids | particles
    position = [0, 0, 0]
    rotation = [0, 0, 0]            # Euler degrees as brushes
    params = { }                    # kind-specific, see SPAWN_PARAMS; particles may set
                                    # blend = "alpha" | "additive" (default: alpha); boids
                                    # need asset = a glTF holding one mesh, the bird (facing +Z,
                                    # up +Y, in metres), which the cooker packs for the runtime
"""

from __future__ import annotations

import math
import re
import sys
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from asset_pipeline import ir
from asset_pipeline._core import CookError

PROCEDURAL = ("checker", "bricks", "planks", "flagstones")
BRUSH_KINDS = ("box", "cylinder", "sphere", "extrude")
OPS = ("union", "difference", "intersection")
LIGHT_KINDS = ("sun", "point", "spot", "rect")
# The parameters each spawn kind understands (the runtime's contract; extend here).
SPAWN_PARAMS = {
    "player": {"speed"},
    "character": {"asset", "animation", "speed", "route", "walk_speed"},
    "boids": {"count", "radius", "speed", "asset"},
    "particles": {"rate_per_s", "lifetime_s", "speed", "spread_deg", "size", "color", "gravity", "blend"},
}
# Particle blend modes: "alpha" (soft, sorted back to front: spray, smoke) or "additive" (adds
# light, order-free: sparks, fire). Absent: alpha.
PARTICLE_BLENDS = ("alpha", "additive")


@dataclass
class MaterialSpec:
    name: str
    base_color: tuple[float, float, float, float]
    texture: str | dict | None  # a path relative to the toml, or validated procedural parameters
    uv_scale: float
    roughness: float
    metallic: float
    emissive: tuple[float, float, float]
    double_sided: bool


@dataclass
class BrushSpec:
    name: str
    kind: str
    shape: dict  # the kind's own keys (size, radius, height, ...), defaults filled in
    transform: np.ndarray  # (4, 4) float64, p' = transform @ p
    material: int  # index into LevelSpec.materials
    repeat: tuple[int, tuple[float, float, float]] = (1, (0.0, 0.0, 0.0))


@dataclass
class ObjectSpec:
    name: str
    op: str
    operands: list[str]
    static: bool
    texels_per_metre: float | None


@dataclass
class PropSpec:
    name: str
    gltf: str  # relative to the toml
    transform: np.ndarray
    static: bool


@dataclass
class LevelSpec:
    path: Path
    name: str
    texels_per_metre: float
    sky: ir.Sky | None
    materials: list[MaterialSpec] = field(default_factory=list)
    brushes: list[BrushSpec] = field(default_factory=list)
    objects: list[ObjectSpec] = field(default_factory=list)
    props: list[PropSpec] = field(default_factory=list)
    lights: list[ir.Light] = field(default_factory=list)
    spawns: list[ir.Spawn] = field(default_factory=list)
    reflection_probes: list[ir.ReflectionProbe] = field(default_factory=list)
    text: str = ""  # the source, to find line numbers for errors found later (e.g. empty CSG)
    allow_external: bool = False  # files outside the level's folder may be read (--allow-external-uris)

    def error(self, key: tuple, reason: str) -> CookError:
        return _error(self.path, self.text, key, reason)

    def check_file(self, key: tuple, relative: str, what: str) -> Path:
        """The path of a file the level names at `key` (see _Checker.file); CookError if not allowed or missing."""
        _Checker(self.path, self.text, self.allow_external).file(key, relative, what)
        return self.path.parent / relative

    @property
    def outputs(self) -> list[int]:
        """Indices of the objects that become meshes: those no other object uses."""
        used = {n for o in self.objects for n in o.operands}
        return [i for i, o in enumerate(self.objects) if o.name not in used]


# ---- errors with a line number ----------------------------------------------------------------


def _key_text(key: tuple) -> str:
    s = ""
    for k in key:
        s += f"[{k}]" if isinstance(k, int) else (f".{k}" if s else k)
    return s


def _find_line(text: str, key: tuple) -> int | None:
    """Best effort: the line of `key` (("brushes", 3, "size")) in the TOML source, else of the
    nearest enclosing table that can be found. Handles [table], [[array]] and `key =` lines."""
    lines = text.splitlines()
    header = re.compile(r"^\s*\[")
    found, lo, hi = None, 0, len(lines)
    table: list[str] = []
    i = 0
    while i < len(key):
        k = key[i]
        nxt = key[i + 1] if i + 1 < len(key) else None
        if i == 0 and isinstance(nxt, int):  # [[k]] number nxt
            pat = re.compile(r"^\s*\[\[\s*" + re.escape(k) + r"\s*\]\]")
            hits = [n for n in range(lo, hi) if pat.match(lines[n])]
            if nxt >= len(hits):
                break
            found, lo = hits[nxt], hits[nxt] + 1
            hi = next((n for n in range(lo, len(lines)) if header.match(lines[n])), len(lines))
            i += 2
            continue
        if isinstance(k, int):
            break
        table.append(k)
        # a `k = ...` line inside the current table, else a [a.b.k] header
        pat = re.compile(r"^\s*" + re.escape(k) + r"\s*=|[{,]\s*" + re.escape(k) + r"\s*=")
        hit = next((n for n in range(lo, hi) if pat.search(lines[n])), None)
        if hit is not None:
            return hit + 1
        hpat = re.compile(r"^\s*\[\[?\s*" + r"\s*\.\s*".join(map(re.escape, table)) + r"\s*\]")
        hit = next((n for n in range(len(lines)) if hpat.match(lines[n])), None)
        if hit is None:
            break
        found, lo = hit, hit + 1
        hi = next((n for n in range(lo, len(lines)) if header.match(lines[n])), len(lines))
        i += 1
    return None if found is None else found + 1


def _one_line(s: str) -> str:
    """`s` with its line breaks and other unprintable characters escaped (a name or key from the
    file may hold a newline): the message stays one line."""
    return s if s.isprintable() else "".join(c if c.isprintable() else repr(c)[1:-1] for c in s)


def _error(path: Path, text: str, key: tuple, reason: str) -> CookError:
    line = _find_line(text, key)
    where = f"{path}:{line}" if line else f"{path}"
    return CookError(f"{where}: {_one_line(_key_text(key))}: {_one_line(reason)}")


# ---- typed readers: each takes (checker, value, key) and returns the clean value --------------


def escapes(root: Path, relative: str) -> bool:
    """Whether `relative`, a path a content file names, reaches outside the folder tree `root`:
    absolute, a file: URI, or `..` or a symbolic link that leads out (checked on the resolved
    path)."""
    if relative.lower().startswith("file:") or Path(relative).is_absolute():
        return True
    root = root.resolve()
    return not (root / relative).resolve().is_relative_to(root)


class _Checker:
    def __init__(self, path: Path, text: str, allow_external: bool = False):
        self.path, self.text, self.allow_external = path, text, allow_external

    def fail(self, key: tuple, reason: str):
        raise _error(self.path, self.text, key, reason)

    def file(self, key: tuple, relative: str, what: str) -> None:
        """`relative` (from the level) must name a file inside the level's folder tree (unless
        external paths are allowed) that exists."""
        if not self.allow_external and escapes(self.path.parent, relative):
            self.fail(key, f"{what} '{relative}' reaches outside the level's folder '{self.path.parent.resolve()}' "
                           "(pass --allow-external-uris to allow it)")
        if not (self.path.parent / relative).is_file():
            self.fail(key, f"{what} '{relative}' not found (looked in {self.path.parent})")

    def table(self, value, key: tuple, fields: dict, what: str = "") -> dict:
        """Check `value` is a table with only `fields` keys; read each with its reader.
        fields: key -> (reader, default); default REQUIRED means it must be present."""
        if not isinstance(value, dict):
            self.fail(key, f"expected a table, got {_tname(value)}")
        for k in value:
            if k not in fields:
                self.fail(key + (k,), f"unknown key '{k}'{what} (expected one of: {', '.join(fields)})")
        out = {}
        for k, (reader, default) in fields.items():
            if k in value:
                out[k] = reader(self, value[k], key + (k,))
            elif default is REQUIRED:
                self.fail(key + (k,), "missing")
            else:
                out[k] = default
        return out


REQUIRED = object()


def _tname(v) -> str:
    if type(v) is int and not _fits_float(v):
        return "an integer too large for a number"
    return {bool: "a boolean", int: "an integer", float: "a number", str: "a string", list: "an array",
            dict: "a table"}.get(type(v), type(v).__name__)


def _fits_float(v: int) -> bool:
    """Whether an integer converts to a float (TOML integers have no bound; past ~1.8e308
    float() raises OverflowError)."""
    return abs(v) <= sys.float_info.max


def _is_num(v) -> bool:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return False
    return math.isfinite(v) if isinstance(v, float) else _fits_float(v)


def number(lo: float | None = None, hi: float | None = None, lo_open: bool = False):
    def read(c: _Checker, v, key):
        if not _is_num(v):
            c.fail(key, f"expected a number, got {_tname(v)}")
        if lo is not None and (v <= lo if lo_open else v < lo):
            c.fail(key, f"must be {'>' if lo_open else '>='} {lo}, got {v}")
        if hi is not None and v > hi:
            c.fail(key, f"must be <= {hi}, got {v}")
        return float(v)
    return read


def integer(lo: int):
    def read(c: _Checker, v, key):
        if not isinstance(v, int) or isinstance(v, bool):
            c.fail(key, f"expected an integer, got {_tname(v)}")
        if v < lo:
            c.fail(key, f"must be >= {lo}, got {v}")
        return v
    return read


def vector(n: int | tuple[int, ...], lo: float | None = None, lo_open: bool = False, hi: float | None = None):
    ns = (n,) if isinstance(n, int) else n
    elem = number(lo, hi, lo_open)

    def read(c: _Checker, v, key):
        if not isinstance(v, list) or len(v) not in ns:
            c.fail(key, f"expected an array of {' or '.join(map(str, ns))} numbers, got {_tname(v) if not isinstance(v, list) else f'{len(v)} values'}")
        return tuple(elem(c, x, key) for x in v)
    return read


def string(c: _Checker, v, key):
    if not isinstance(v, str) or not v:
        c.fail(key, f"expected a non-empty string, got {_tname(v)}")
    return v


def boolean(c: _Checker, v, key):
    if not isinstance(v, bool):
        c.fail(key, f"expected true or false, got {_tname(v)}")
    return v


def choice(options: tuple[str, ...]):
    def read(c: _Checker, v, key):
        if v not in options:
            c.fail(key, f"unknown value {v!r} (expected one of: {', '.join(options)})")
        return v
    return read


def names(c: _Checker, v, key):
    if not isinstance(v, list) or not v:
        c.fail(key, "expected a non-empty array of names")
    return [string(c, x, key + (i,)) for i, x in enumerate(v)]


def array_of_tables(c: _Checker, v, key):
    if not isinstance(v, list) or not all(isinstance(x, dict) for x in v):
        c.fail(key, f"expected an array of tables ([[{key[-1]}]]), got {_tname(v)}")
    return v


def polygon(c: _Checker, v, key):
    if not isinstance(v, list) or len(v) < 3:
        c.fail(key, "expected an array of at least 3 [x, y] points")
    pts = np.array([vector(2)(c, p, key + (i,)) for i, p in enumerate(v)])
    area = 0.5 * float(np.sum(pts[:, 0] * np.roll(pts[:, 1], -1) - np.roll(pts[:, 0], -1) * pts[:, 1]))
    if abs(area) < 1e-9:
        c.fail(key, "the polygon has no area")
    return [tuple(p) for p in pts]


def params(c: _Checker, v, key):
    if not isinstance(v, dict):
        c.fail(key, f"expected a table, got {_tname(v)}")
    for k, x in v.items():
        flat = isinstance(x, list) and all(_is_num(e) for e in x)
        nested = isinstance(x, list) and all(isinstance(e, list) and all(_is_num(y) for y in e) for e in x)
        if not (_is_num(x) or isinstance(x, (str, bool)) or flat or nested):
            c.fail(key + (k,), f"expected a number, string, boolean or array of numbers (or of arrays of numbers), got {_tname(x)}")
    return dict(v)


def waypoints(c: _Checker, v, key):
    """A character's route: one or more [x, y, z] points in level space."""
    if not isinstance(v, list) or not v:
        c.fail(key, f"expected an array of [x, y, z] waypoints, got {_tname(v) if v else 'an empty array'}")
    return [list(vector(3)(c, p, key + (i,))) for i, p in enumerate(v)]


# Spawn params whose values have a shape of their own; the others are kept as authored.
SPAWN_PARAM_READERS = {
    ("character", "route"): waypoints,
    ("character", "walk_speed"): number(0.0, lo_open=True),
}


# ---- transforms -------------------------------------------------------------------------------


def euler_matrix(deg) -> np.ndarray:
    """R = Rz Ry Rx for Euler angles in degrees (about X first)."""
    x, y, z = np.radians(deg)
    cx, sx, cy, sy, cz, sz = np.cos(x), np.sin(x), np.cos(y), np.sin(y), np.cos(z), np.sin(z)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


def euler_quaternion(deg) -> tuple[float, float, float, float]:
    """The same rotation as euler_matrix, as a unit quaternion (x, y, z, w)."""
    h = np.radians(deg) / 2
    qs = [np.array([*(np.sin(a) * np.eye(3)[i]), np.cos(a)]) for i, a in enumerate(h)]

    def mul(a, b):  # Hamilton product, xyzw
        av, aw, bv, bw = a[:3], a[3], b[:3], b[3]
        return np.array([*(aw * bv + bw * av + np.cross(av, bv)), aw * bw - av @ bv])

    return tuple(float(x) for x in mul(qs[2], mul(qs[1], qs[0])))


def trs(t, r, s) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = euler_matrix(r) * np.asarray(s, dtype=float)
    m[:3, 3] = t
    return m


TRANSFORM = {
    "translation": (vector(3), (0.0, 0.0, 0.0)),
    "rotation": (vector(3), (0.0, 0.0, 0.0)),
    "scale": (vector(3, lo=0, lo_open=True), (1.0, 1.0, 1.0)),
}

# ---- sections ---------------------------------------------------------------------------------

SHAPE_KEYS = {
    "box": {"size": (vector(3, lo=0, lo_open=True), REQUIRED)},
    "cylinder": {"radius": (number(0, lo_open=True), REQUIRED), "height": (number(0, lo_open=True), REQUIRED),
                 "radius_top": (number(0), None), "segments": (integer(3), 32)},
    "sphere": {"radius": (number(0, lo_open=True), REQUIRED), "segments": (integer(4), 32)},
    "extrude": {"points": (polygon, REQUIRED), "height": (number(0, lo_open=True), REQUIRED)},
}

def _two_colors(c: _Checker, v, key):
    if not isinstance(v, list) or len(v) != 2:
        c.fail(key, "expected two [r, g, b] sRGB colours (face, joint)")
    return [vector(3, lo=0, hi=1)(c, x, key + (i,)) for i, x in enumerate(v)]


TEXTURE_KEYS = {
    "procedural": (choice(PROCEDURAL), REQUIRED),
    "size": (integer(8), 256),
    "count": (integer(1), 8),
    "mortar": (number(0, 0.5), 0.06),
    "colors": (_two_colors, [(0.8, 0.8, 0.8), (0.4, 0.4, 0.4)]),
    "seed": (integer(0), 0),
    "relief": (number(0, 4), 1.0),
}


def _texture(c: _Checker, v, key):
    if isinstance(v, str):
        if not v.lower().endswith(".png"):
            c.fail(key, f"texture files must be PNG, got '{v}'")
        c.file(key, v, "texture file")
        return v
    if isinstance(v, dict):
        t = c.table(v, key, TEXTURE_KEYS)
        if t["size"] & (t["size"] - 1) or t["size"] > 4096:
            c.fail(key + ("size",), f"must be a power of two up to 4096, got {t['size']}")
        return t
    c.fail(key, f"expected a PNG path or a {{ procedural = ... }} table, got {_tname(v)}")


MATERIAL_KEYS = {
    "name": (string, REQUIRED),
    "base_color": (vector(3, lo=0, hi=1), (1.0, 1.0, 1.0)),  # opaque: level geometry is solid
    "texture": (_texture, None),
    "uv_scale": (number(0, lo_open=True), 1.0),
    "roughness": (number(0, 1), 0.8),
    "metallic": (number(0, 1), 0.0),
    "emissive": (vector(3, lo=0), (0.0, 0.0, 0.0)),
    "double_sided": (boolean, False),
}

LIGHT_KEYS = {
    "name": (string, REQUIRED),
    "kind": (choice(LIGHT_KINDS), REQUIRED),
    "color": (vector(3, lo=0), (1.0, 1.0, 1.0)),
    "intensity": (number(0), REQUIRED),
    "position": (vector(3), REQUIRED),
    "direction": (vector(3), REQUIRED),
    "range": (number(0, lo_open=True), None),
    "inner_cone_deg": (number(0, 90), 0.0),
    "outer_cone_deg": (number(0, 90, lo_open=True), 45.0),
    "size": (vector(2, lo=0, lo_open=True), REQUIRED),
    "angular_radius_deg": (number(0, 45), 0.2665),
}
LIGHT_KIND_KEYS = {
    "sun": {"name", "kind", "color", "intensity", "direction", "angular_radius_deg"},
    "point": {"name", "kind", "color", "intensity", "position", "range"},
    "spot": {"name", "kind", "color", "intensity", "position", "direction", "range", "inner_cone_deg", "outer_cone_deg"},
    "rect": {"name", "kind", "color", "intensity", "position", "direction", "size", "range"},
}


REFLECTION_PROBE_KEYS = ("name", "position", "box_min", "box_max", "blend_distance")


def _reflection_probe(c: _Checker, raw, key: tuple, i: int) -> ir.ReflectionProbe:
    """One [[reflection_probes]] entry; every message names the probe."""
    if not isinstance(raw, dict):
        c.fail(key, f"expected a table, got {_tname(raw)}")
    name = string(c, raw["name"], key + ("name",)) if "name" in raw else f"reflection_probe_{i}"
    what = f"reflection probe '{name}'"
    for k in raw:
        if k not in REFLECTION_PROBE_KEYS:
            c.fail(key + (k,), f"{what}: unknown key '{k}' (expected one of: {', '.join(REFLECTION_PROBE_KEYS)})")

    def point(k: str) -> tuple[float, float, float]:
        if k not in raw:
            c.fail(key + (k,), f"{what}: missing")
        v = raw[k]
        if not isinstance(v, list) or len(v) != 3 or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v):
            c.fail(key + (k,), f"{what}: expected an array of 3 numbers, got {_tname(v) if not isinstance(v, list) else f'{len(v)} values'}")
        if not all(_is_num(x) for x in v):
            c.fail(key + (k,), f"{what}: every number must be finite, got [{', '.join(str(x) for x in v)}]")
        return tuple(float(x) for x in v)

    position, lo, hi = point("position"), point("box_min"), point("box_max")
    blend = raw.get("blend_distance", 0.5)
    if not isinstance(blend, (int, float)) or isinstance(blend, bool):
        c.fail(key + ("blend_distance",), f"{what}: expected a number, got {_tname(blend)}")
    if not _is_num(blend) or blend < 0:
        c.fail(key + ("blend_distance",), f"{what}: blend_distance must be a finite number >= 0, got {blend}")
    empty = [a for a, l, h in zip("xyz", lo, hi) if not l < h]
    if empty:
        c.fail(key + ("box_max",), f"{what}: the box is empty (box_max must exceed box_min on every axis; it does not on "
                                   f"{', '.join(empty)}): {list(lo)}..{list(hi)}")
    outside = [a for a, p, l, h in zip("xyz", position, lo, hi) if not l <= p <= h]
    if outside:
        c.fail(key + ("position",), f"{what}: the capture point {list(position)} is outside its box {list(lo)}..{list(hi)} "
                                    f"(on {', '.join(outside)})")
    return ir.ReflectionProbe(name=name, position=position, box_min=lo, box_max=hi, blend_distance=float(blend))


def _claim(c: _Checker, seen: dict, name: str, section: str, i: int) -> None:
    """Names are unique within a section (brushes and objects share one namespace)."""
    if name in seen:
        c.fail((section, i, "name"), f"'{name}' is already the name of {seen[name]}")
    seen[name] = f"{section}[{i}]"


def _unique(c: _Checker, items: list[dict], section: str) -> None:
    seen: dict[str, str] = {}
    for i, it in enumerate(items):
        _claim(c, seen, it["name"], section, i)


def _kinded(c: _Checker, raw: dict, key: tuple, kinds: tuple) -> str:
    """Read `kind` first, so the unknown-key message can say which keys the kind has."""
    if not isinstance(raw, dict):
        c.fail(key, f"expected a table, got {_tname(raw)}")
    if "kind" not in raw:
        c.fail(key + ("kind",), "missing")
    return choice(kinds)(c, raw["kind"], key + ("kind",))


# The most triangles the brushes may make before CSG (an estimate per kind, times repeats): a
# typing slip such as `segments = 1000000000` or a huge repeat count gets a message instead of
# exhausting memory in manifold3d. The demo level uses well under 1% of it.
MAX_BRUSH_TRIANGLES = 1 << 22


def brush_triangles(kind: str, shape: dict) -> int:
    """About how many triangles manifold3d makes for one copy of a brush."""
    if kind == "cylinder":
        return 4 * shape["segments"]
    if kind == "sphere":
        return shape["segments"] ** 2
    if kind == "extrude":
        return 4 * len(shape["points"])
    return 12


def _check_brush_budget(c: "_Checker", spec: "LevelSpec") -> None:
    total = 0
    for i, b in enumerate(spec.brushes):
        count = b.repeat[0]
        total += brush_triangles(b.kind, b.shape) * count
        if total > MAX_BRUSH_TRIANGLES:
            key = ("brushes", i) + (("repeat", "count") if count > 1 else ("segments",) if "segments" in b.shape else ())
            c.fail(key, f"the brushes up to '{b.name}' make about {total} triangles, more than the cooker's limit of "
                        f"{MAX_BRUSH_TRIANGLES} (lower segments or repeat counts)")


def load_level(path: str | Path, allow_external_uris: bool = False) -> LevelSpec:
    """Parse and validate the level spec at `path`. Every file it names (textures, props,
    characters) must lie inside the level's folder tree unless `allow_external_uris`. Raises
    CookError naming file, line and key."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise CookError(f"{path}: cannot read the level: {e}") from None
    return parse_level(text, path, allow_external_uris)


def parse_level(text: str, path: str | Path, allow_external_uris: bool = False) -> LevelSpec:
    """`load_level` of `text`, the contents of the level file `path` (which names it in errors
    and is where the files it names are looked for). Raises CookError naming file, line and key."""
    path = Path(path)
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        msg = str(e)
        m = re.search(r"\s*\(at line (\d+), column (\d+)\)", msg)
        if m:
            raise CookError(f"{path}:{m[1]}:{m[2]}: {msg[:m.start()] + msg[m.end():]}") from None
        raise CookError(f"{path}: {msg}") from None
    except ValueError as e:
        # tomllib's own int(): an integer of more digits than Python converts (4300).
        raise CookError(f"{path}: not a valid level TOML: {_one_line(str(e).split(';')[0])}") from None
    except RecursionError:
        # tomllib parses nested arrays and inline tables recursively.
        raise CookError(f"{path}: not a valid level TOML: arrays or inline tables nested too deeply") from None

    c = _Checker(path, text, allow_external_uris)
    top = c.table(doc, (), {
        "level": (lambda c, v, k: v, {}), "materials": (array_of_tables, []), "brushes": (array_of_tables, []),
        "objects": (array_of_tables, []), "props": (array_of_tables, []), "lights": (array_of_tables, []),
        "spawns": (array_of_tables, []), "reflection_probes": (array_of_tables, []),
    })
    lvl = c.table(top["level"], ("level",), {
        "name": (string, path.stem),
        "texels_per_metre": (number(0, lo_open=True), 16.0),
        "sky": (lambda c, v, k: c.table(v, k, {"color": (vector(3, lo=0), (0.5, 0.7, 1.0)),
                                                "intensity": (number(0), 1.0)}), None),
    })
    spec = LevelSpec(path=path, name=lvl["name"], texels_per_metre=lvl["texels_per_metre"],
                     sky=None if lvl["sky"] is None else ir.Sky(**lvl["sky"]), text=text, allow_external=allow_external_uris)

    mats = [c.table(m, ("materials", i), MATERIAL_KEYS) for i, m in enumerate(top["materials"])]
    _unique(c, mats, "materials")
    spec.materials = [MaterialSpec(**{**m, "base_color": (*m["base_color"], 1.0)}) for m in mats]
    mat_index = {m.name: i for i, m in enumerate(spec.materials)}

    solids: dict[str, str] = {}  # brush/object name -> where it was defined
    for i, raw in enumerate(top["brushes"]):
        key = ("brushes", i)
        kind = _kinded(c, raw, key, BRUSH_KINDS)
        common = {"name": (string, REQUIRED), "kind": (string, REQUIRED), "material": (string, REQUIRED), **TRANSFORM,
                  "repeat": (lambda c, v, k: c.table(v, k, {"count": (integer(1), REQUIRED),
                                                            "step": (vector(3), REQUIRED)}), None)}
        b = c.table(raw, key, {**common, **SHAPE_KEYS[kind]}, what=f" for a {kind} brush")
        if b["material"] not in mat_index:
            c.fail(key + ("material",), f"unknown material '{b['material']}' (defined: {', '.join(mat_index) or 'none'})")
        _claim(c, solids, b["name"], "brushes", i)
        shape = {k: b[k] for k in SHAPE_KEYS[kind]}
        rep = b["repeat"]
        spec.brushes.append(BrushSpec(
            name=b["name"], kind=kind, shape=shape, transform=trs(b["translation"], b["rotation"], b["scale"]),
            material=mat_index[b["material"]], repeat=(1, (0.0, 0.0, 0.0)) if rep is None else (rep["count"], rep["step"])))

    _check_brush_budget(c, spec)
    brush_names = {b.name for b in spec.brushes}
    for i, raw in enumerate(top["objects"]):
        key = ("objects", i)
        o = c.table(raw, key, {
            "name": (string, REQUIRED), "op": (choice(OPS), REQUIRED), "operands": (names, REQUIRED),
            "static": (boolean, True), "texels_per_metre": (number(0, lo_open=True), None),
        })
        _claim(c, solids, o["name"], "objects", i)
        defined = {x.name for x in spec.objects}
        for j, n in enumerate(o["operands"]):
            if n == o["name"]:
                c.fail(key + ("operands", j), f"object '{n}' cannot be its own operand")
            if n not in brush_names and n not in defined:
                later = " (objects must be defined before they are used)" if any(
                    isinstance(r, dict) and r.get("name") == n for r in top["objects"]) else ""
                c.fail(key + ("operands", j), f"'{n}' is not a brush or an object defined above{later}")
        if o["texels_per_metre"] is not None and not o["static"]:
            c.fail(key + ("texels_per_metre",), "only static objects have lightmaps")
        if o["op"] != "union" and len(o["operands"]) < 2:
            c.fail(key + ("operands",), f"a {o['op']} needs at least two operands")
        spec.objects.append(ObjectSpec(**o))
    props = []
    for i, raw in enumerate(top["props"]):
        key = ("props", i)
        p = c.table(raw, key, {"name": (string, REQUIRED), "gltf": (string, REQUIRED), **TRANSFORM,
                               "static": (boolean, False)})
        if not p["gltf"].lower().endswith((".gltf", ".glb")):
            c.fail(key + ("gltf",), f"expected a .gltf or .glb file, got '{p['gltf']}'")
        c.file(key + ("gltf",), p["gltf"], "prop file")
        props.append(p)
        spec.props.append(PropSpec(p["name"], p["gltf"], trs(p["translation"], p["rotation"], p["scale"]), p["static"]))
    _unique(c, props, "props")

    lights = []
    for i, raw in enumerate(top["lights"]):
        key = ("lights", i)
        kind = _kinded(c, raw, key, LIGHT_KINDS)
        fields = {k: v for k, v in LIGHT_KEYS.items() if k in LIGHT_KIND_KEYS[kind]}
        l = c.table(raw, key, fields, what=f" for a {kind} light")
        lights.append(l)
        d = l.get("direction")
        if d is not None:
            with np.errstate(over="ignore"):
                n = float(np.linalg.norm(d))
            if not math.isfinite(n):
                # Its squares overflow ([1e200, 1e200, 0]): scaled by its largest component first.
                d = tuple(float(x) for x in np.divide(d, max(abs(x) for x in d)))
                n = float(np.linalg.norm(d))
            if n < 1e-9:
                c.fail(key + ("direction",), "must not be the zero vector")
            d = tuple(float(x) / n for x in d)
        if kind == "spot" and l["inner_cone_deg"] > l["outer_cone_deg"]:
            c.fail(key + ("inner_cone_deg",), f"must be <= outer_cone_deg ({l['outer_cone_deg']})")
        light = ir.Light(name=l["name"], kind=kind, color=l["color"], intensity=l["intensity"],
                         range=l.get("range"))
        if "position" in l:
            light.position = l["position"]
        if d is not None:
            light.direction = d
        if kind == "spot":
            light.inner_cone, light.outer_cone = math.radians(l["inner_cone_deg"]), math.radians(l["outer_cone_deg"])
        if kind == "rect":
            light.size = l["size"]
        if kind == "sun":
            light.angular_radius = math.radians(l["angular_radius_deg"])
        spec.lights.append(light)
    _unique(c, lights, "lights")

    spawns = []
    for i, raw in enumerate(top["spawns"]):
        key = ("spawns", i)
        kind = _kinded(c, raw, key, tuple(SPAWN_PARAMS))
        s = c.table(raw, key, {"name": (string, REQUIRED), "kind": (string, REQUIRED),
                               "position": (vector(3), (0.0, 0.0, 0.0)), "rotation": (vector(3), (0.0, 0.0, 0.0)),
                               "params": (params, {})})
        for k in s["params"]:
            if k not in SPAWN_PARAMS[kind]:
                c.fail(key + ("params", k), f"unknown parameter '{k}' for a {kind} spawn "
                                            f"(expected one of: {', '.join(sorted(SPAWN_PARAMS[kind])) or 'none'})")
            if (kind, k) in SPAWN_PARAM_READERS:
                s["params"][k] = SPAWN_PARAM_READERS[(kind, k)](c, s["params"][k], key + ("params", k))
        if kind == "boids" and "asset" not in s["params"]:
            c.fail(key + ("params",), f"boids '{s['name']}': no asset (params.asset: the glTF of the bird every member is drawn with)")
        blend = s["params"].get("blend")
        if blend is not None and blend not in PARTICLE_BLENDS:
            c.fail(key + ("params", "blend"), f"spawn '{s['name']}': unknown blend {blend!r} "
                                               f"(expected one of: {', '.join(PARTICLE_BLENDS)})")
        spawns.append(s)
        spec.spawns.append(ir.Spawn(name=s["name"], kind=kind, position=s["position"],
                                    rotation=euler_quaternion(s["rotation"]), params=s["params"]))
    _unique(c, spawns, "spawns")

    probes = [_reflection_probe(c, raw, ("reflection_probes", i), i) for i, raw in enumerate(top["reflection_probes"])]
    _unique(c, [{"name": p.name} for p in probes], "reflection_probes")
    spec.reflection_probes = probes

    if not spec.objects and not spec.props:
        c.fail(("objects",), "a level needs at least one [[objects]] or [[props]] entry")
    return spec
