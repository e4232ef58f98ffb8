"""The scene IR: what the cooker's stages pass to each other.

A scene is plain dataclasses holding numpy arrays. Every stage is a function
``stage(scene_or_part, settings) -> new value`` that does not mutate its input, so stages can
be cached by a hash of their inputs (see ``cache.py``). The Rust core imports glTF into this IR
and writes the pack from it (``to_wire`` / ``from_wire`` are the crossing); Python never writes
pack bytes itself.

Units and conventions: metres, right-handed, +Y up (glTF's). Colours are linear. Transforms are
column-major 4x4 (as glTF and glam).
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass, field

import numpy as np

# Per-vertex attributes a mesh may carry: name -> (dtype, components). "position" is required.
# Colours are linear RGBA in 8-bit UNORM; joints index a skin's joint list.
ATTRIBUTES: dict[str, tuple[np.dtype, int]] = {
    "position": (np.dtype(np.float32), 3),
    "normal": (np.dtype(np.float32), 3),
    "tangent": (np.dtype(np.float32), 4),
    "uv0": (np.dtype(np.float32), 2),  # glTF TEXCOORD_0
    # Lightmap UVs (the uv2 stage's), in the mesh's own lightmap space: texels of the page for a
    # mesh placed once, [0, 1] over its largest block for a mesh placed several times; a static
    # instance's Node.lightmap region maps them onto its atlas page.
    "uv1": (np.dtype(np.float32), 2),
    "texcoord1": (np.dtype(np.float32), 2),  # glTF TEXCOORD_1 (texture slots with tex_coord 1)
    "color": (np.dtype(np.uint8), 4),
    "joints": (np.dtype(np.uint16), 4),
    "weights": (np.dtype(np.float32), 4),
}


# Texture usages and the format each is stored in.
USAGE_OF_FORMAT = {"Rgba8Srgb": "color", "Rgba8Unorm": "data", "Rgba16Float": "hdr", "Rgba16Unorm": "normal",
                   # Block-compressed (the compress stage): levels are 1-D uint8 arrays of 4x4 blocks.
                   "Bc7Srgb": "color", "Bc7Unorm": "data", "Bc4Unorm": "data", "Bc5Unorm": "normal", "Bc6hUfloat": "hdr"}


class IrError(ValueError):
    """An IR value breaks its invariants (a cooker bug or bad data from a stage)."""


@dataclass
class Lod:
    """One level of detail: its own vertices and triangles. LOD 0 is the full mesh."""

    attributes: dict[str, np.ndarray]  # name -> (n, k) array, dtypes as ATTRIBUTES
    triangles: np.ndarray  # (m, 3) uint32 indices into the attributes
    materials: np.ndarray  # (m,) uint32 material index per triangle
    # (m,) uint32 lightmap block per triangle, after uv2: a mesh too big for one atlas page is laid
    # out in several blocks; a static instance puts block b on its region's page + b.
    lightmap_blocks: np.ndarray | None = None
    error: float = 0.0  # geometric error to LOD 0 in metres, object space (0 for LOD 0)
    # Morph target deltas added to position/normal before skinning: (targets, n, 3) float32.
    # Every LOD has its own (the lod stage carries LOD 0's to each level's vertices).
    morph_positions: np.ndarray | None = None
    morph_normals: np.ndarray | None = None

    @property
    def vertex_count(self) -> int:
        return len(self.attributes["position"])

    @property
    def triangle_count(self) -> int:
        return len(self.triangles)

    def validate(self, what: str) -> None:
        if "position" not in self.attributes:
            raise IrError(f"{what}: no position attribute")
        n = self.vertex_count
        for name, a in self.attributes.items():
            if name not in ATTRIBUTES:
                raise IrError(f"{what}: unknown attribute '{name}'")
            dtype, k = ATTRIBUTES[name]
            if a.dtype != dtype or a.ndim != 2 or a.shape != (n, k):
                raise IrError(f"{what}: attribute '{name}' is {a.dtype}{a.shape}, expected {dtype}({n}, {k})")
        m = len(self.triangles)
        if self.triangles.dtype != np.uint32 or self.triangles.shape != (m, 3):
            raise IrError(f"{what}: triangles are {self.triangles.dtype}{self.triangles.shape}, expected uint32(m, 3)")
        if m and int(self.triangles.max()) >= n:
            raise IrError(f"{what}: a triangle index is >= the vertex count {n}")
        for name, d in (("morph_positions", self.morph_positions), ("morph_normals", self.morph_normals)):
            if d is not None and (d.dtype != np.float32 or d.ndim != 3 or d.shape[1:] != (n, 3)):
                raise IrError(f"{what}: {name} is {d.dtype}{d.shape}, expected float32(targets, {n}, 3)")
        for name, arr in (("materials", self.materials), ("lightmap_blocks", self.lightmap_blocks)):
            if arr is not None and (arr.dtype != np.uint32 or arr.shape != (m,)):
                raise IrError(f"{what}: {name} is {arr.dtype}{arr.shape}, expected uint32({m},)")


@dataclass
class Mesh:
    name: str
    lods: list[Lod]  # lods[0] is the full-detail mesh; the lod stage appends the rest
    # Per-object override of the scene's lightmap density for its static instances.
    texels_per_metre: float | None = None
    morph_weights: list[float] = field(default_factory=list)  # default weight per morph target
    # Bounds its texture coordinates are stored over besides its own (pack::UvBounds: per set,
    # uv0, uv1, texcoord1, [lo_u, lo_v, hi_u, hi_v]); the chunk stage gives each chunk its
    # whole mesh's (`uv_bounds`), so the chunks store a vertex they share alike.
    uv_bounds: list[list[float]] | None = None

    @property
    def base(self) -> Lod:
        return self.lods[0]


def uv_bounds(lod: Lod) -> list[list[float]]:
    """The bounds of a LOD's texture coordinates as `Mesh.uv_bounds` holds them (float32 values,
    finite ones only; an absent or empty set as the zeros its vertices are stored with)."""
    out = []
    for name in ("uv0", "uv1", "texcoord1"):
        a = lod.attributes.get(name)
        if a is None or not len(a):
            out.append([0.0, 0.0, 0.0, 0.0])
            continue
        lo, hi = [], []
        for c in range(2):
            f = a[:, c][np.isfinite(a[:, c])]
            lo.append(float(f.min()) if len(f) else 0.0)
            hi.append(float(f.max()) if len(f) else 0.0)
        out.append(lo + hi)
    return out


@dataclass
class Material:
    name: str = "default"
    base_color: tuple[float, float, float, float] = (1.0, 1.0, 1.0, 1.0)
    base_color_texture: int | None = None
    metallic: float = 0.0
    roughness: float = 1.0
    emissive: tuple[float, float, float] = (0.0, 0.0, 0.0)  # linear radiance factor
    alpha_mode: str = "Opaque"  # Opaque | Mask | Blend
    alpha_cutoff: float = 0.5
    double_sided: bool = False
    normal_texture: int | None = None  # tangent-space normal map (usage "normal")
    normal_scale: float = 1.0
    metallic_roughness_texture: int | None = None  # roughness in g, metalness in b (usage "data")
    occlusion_texture: int | None = None  # ambient occlusion in r (usage "data")
    occlusion_strength: float = 1.0
    emissive_texture: int | None = None  # emission colour, sRGB (usage "color")
    # Per slot: the UV set it reads and its KHR_texture_transform (pack::TextureTransform):
    # {"tex_coord": 0|1, "offset": [u, v], "rotation": radians, "scale": [u, v]}; None is the
    # identity on TEXCOORD_0.
    base_color_uv: dict | None = None
    normal_uv: dict | None = None
    metallic_roughness_uv: dict | None = None
    occlusion_uv: dict | None = None
    emissive_uv: dict | None = None

    def uv(self, slot: str) -> dict:
        """The UV transform of `slot` ("base_color", "emissive", ...), identity filled in."""
        return texture_transform(getattr(self, f"{slot}_uv"))

    def with_textures_mapped(self, index: list[int]) -> "Material":
        """The material with every texture index i replaced by index[i] (scenes being merged)."""
        return dataclasses.replace(self, **{s: index[getattr(self, s)] for s in TEXTURE_SLOTS if getattr(self, s) is not None})


# Material fields that hold a texture index.
TEXTURE_SLOTS = ("base_color_texture", "normal_texture", "metallic_roughness_texture", "occlusion_texture", "emissive_texture")

# The slots' names as in the `<slot>_uv` fields.
UV_SLOTS = ("base_color", "normal", "metallic_roughness", "occlusion", "emissive")
IDENTITY_UV = {"tex_coord": 0, "offset": [0.0, 0.0], "rotation": 0.0, "scale": [1.0, 1.0]}


def texture_transform(t: dict | None) -> dict:
    """A slot's UV transform with every field present (None: the identity on TEXCOORD_0)."""
    return {**IDENTITY_UV, **(t or {})}


def uv_matrix(t: dict | None) -> np.ndarray:
    """(2, 3) matrix of a KHR_texture_transform: uv' = M @ (u, v, 1), M = T(offset) R(rotation) S(scale)
    (pack::TextureTransform::matrix)."""
    t = texture_transform(t)
    c, s = np.cos(t["rotation"]), np.sin(t["rotation"])
    (sx, sy), (ox, oy) = t["scale"], t["offset"]
    return np.array([[c * sx, s * sy, ox], [-s * sx, c * sy, oy]], np.float64)


# pack::Sampler: wrap per axis (repeat | clamp | mirror), filters (nearest | linear) and the mip
# blend (None: level 0 only).
DEFAULT_SAMPLER = {"wrap_s": "repeat", "wrap_t": "repeat", "mag_filter": "linear", "min_filter": "linear", "mipmap_filter": "linear"}


@dataclass
class Texture:
    name: str
    width: int
    height: int
    format: str  # Rgba8Srgb | Rgba8Unorm | Rgba16Float | Rgba16Unorm | Bc7Srgb | Bc7Unorm | Bc5Unorm | Bc4Unorm | Bc6hUfloat
    # Level 0 first; (h, w, 4) uint8, float16 for Rgba16Float, uint16 for Rgba16Unorm; for a
    # block-compressed format, 1-D uint8 arrays of the level's 4x4 blocks.
    mips: list[np.ndarray]
    # How its mip levels are made: color (sRGB) | data (linear) | normal | hdr. None: what the
    # format implies (Rgba8Srgb colour, Rgba8Unorm data, Rgba16Float hdr, Rgba16Unorm normal).
    # Normal maps arrive as Rgba8Unorm (or Rgba16Unorm) and leave the textures stage Rgba16Unorm.
    usage: str | None = None
    # How it is sampled (DEFAULT_SAMPLER's keys); None: repeating, trilinear.
    sampler: dict | None = None

    def __post_init__(self):
        if self.usage is None:
            self.usage = USAGE_OF_FORMAT.get(self.format, "color")

    def same_as(self, other: "Texture") -> bool:
        """Whether `other` holds the same texels, read the same way (a second import of one asset)."""
        return ((self.name, self.width, self.height, self.format, self.usage, self.sampling) ==
                (other.name, other.width, other.height, other.format, other.usage, other.sampling)
                and len(self.mips) == len(other.mips) and all(np.array_equal(a, b) for a, b in zip(self.mips, other.mips)))

    @property
    def sampling(self) -> dict:
        """The sampler with every field present."""
        return {**DEFAULT_SAMPLER, **(self.sampler or {})}


@dataclass
class Node:
    name: str
    parent: int | None = None  # parents precede children
    local: tuple[float, ...] = (1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1)
    mesh: int | None = None
    skin: int | None = None  # the skin deforming this node's mesh
    weights: tuple[float, ...] | None = None  # this instance's morph weights (overrides the mesh's)
    # A static instance of its mesh: it never moves (not skinned, morphed or animated), so it is
    # baked into the lightmaps and lights the probes.
    static: bool = False
    # Its lightmap region once the uv2 stage has run (pack::LightmapRegion): {"page": p,
    # "scale": [su, sv], "offset": [ou, ov]}; the mesh's uv1 map to uv1 * scale + offset on page
    # p + block.
    lightmap: dict | None = None


@dataclass
class Skin:
    name: str
    joints: list[int]  # node indices; a vertex's joint j means joints[j]
    inverse_bind: np.ndarray  # (len(joints), 16) float32, column-major


@dataclass
class Channel:
    """One animated node property (pack::Channel). `path`: translation | rotation | scale |
    weights; `interpolation`: step | linear | cubicspline. `times` (k,) float32 seconds, strictly
    increasing; `values` (k, c) float32, or (3k, c) for cubicspline (in tangent, value, out
    tangent per key)."""

    node: int
    path: str
    interpolation: str
    times: np.ndarray
    values: np.ndarray


@dataclass
class Clip:
    name: str
    channels: list[Channel] = field(default_factory=list)


@dataclass
class Light:
    """Lights in physical units: sun in lux (illuminance at normal incidence), point and spot in
    candela (intensity), rect in nits (luminance of the emitting face). `color` is a linear
    tint multiplied by `intensity`."""

    name: str
    kind: str  # sun | point | spot | rect
    color: tuple[float, float, float] = (1.0, 1.0, 1.0)
    intensity: float = 1.0
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    direction: tuple[float, float, float] = (0.0, -1.0, 0.0)  # the way the light travels
    range: float | None = None  # metres; None = physically unbounded
    inner_cone: float = 0.0  # spot: radians from the axis
    outer_cone: float = 0.7853982
    size: tuple[float, float] = (1.0, 1.0)  # rect: width, height in metres
    angular_radius: float = 0.00465  # sun: radians (the real sun's)


@dataclass
class Spawn:
    name: str
    kind: str  # player | character | boids | particles
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rotation: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)  # quaternion xyzw
    params: dict = field(default_factory=dict)  # kind-specific: asset, count, radius, rate, ...


@dataclass
class Pillar:
    """A vertical cylinder of a level's solid geometry, world space (pack::Pillar)."""

    name: str  # the brush's, with the copy's number for a repeated brush: "columns[2]"
    centre: tuple[float, float]  # the axis at (x, z)
    radius: float
    y_min: float
    y_max: float


@dataclass
class Sky:
    color: tuple[float, float, float] = (0.5, 0.7, 1.0)  # linear
    intensity: float = 1.0  # luminance scale in nits


@dataclass
class LightmapLayout:
    texels_per_metre: float
    pages: list[tuple[int, int]]  # (width, height) in texels of each atlas page
    padding: int = 2  # texels between charts
    textures: list[int] = field(default_factory=list)  # baked page -> Rgba16Float texture index (empty: not baked)
    # Directional lightmaps: page -> Rgba8Unorm direction texture, the sun's visibility in its
    # alpha (pack::LightmapLayout::directions; `textures` then hold b0). Empty: irradiance lightmaps.
    directions: list[int] = field(default_factory=list)
    # The log-average luminance the runtime's exposure is made from (pack::exposure), of the
    # pages as baked; None until baked.
    log_average: float | None = None
    # Paths per texel the pages were baked with (pack::LightmapLayout::samples); None until baked.
    samples: int | None = None


@dataclass
class ProbeGrid:
    """Baked irradiance probes (pack::ProbeGrid): probe (i, j, k) at origin + (i, j, k) * spacing,
    numbered i + nx (j + ny k); `sh` (n, 9, 3) float32, order-2 SH of B = E/pi without the sun's
    direct light; `sun_visibility` (n,) float32."""

    origin: tuple[float, float, float]
    spacing: tuple[float, float, float]
    counts: tuple[int, int, int]
    sh: np.ndarray
    sun_visibility: np.ndarray


@dataclass
class ReflectionProbe:
    """An authored reflection probe (pack::ReflectionProbe without its cube): the capture point
    and a world-space axis-aligned box, which is both the parallax-correction box and the
    influence volume (the weight fades to 0 over `blend_distance` metres inside its faces). The
    capture point lies inside the box."""

    name: str
    position: tuple[float, float, float]
    box_min: tuple[float, float, float]
    box_max: tuple[float, float, float]
    blend_distance: float = 0.5  # metres, >= 0


# Every face of a reflection cube, in the pack's (and Vulkan's layer) order.
CUBE_FACES = ("+X", "-X", "+Y", "-Y", "+Z", "-Z")


def cube_texels(face_size: int, levels: int) -> int:
    """Texels of a reflection cube with its mip chain: sum over k < levels of 6 (face_size >> k)^2."""
    return sum(6 * (face_size >> k) ** 2 for k in range(levels))


def cube_block_bytes(face_size: int, levels: int) -> int:
    """Bytes of a BC6H reflection cube: every face of every level whole 4x4 blocks of 16 bytes."""
    return sum(6 * 16 * (-(-max(1, face_size >> k) // 4)) ** 2 for k in range(levels))


@dataclass
class ReflectionCubes:
    """Baked reflection probes (the pack's `reflection_probes` with Scene.reflection_probes): per
    probe, in the same order, its radiance cube as float16 (cube_texels(face_size, levels), 4)
    RGBA (alpha 1), rows [level k][face +X, -X, +Y, -Y, +Z, -Z][row j, 0 = top][column i]; level k
    prefiltered for roughness k / (levels - 1), level 0 the mirror. Nits, linear, the sun's disc
    left out. Once the compress stage made them BC6H (`format` "Bc6hUfloat"), each cube is a 1-D
    uint8 array of blocks in the same [level][face] order (cube_block_bytes long)."""

    face_size: int
    levels: int
    cubes: list[np.ndarray]
    format: str = "Rgba16Float"


@dataclass
class Scene:
    name: str
    source: str
    meshes: list[Mesh] = field(default_factory=list)
    materials: list[Material] = field(default_factory=list)
    textures: list[Texture] = field(default_factory=list)
    nodes: list[Node] = field(default_factory=list)
    lights: list[Light] = field(default_factory=list)
    spawns: list[Spawn] = field(default_factory=list)
    pillars: list[Pillar] = field(default_factory=list)  # levels: columns for the flocks to avoid
    sky: Sky | None = None
    lightmap: LightmapLayout | None = None
    probes: ProbeGrid | None = None
    # Reflection probes as authored (a level's [[reflection_probes]], a glTF scene's node extras
    # or its default one), and their cubes once baked (None: not baked; the pack then has none).
    reflection_probes: list[ReflectionProbe] = field(default_factory=list)
    reflection_cubes: ReflectionCubes | None = None
    skins: list[Skin] = field(default_factory=list)
    clips: list[Clip] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)  # fixes the import made (one line each)
    # Every file the source stage read to make this scene (the source first): what the cook's
    # cache key covers. Python-side only (not part of the wire form).
    files: list[str] = field(default_factory=list)

    def static_meshes(self) -> list[int]:
        """Meshes placed by at least one static node (they get lightmap UVs), in mesh order."""
        return sorted({n.mesh for n in self.nodes if n.static and n.mesh is not None})

    def baked_textures(self) -> set[int]:
        """Texture indices of the baked lightmap pages and their direction textures (one level,
        half float / RGBA8: the textures stage leaves them as the bake made them; the compress
        stage makes them BC6H / BC7)."""
        lm = self.lightmap
        return set(lm.textures) | set(lm.directions) if lm is not None else set()

    def static_nodes(self) -> list[int]:
        """Static instances: nodes that place a mesh and are static, in node order."""
        return [i for i, n in enumerate(self.nodes) if n.static and n.mesh is not None]

    def world_matrices(self) -> list[np.ndarray]:
        """4x4 world matrix (row-major, column vectors, float64) of every node."""
        world: list[np.ndarray] = []
        for n in self.nodes:
            local = np.array(n.local, dtype=np.float64).reshape(4, 4).T  # column-major -> row-major
            world.append(world[n.parent] @ local if n.parent is not None else local)
        return world

    def validate(self) -> None:
        for i, m in enumerate(self.meshes):
            if not m.lods:
                raise IrError(f"mesh {i} '{m.name}': no LODs")
            for l, lod in enumerate(m.lods):
                lod.validate(f"mesh {i} '{m.name}' LOD {l}")
                if len(lod.materials) and int(lod.materials.max()) >= len(self.materials):
                    raise IrError(f"mesh {i} '{m.name}' LOD {l}: material index out of range")
        for i, n in enumerate(self.nodes):
            if n.parent is not None and not 0 <= n.parent < i:
                raise IrError(f"node {i} '{n.name}': parent {n.parent} does not precede it")
            if n.mesh is not None and not 0 <= n.mesh < len(self.meshes):
                raise IrError(f"node {i} '{n.name}': mesh {n.mesh} does not exist")
        for i, p in enumerate(self.reflection_probes):
            what = f"reflection probe {i} '{p.name}'"
            lo, hi, at = (np.asarray(v, np.float64) for v in (p.box_min, p.box_max, p.position))
            if not all(v.shape == (3,) and np.isfinite(v).all() for v in (lo, hi, at)) or not math.isfinite(p.blend_distance):
                raise IrError(f"{what}: its position and box need three finite numbers each, and a finite blend distance")
            if not (lo < hi).all():
                raise IrError(f"{what}: the box {tuple(lo)}..{tuple(hi)} is empty")
            if not ((lo <= at) & (at <= hi)).all():
                raise IrError(f"{what}: the capture point {tuple(at)} is outside its box {tuple(lo)}..{tuple(hi)}")
            if p.blend_distance < 0:
                raise IrError(f"{what}: blend distance {p.blend_distance} is negative")
        rc = self.reflection_cubes
        if rc is not None:
            if rc.face_size < 4 or rc.face_size & (rc.face_size - 1) or not 1 <= rc.levels or rc.face_size >> (rc.levels - 1) < 1:
                raise IrError(f"reflection cubes: face size {rc.face_size} with {rc.levels} levels")
            if len(rc.cubes) != len(self.reflection_probes):
                raise IrError(f"reflection cubes: {len(rc.cubes)} cubes for {len(self.reflection_probes)} probes")
            if rc.format == "Bc6hUfloat":
                dtype, shape = np.uint8, (cube_block_bytes(rc.face_size, rc.levels),)
            elif rc.format == "Rgba16Float":
                dtype, shape = np.float16, (cube_texels(rc.face_size, rc.levels), 4)
            else:
                raise IrError(f"reflection cubes: format {rc.format} is not Rgba16Float or Bc6hUfloat")
            for p, c in zip(self.reflection_probes, rc.cubes):
                if c.dtype != dtype or c.shape != shape:
                    raise IrError(f"reflection probe '{p.name}': its cube is {c.dtype}{c.shape}, expected {np.dtype(dtype).name}{shape}")


# ---- crossing to and from the Rust core -------------------------------------------------------
# The wire form is (JSON text, list of arrays): every numpy array in the scene is replaced in the
# JSON by its index into the list, so the Rust side reads metadata with serde and arrays without
# copying through Python objects.


def _lod_doc(l: Lod, put) -> dict:
    return {
        "attributes": {k: put(v) for k, v in l.attributes.items()},
        "triangles": put(l.triangles),
        "materials": put(l.materials),
        "lightmap_blocks": None if l.lightmap_blocks is None else put(l.lightmap_blocks),
        "error": float(l.error),
        "morph_positions": None if l.morph_positions is None else put(l.morph_positions),
        "morph_normals": None if l.morph_normals is None else put(l.morph_normals),
    }


def _lod_from_doc(d: dict, arrays: list[np.ndarray]) -> Lod:
    pages = d.get("lightmap_blocks")
    return Lod(
        attributes={k: arrays[i] for k, i in d["attributes"].items()},
        triangles=arrays[d["triangles"]],
        materials=arrays[d["materials"]],
        lightmap_blocks=None if pages is None else arrays[pages],
        error=d.get("error", 0.0),
        morph_positions=None if d.get("morph_positions") is None else arrays[d["morph_positions"]],
        morph_normals=None if d.get("morph_normals") is None else arrays[d["morph_normals"]],
    )


def _probe_doc(p: ReflectionProbe) -> dict:
    return {"name": p.name, "position": [float(x) for x in p.position], "box_min": [float(x) for x in p.box_min],
            "box_max": [float(x) for x in p.box_max], "blend_distance": float(p.blend_distance)}


def _probe_from_doc(d: dict) -> ReflectionProbe:
    return ReflectionProbe(d["name"], tuple(d["position"]), tuple(d["box_min"]), tuple(d["box_max"]), float(d.get("blend_distance", 0.5)))


def lods_to_wire(lods: list[Lod]) -> tuple[list[dict], list[np.ndarray]]:
    """A list of LODs alone (a stage's output) as (docs, arrays)."""
    arrays: list[np.ndarray] = []

    def put(a: np.ndarray) -> int:
        arrays.append(np.ascontiguousarray(a))
        return len(arrays) - 1

    return [_lod_doc(l, put) for l in lods], arrays


def lods_from_wire(docs: list[dict], arrays: list[np.ndarray]) -> list[Lod]:
    return [_lod_from_doc(d, arrays) for d in docs]


def to_wire(scene: Scene) -> tuple[str, list[np.ndarray]]:
    scene.validate()
    arrays: list[np.ndarray] = []

    def put(a: np.ndarray) -> int:
        arrays.append(np.ascontiguousarray(a))
        return len(arrays) - 1

    def lod(l: Lod) -> dict:
        return _lod_doc(l, put)

    doc = {
        "name": scene.name,
        "source": scene.source,
        "meshes": [{"name": m.name, "texels_per_metre": m.texels_per_metre, "morph_weights": [float(w) for w in m.morph_weights],
                    "uv_bounds": m.uv_bounds, "lods": [lod(l) for l in m.lods]} for m in scene.meshes],
        "materials": [{**dataclasses.asdict(m), **{f"{slot}_uv": m.uv(slot) for slot in UV_SLOTS}} for m in scene.materials],
        "textures": [{"name": t.name, "width": t.width, "height": t.height, "format": t.format, "usage": t.usage, "sampler": t.sampling,
                      "mips": [put(m) for m in t.mips]} for t in scene.textures],
        "nodes": [dataclasses.asdict(n) for n in scene.nodes],
        "lights": [dataclasses.asdict(l) for l in scene.lights],
        "spawns": [dataclasses.asdict(s) for s in scene.spawns],
        "pillars": [dataclasses.asdict(p) for p in scene.pillars],
        "sky": None if scene.sky is None else dataclasses.asdict(scene.sky),
        "lightmap": None if scene.lightmap is None else dataclasses.asdict(scene.lightmap),
        "probes": None if scene.probes is None else {
            "origin": list(scene.probes.origin), "spacing": list(scene.probes.spacing), "counts": list(scene.probes.counts),
            "sh": put(np.asarray(scene.probes.sh, np.float32).reshape(-1, 27)),
            "sun_visibility": put(np.asarray(scene.probes.sun_visibility, np.float32).reshape(-1)),
        },
        # The pack's `reflection_probes` (reflection_contract: each probe's `data` here the index
        # of its float16 (T, 4) cube), present only once baked; the authored probes ride beside
        # it for the cooker's own caches (the Rust core ignores them).
        "authored_reflection_probes": [_probe_doc(p) for p in scene.reflection_probes],
        "reflection_probes": None if scene.reflection_cubes is None else {
            "face_size": int(scene.reflection_cubes.face_size), "levels": int(scene.reflection_cubes.levels),
            "format": scene.reflection_cubes.format,
            "probes": [{**_probe_doc(p), "data": put(np.asarray(c, np.uint8 if scene.reflection_cubes.format == "Bc6hUfloat" else np.float16))}
                       for p, c in zip(scene.reflection_probes, scene.reflection_cubes.cubes)],
        },
        "skins": [{"name": s.name, "joints": [int(j) for j in s.joints], "inverse_bind": put(np.asarray(s.inverse_bind, np.float32).reshape(-1, 16))} for s in scene.skins],
        "clips": [{"name": c.name, "channels": [{"node": int(ch.node), "path": ch.path, "interpolation": ch.interpolation,
                                                  "times": put(np.asarray(ch.times, np.float32).reshape(-1)),
                                                  "values": put(np.asarray(ch.values, np.float32).reshape(len(ch.values), -1))}
                                                 for ch in c.channels]} for c in scene.clips],
        "warnings": list(scene.warnings),
    }
    return json.dumps(doc), arrays


def from_wire(text: str, arrays: list[np.ndarray]) -> Scene:
    doc = json.loads(text)

    def lod(d: dict) -> Lod:
        return _lod_from_doc(d, arrays)

    def tup(d: dict, cls):
        names = {f.name for f in dataclasses.fields(cls)}
        return cls(**{k: (tuple(v) if isinstance(v, list) and k != "pages" else v) for k, v in d.items() if k in names})

    scene = Scene(
        name=doc["name"],
        source=doc["source"],
        meshes=[Mesh(name=m["name"], texels_per_metre=m.get("texels_per_metre"), lods=[lod(l) for l in m["lods"]],
                     morph_weights=list(m.get("morph_weights", [])), uv_bounds=m.get("uv_bounds")) for m in doc["meshes"]],
        materials=[tup(m, Material) for m in doc["materials"]],
        textures=[Texture(t["name"], t["width"], t["height"], t["format"], [arrays[i] for i in t["mips"]], t.get("usage"),
                          None if t.get("sampler") in (None, DEFAULT_SAMPLER) else t["sampler"]) for t in doc["textures"]],
        nodes=[tup(n, Node) for n in doc["nodes"]],
        lights=[tup(l, Light) for l in doc.get("lights", [])],
        spawns=[tup(s, Spawn) for s in doc.get("spawns", [])],
        pillars=[tup(p, Pillar) for p in doc.get("pillars", [])],
        sky=None if doc.get("sky") is None else tup(doc["sky"], Sky),
        skins=[Skin(s["name"], list(s["joints"]), arrays[s["inverse_bind"]]) for s in doc.get("skins", [])],
        clips=[Clip(c["name"], [Channel(ch["node"], ch["path"], ch["interpolation"], arrays[ch["times"]], arrays[ch["values"]]) for ch in c["channels"]])
               for c in doc.get("clips", [])],
        warnings=list(doc.get("warnings", [])),
    )
    if doc.get("lightmap"):
        lm = doc["lightmap"]
        scene.lightmap = LightmapLayout(lm["texels_per_metre"], [tuple(p) for p in lm["pages"]], lm.get("padding", 2), list(lm.get("textures", [])),
                                        list(lm.get("directions", [])), lm.get("log_average"), lm.get("samples"))
    rp = doc.get("reflection_probes")
    authored = doc.get("authored_reflection_probes", rp["probes"] if rp else [])
    scene.reflection_probes = [_probe_from_doc(p) for p in authored]
    if rp:
        scene.reflection_cubes = ReflectionCubes(int(rp["face_size"]), int(rp["levels"]), [arrays[p["data"]] for p in rp["probes"]],
                                                 rp.get("format", "Rgba16Float"))
    if doc.get("probes"):
        pr = doc["probes"]
        scene.probes = ProbeGrid(tuple(pr["origin"]), tuple(pr["spacing"]), tuple(pr["counts"]),
                                 arrays[pr["sh"]].reshape(-1, 9, 3), arrays[pr["sun_visibility"]])
    scene.validate()
    return scene
