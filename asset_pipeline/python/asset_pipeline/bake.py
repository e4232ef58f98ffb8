"""The bake stage: lightmaps for the static scene and irradiance probes for dynamic objects.

``bake_level(scene, settings, progress) -> Baked`` is a pure function of the scene and settings
(the orchestrator caches it by content hash); ``attach(scene, baked)`` puts the result into the
scene for the pack writer. The path tracer is Rust (``_core.Baker``, ``cook_core::bake``); this
module gathers its inputs, batches the work for progress and Ctrl-C, and orders the clean-up.

What is baked
-------------
- **The scene**: every static instance (``Scene.static_nodes()``: its mesh's LOD 0, in world
  space through its node) is an occluder and a bounce surface. Its materials are evaluated where
  rays hit, in Rust (``cook_core::bake::material``): albedo = base colour factor x base colour
  texture (bilinear at the hit's UV for that slot, uv0 or texcoord1 by ``tex_coord``, through
  its KHR_texture_transform and the texture's wrap modes; sRGB decoded) x vertex colour;
  emission = emissive factor (nits) x emissive texture. Alpha: Mask materials let rays
  (closest-hit and shadow) through where alpha < cutoff, Blend ones where alpha < a hash of the
  point (a pane of alpha a stops a fraction a of the light), Opaque ones ignore alpha.
  Sides: the back face of a **single-sided** material is opaque and black: it blocks light
  (a single-sided wall still casts its shadow) but reflects and emits nothing, so the insides
  of closed meshes stay dark; a **double-sided** material's back face is the same surface with
  the normal flipped (it reflects and emits on both sides). Lights and the sky come from the
  level. Dynamic instances (props that move, characters) are not in it.
- **Lightmaps**: every static instance has its own region of the atlas (``Node.lightmap``, from
  the uv2 stage), so a mesh placed twice gets two lightmaps, each baked at its own world
  positions and normals. Each atlas page is rasterised conservatively in UV2 space with every
  instance's LOD 0 placed on it (``uv2.place_on_atlas``; every texel a chart touches,
  ``uv2.rasterize_page``); each covered texel gets B = H/pi (nits, linear). Then
  ``lightmap_post.finish_page``: OIDN denoise per chart, dilation into the gutters, seam
  stitching (within each instance). Pages go into the pack as half-float textures and beside it
  as OpenEXR files.
- **Reflection probes** (``Scene.reflection_probes``, after the lightmaps and the probes): per
  probe, the radiance seen from its capture point as a cube with its mip chain, each level
  prefiltered for a roughness (GGX), by ``Baker.bake_reflection_probe`` (``cook_core::bake``);
  face size, levels and samples from ``BakeSettings.reflection`` (REFLECTION_PRESETS). Stored
  as half-float RGBA (``half_rgba``), ``Scene.reflection_cubes`` in the pack. A scene that is
  not baked has none.
- **Probes**: a grid over the static geometry's bounds, ``probe_spacing`` metres apart (wider if
  it would exceed ``max_probes``); each holds order-2 SH of B(n) = E(n)/pi without the sun's direct
  light, and the fraction of the sun's disk it sees (``cook_core::bake::probes``). Probes inside
  solid geometry (more than ``max_backface`` of their rays hit single-sided back faces) take the
  mean of their valid neighbours, grown outward until every such probe has a value.

The baker's inputs are built once (``StaticScene.baker_args``, the arguments of
``_core.Baker``) and used as they are by the local bake and by every Ray worker, so the two
cannot drift apart.

Determinism: a texel's random streams are keyed by (seed, page, texel index), a probe's by its
grid index, a reflection probe's by its index in the scene, so the same seed gives the same bytes
for any thread count and batch size. Ctrl-C is honoured between batches (about a second of work
each; a reflection probe is one call, several seconds at medium): the stage raises
``KeyboardInterrupt`` and nothing is written.

With a Ray executor (executor.py) the texels of every page are cut into tiles of
``tile_texels``, the probes into batches of ``probe_tile``, and each reflection probe is a task
of its own, all submitted at once as tasks against the scene put once into the object store;
rasterising the pages, the clean-up (``finish_page``) and filling the probes inside geometry stay
in the driver.
"""

from __future__ import annotations

import dataclasses
import json
import time
from dataclasses import dataclass, field

import numpy as np

from asset_pipeline import _core, ir
from asset_pipeline.lightmap_post import DIRECTIONAL_CHANNELS, NONE, LightmapPostSettings, finish_directional_page, finish_page, page_seams
from asset_pipeline.uv2 import place_on_atlas, rasterize_page

PRESETS = ("draft", "medium", "high")


@dataclass(frozen=True)
class BakeSettings:
    """Settings of the bake stage (all but `threads` are part of its cache key)."""

    preset: str = "medium"  # draft | medium | high (cook_core::bake::integrator::BakeSettings::preset)
    # irradiance: B = H/pi per texel (the sun included); directional: per texel L1 SH of all the
    # light but the sun's direct light, and the sun's visibility (LIGHTMAP_MODES). Directional by
    # default: the runtime reads it (normal maps under baked light, the sun's highlight).
    lightmap_mode: str = "directional"
    samples: int | None = None  # paths per lightmap texel (None: the preset's)
    bounces: int | None = None  # indirect bounces (None: the preset's)
    probe_samples: int | None = None  # rays per probe (None: the preset's)
    seed: int = 0
    probe_spacing: float = 2.0  # metres between probes
    max_probes: int = 4096
    max_backface: float = 0.25  # probes seeing more back faces than this are inside geometry
    post: LightmapPostSettings = field(default_factory=LightmapPostSettings)
    batch_texels: int = 16384  # texels per call: progress and Ctrl-C granularity
    threads: int | None = None  # None: all cores (does not change the result)
    # With the Ray executor: texels per task and probes per task (neither changes the result).
    # Smaller tiles balance better across workers; each costs a round trip (see README).
    tile_texels: int = 4096
    probe_tile: int = 128
    # Reflection probes (Scene.reflection_probes): each cube face's size in texels, a power of two
    # >= 8 (its mip chain stops at 4 texels: log2(face) - 1 levels), and capture samples per
    # texel; None: the preset's (REFLECTION_PRESETS).
    reflection_face: int | None = None
    reflection_samples: int | None = None

    def key_doc(self) -> dict:
        return {k: v for k, v in dataclasses.asdict(self).items() if k not in SCHEDULING}

    def reflection(self) -> tuple[int, int, int]:
        """(face size, levels, samples per texel) of this bake's reflection probes."""
        face, samples = REFLECTION_PRESETS[self.preset]
        face = face if self.reflection_face is None else int(self.reflection_face)
        samples = samples if self.reflection_samples is None else int(self.reflection_samples)
        return face, reflection_levels(face), samples


# Settings that change how the work is cut up and where it runs, never the result: left out of
# every cache key.
SCHEDULING = ("threads", "batch_texels", "tile_texels", "probe_tile")


# What a lightmap texel holds, and its bytes in the pack (see `attach`):
# - irradiance: B = H/pi (nits), the sun included; Rgba16Float, 8 bytes a texel (BC6H once
#   compressed: 1 byte).
# - directional: b0 (nits, RGB) in one Rgba16Float, and the luminance's L1 direction
#   t = b1_Y / (2 b0_Y) as bytes 128 + 127 t with the sun's visibility (alpha) in one
#   Rgba8Unorm ("MonoSH", shading.md section 4.2): 12 bytes a texel, 1.5x (BC6H and BC7 once
#   compressed: 2 bytes). The runtime evaluates b0 (1 + 2 t.n) for the shading
#   normal and lights the texel with the sun itself, times its visibility. (Every channel's own
#   direction would take three Rgba8Unorm, 20 bytes, 2.5x, and two lookups more per pixel;
#   MonoSH loses only colour that differs by direction.)
LIGHTMAP_MODES = ("irradiance", "directional")

# Per preset, a reflection probe's (cube face size in texels, capture samples per texel)
# (reflection_contract.md; shading.md section 3.2: base 128, 32-128 samples).
REFLECTION_PRESETS = {"draft": (64, 16), "medium": (128, 32), "high": (128, 128)}


def reflection_levels(face: int) -> int:
    """Mip levels of a reflection cube of `face` texels: down to 4 texels a side (log2(face) - 1).
    Level k holds roughness k / (levels - 1), so the chain's length fixes the roughness steps."""
    if face < 8 or face & (face - 1):
        raise ValueError(f"bake: a reflection probe's face size must be a power of two >= 8, got {face}")
    return face.bit_length() - 2


@dataclass
class Baked:
    # Per atlas page, the finished lightmap: (h, w, 3) float32 B, or (h, w, 13) for a directional
    # bake (lightmap_post.DIRECTIONAL_CHANNELS: b0, b1 per channel, the sun's visibility).
    pages: list[np.ndarray]
    probes: ir.ProbeGrid | None
    stats: dict
    # The reflection probes' cubes (Scene.reflection_probes' order); None: the scene has none.
    reflections: ir.ReflectionCubes | None = None


# ---- the scene --------------------------------------------------------------------------------


@dataclass
class StaticInstance:
    """One static placement of a mesh, as its lightmap is baked."""

    node: int  # index into scene.nodes
    name: str  # the node's
    mesh: int
    mesh_name: str
    # Its mesh's LOD 0 with uv1 moved into its atlas region and lightmap_blocks made pages
    # (uv2.place_on_atlas); None when the node has no region (nothing of it is baked).
    lod: ir.Lod | None
    world_positions: np.ndarray  # (n, 3) float32, its LOD 0's vertices in world space
    world_normals: np.ndarray | None  # (n, 3) float32, unit, or None if the mesh has none


@dataclass
class StaticScene:
    """The static geometry as the baker sees it."""

    # The arguments of _core.Baker, built once and used as they are by the local bake and by
    # every Ray worker (executor._worker_baker): (positions float32 (n, 3) world space of every
    # static instance, triangles uint32 (m, 3), triangle_materials uint32 (m,), uv0 float32
    # (n, 2) | None, texcoord1 float32 (n, 2) | None, colors uint8 (n, 4) | None, materials_json,
    # textures [uint8 (h, w, 4)], textures_json, lights_json, sky (r, g, b) nits | None).
    baker_args: tuple
    instances: list[StaticInstance]  # every static instance, node order

    @property
    def positions(self) -> np.ndarray:
        return self.baker_args[0]

    @property
    def triangles(self) -> np.ndarray:
        return self.baker_args[1]

    @property
    def baked(self) -> list[StaticInstance]:
        """The instances with a lightmap region: what the pages are rasterised from."""
        return [i for i in self.instances if i.lod is not None]


def static_scene(scene: ir.Scene) -> StaticScene:
    world = scene.world_matrices()
    instances: list[StaticInstance] = []
    lods: list[ir.Lod] = []
    tri, base = [], 0
    for k in scene.static_nodes():
        node, w = scene.nodes[k], world[k]
        mesh = scene.meshes[node.mesh]
        lod = mesh.lods[0]
        p = lod.attributes["position"].astype(np.float64) @ w[:3, :3].T + w[:3, 3]
        nrm = lod.attributes.get("normal")
        if nrm is not None:
            # Normals go through the inverse transpose; renormalised.
            nrm = nrm.astype(np.float64) @ np.linalg.inv(w[:3, :3])
            nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-30)
        placed = None
        if node.lightmap is not None and "uv1" in lod.attributes and lod.lightmap_blocks is not None:
            placed = place_on_atlas(lod, node.lightmap)
        instances.append(StaticInstance(k, node.name, node.mesh, mesh.name, placed, p.astype(np.float32),
                                        None if nrm is None else nrm.astype(np.float32)))
        t = lod.triangles.astype(np.int64)
        if np.linalg.det(w[:3, :3]) < 0:
            t = t[:, ::-1]  # a mirroring transform flips the winding: keep fronts outward
        tri.append(t + base)
        base += len(p)
        lods.append(lod)

    def cat(xs, shape, dt):
        return np.ascontiguousarray(np.concatenate(xs) if xs else np.zeros(shape, dt), dt)

    def attribute(name: str, fill, dt):
        # Per vertex of every instance when any instance's mesh has it (the others read `fill`,
        # as the runtime's vertices do); None when none has it.
        if not any(name in l.attributes for l in lods):
            return None
        k = ir.ATTRIBUTES[name][1]
        return cat([l.attributes[name] if name in l.attributes else np.full((l.vertex_count, k), fill, dt) for l in lods], (0, k), dt)

    materials_json, textures, textures_json = _material_args(scene)
    args = (
        cat([i.world_positions for i in instances], (0, 3), np.float32),
        cat(tri, (0, 3), np.uint32),
        cat([l.materials for l in lods], (0,), np.uint32),
        attribute("uv0", 0.0, np.float32),
        attribute("texcoord1", 0.0, np.float32),
        attribute("color", 255, np.uint8),
        materials_json,
        textures,
        textures_json,
        _lights_json(scene),
        _sky(scene),
    )
    return StaticScene(baker_args=args, instances=instances)


def key_inputs(scene: ir.Scene) -> tuple[dict, list[np.ndarray]]:
    """Everything ``bake_level`` reads from `scene`, normalised (a material's missing UV
    transform and the identity one are the same input), as (JSON-able doc, arrays): for the
    stage's cache key, with the settings and the denoiser's version beside it. It is the
    baker's own arguments (``StaticScene.baker_args``: world-space geometry of every static
    instance, per-vertex uv0 / texcoord1 / colour, the materials' baked fields, the textures
    they read with formats and samplers, lights, sky) plus, per instance, its atlas region and
    the placed lightmap UVs, pages and normals it is rasterised from, the atlas layout, and the
    reflection probes' capture points in order."""
    st = static_scene(scene)
    positions, triangles, materials, uv0, texcoord1, colors, materials_json, textures, textures_json, lights_json, sky = st.baker_args
    arrays = [positions, triangles, materials, uv0, texcoord1, colors, *textures]
    doc = {"materials": materials_json, "textures": textures_json, "lights": lights_json, "sky": sky,
           # What a reflection probe's cube depends on besides the scene: its capture point and
           # its index (its random streams' key); not its box, name or blend (the pack's, not the bake's).
           "reflection_probes": [[float(x) for x in p.position] for p in scene.reflection_probes],
           "arrays": [None if a is None else [a.dtype.str, list(a.shape)] for a in arrays],
           "layout": None if scene.lightmap is None else {"texels_per_metre": float(scene.lightmap.texels_per_metre),
                                                         "pages": [list(map(int, p)) for p in scene.lightmap.pages],
                                                         "padding": int(scene.lightmap.padding)},
           "instances": []}
    for i in st.instances:
        doc["instances"].append({"node": i.node, "name": i.name, "mesh": i.mesh, "vertices": len(i.world_positions), "baked": i.lod is not None})
        if i.lod is not None:
            arrays += [i.lod.attributes["uv1"], i.lod.lightmap_blocks, i.lod.triangles, i.world_normals]
    return doc, [a for a in arrays if a is not None]


def _material_args(scene: ir.Scene) -> tuple[str, list[np.ndarray], str]:
    """(materials JSON, textures, textures JSON) for _core.Baker: what the materials' base colour
    and emissive slots read (texture indices renumbered over just those textures), each texture's
    level 0 as uint8 RGBA and its format and sampler."""
    used = sorted({t for m in scene.materials for t in (m.base_color_texture, m.emissive_texture) if t is not None})
    index = {t: k for k, t in enumerate(used)}

    def uv(t: dict) -> dict:
        return {"tex_coord": int(t["tex_coord"]), "offset": [float(x) for x in t["offset"]], "rotation": float(t["rotation"]),
                "scale": [float(x) for x in t["scale"]]}

    mats = [{"name": m.name, "base_color": [float(c) for c in m.base_color], "base_color_texture": index.get(m.base_color_texture),
             "base_color_uv": uv(m.uv("base_color")), "emissive": [float(c) for c in m.emissive],
             "emissive_texture": index.get(m.emissive_texture), "emissive_uv": uv(m.uv("emissive")),
             "alpha_mode": m.alpha_mode, "alpha_cutoff": float(m.alpha_cutoff), "double_sided": bool(m.double_sided)}
            for m in scene.materials]
    images, infos = [], []
    for t in used:
        tex = scene.textures[t]
        img, fmt = _rgba8(tex)
        images.append(img)
        infos.append({"name": tex.name, "format": fmt, "sampler": tex.sampling})
    return json.dumps(mats), images, json.dumps(infos)


def _rgba8(tex: ir.Texture) -> tuple[np.ndarray, str]:
    """Level 0 of `tex` as C-contiguous uint8 (h, w, 4) and the format the baker decodes it by:
    8-bit textures as they are (Rgba8Srgb decoded through sRGB, others as linear); 16-bit ones
    (not what glTF's colour slots hold, but the IR allows them) rounded to 8 bits: half floats
    (linear) encoded as sRGB, clipped to [0, 1], UNORM16 kept linear."""
    img = np.asarray(tex.mips[0])
    if img.ndim == 2:
        img = img[..., None]
    if img.shape[2] < 4:  # grey, grey + alpha or RGB: made RGBA
        full = 1.0 if img.dtype.kind == "f" else np.iinfo(img.dtype).max
        rgb = img[..., :3] if img.shape[2] >= 3 else np.repeat(img[..., :1], 3, 2)
        alpha = img[..., 1:2] if img.shape[2] == 2 else np.full(img.shape[:2] + (1,), full, img.dtype)
        img = np.concatenate([rgb, alpha], 2)
    if img.dtype == np.uint8:
        return np.ascontiguousarray(img), "Rgba8Srgb" if tex.format == "Rgba8Srgb" else "Rgba8Unorm"
    if img.dtype == np.uint16:
        return np.ascontiguousarray(np.round(img / 257.0).astype(np.uint8)), "Rgba8Unorm"
    lin = np.clip(np.nan_to_num(img.astype(np.float64)), 0.0, 1.0)
    rgb = np.where(lin[..., :3] <= 0.0031308, lin[..., :3] * 12.92, 1.055 * lin[..., :3] ** (1 / 2.4) - 0.055)
    out = np.concatenate([rgb, lin[..., 3:4]], 2)
    return np.ascontiguousarray(np.round(out * 255.0).astype(np.uint8)), "Rgba8Srgb"


def _lights_json(scene: ir.Scene) -> str:
    return json.dumps([dataclasses.asdict(l) for l in scene.lights])


def _sky(scene: ir.Scene):
    if scene.sky is None:
        return None
    return tuple(float(c) * float(scene.sky.intensity) for c in scene.sky.color)


# ---- lightmaps ----------------------------------------------------------------------------------


def _texel_ids(page: int, flat: np.ndarray) -> np.ndarray:
    return (np.uint64(page) << np.uint64(40)) | flat.astype(np.uint64)


class Superseded(Exception):
    """A refining bake step given up because its inputs changed meanwhile (Refinement.stop)."""


@dataclass
class Refinement:
    """A bake refined in steps (``cook --watch``): the running sums of every lightmap texel and
    reflection probe texel for one set of bake inputs, and their probes.

    ``bake_level(scene, settings, refine=r)`` with ``r.key`` the inputs' key (everything the bake
    reads and every setting but the sample counts) traces only the samples the sums lack, up to
    ``settings``' counts, and finishes the pages and cubes from the sums. A sample of a texel is
    the same whichever step draws it and the sums take samples in order (``Baker.add_samples``),
    so each step is, to the bit, the one-shot bake of its counts, and the last one the one-shot
    bake of the target. Probes do not refine: they are baked at the first step with the
    settings' ``probe_samples`` (a fraction of a second where lightmaps take tens) and kept.
    Only local bakes refine (with a Ray executor each step bakes in full)."""

    key: str | None = None
    samples: int = 0  # lightmap samples in `pages`
    pages: list = field(default_factory=list)  # per page, float64 sums of its covered texels
    reflection_samples: int = 0
    reflections: list = field(default_factory=list)  # per reflection probe, float64 (6 face², 3) sums
    probes: tuple | None = None  # (probe_out, seconds) as `bake_level` makes them
    # Asked between batches of texels: True gives the step up (raises Superseded), its sums
    # left as the last finished step made them.
    stop: "object | None" = None

    def begin(self, key: str) -> None:
        """Start over unless these sums belong to the inputs `key`."""
        if key != self.key:
            self.key, self.samples, self.pages, self.reflection_samples, self.reflections, self.probes = key, 0, [], 0, [], None

    def check(self) -> None:
        if self.stop is not None and self.stop():
            raise Superseded()


def preset_samples(s: BakeSettings) -> tuple[int, int]:
    """(lightmap samples per texel, reflection capture samples per texel) of settings `s`."""
    lightmap = int(s.samples) if s.samples is not None else _core.bake_preset(s.preset)[0]
    return lightmap, s.reflection()[2]


def bake_level(scene: ir.Scene, settings: BakeSettings | None = None, progress=None, executor=None, refine: Refinement | None = None) -> Baked:
    """`executor`: None bakes in this process; a RayExecutor bakes tiles as Ray tasks (same bytes).
    `refine`: go on from a Refinement's sums (local bakes only; see Refinement)."""
    s = settings or BakeSettings()
    if s.preset not in PRESETS:
        raise ValueError(f"bake: unknown preset '{s.preset}' ({', '.join(PRESETS)})")
    if s.lightmap_mode not in LIGHTMAP_MODES:
        raise ValueError(f"bake: unknown lightmap mode '{s.lightmap_mode}' ({', '.join(LIGHTMAP_MODES)})")
    directional = s.lightmap_mode == "directional"
    # The reflection probes' capture points and cube settings (checked before any work is done).
    refl_points = np.array([p.position for p in scene.reflection_probes], np.float32).reshape(-1, 3)
    refl = s.reflection() if len(refl_points) else None
    layout = scene.lightmap
    st = static_scene(scene)
    baked_instances = st.baked if layout is not None else []
    samples, reflection_samples = preset_samples(s)
    stats: dict = {"preset": s.preset, "lightmap_mode": s.lightmap_mode, "samples": samples, "static_triangles": int(len(st.triangles)),
                   "static_instances": len(st.instances)}
    if len(st.triangles) == 0:
        return Baked(pages=[], probes=None, stats=stats)
    kw = dict(preset=s.preset, seed=int(s.seed), bounces=s.bounces, threads=s.threads)
    # The texels' channels (Baker.bake_points: B, or with directional=True a directional texel).
    channels = DIRECTIONAL_CHANNELS if directional else 3
    # Every static instance's own region, at its own world positions and normals.
    lods = [i.lod for i in baked_instances]
    positions = [i.world_positions for i in baked_instances]
    normals = [i.world_normals for i in baked_instances]
    instance_texels = np.zeros(len(baked_instances), np.int64)
    inputs = []  # per page: (w, h, chart, covered, points, normals, ids)
    for page, (w, h) in enumerate(layout.pages if layout else []):
        r = rasterize_page(lods, layout, page, positions=positions, normals=normals)
        chart = r["chart"]
        covered = np.flatnonzero(chart.ravel() != NONE)
        instance_texels += np.bincount(r["mesh"][r["triangle"].ravel()[covered]], minlength=len(lods))
        points = np.ascontiguousarray(r["position"].reshape(-1, 3)[covered])
        nrm = np.ascontiguousarray(r["normal"].reshape(-1, 3)[covered])
        inputs.append((w, h, chart, covered, points, nrm, _texel_ids(page, covered)))
    texels_of = {i.node: int(n) for i, n in zip(baked_instances, instance_texels)}
    stats["instances"] = [{"node": i.name, "mesh": i.mesh_name, "texels": texels_of.get(i.node, 0)} for i in st.instances]
    probe_points, probe_layout = _probe_points(st, s)

    if executor is None and refine is not None:
        t0 = time.perf_counter()
        baker = _core.Baker(*st.baker_args)
        stats["bvh_seconds"] = time.perf_counter() - t0
        stats["refined_from"] = refine.samples if refine.samples <= samples else 0
        traced, probe_out, probe_seconds, refl_out = _refine_local(baker, refine, inputs, probe_points, refl_points, refl, s,
                                                                  samples, reflection_samples, kw, directional, channels, progress)
    elif executor is None:
        t0 = time.perf_counter()
        baker = _core.Baker(*st.baker_args)
        stats["bvh_seconds"] = time.perf_counter() - t0
        traced = [_bake_page_local(baker, page, inp, s, {**kw, "directional": directional}, channels, progress) for page, inp in enumerate(inputs)]
        t_probes = time.perf_counter()
        probe_out = _bake_probes_local(baker, probe_points, s, progress, kw)
        probe_seconds = time.perf_counter() - t_probes
        refl_out = _bake_reflections_local(baker, refl_points, refl, kw, progress)
    else:
        traced, probe_out, probe_seconds, refl_out = _bake_on_ray(executor, st, inputs, probe_points, refl_points, refl, s, kw, channels,
                                                                  progress, stats)

    pages: list[np.ndarray] = []
    rays_total, texels_total, bake_seconds = 0, 0, 0.0
    page_stats = []
    for page, ((w, h, chart, covered, *_), (raw, rays, seconds)) in enumerate(zip(inputs, traced)):
        seams = page_seams(lods, layout, page, positions=positions, normals=normals,
                           min_normal_cos=s.post.seam_min_normal_cos) if s.post.stitch else None
        t_post = time.perf_counter()
        if directional:
            done = finish_directional_page(raw.reshape(h, w, DIRECTIONAL_CHANNELS), chart, seams=seams, settings=s.post)
        else:
            done = finish_page(raw.reshape(h, w, 3), chart, seams=seams, settings=s.post)
        pages.append(done.image)
        page_stats.append({"page": page, "texels": int(len(covered)), "rays": int(rays), "seconds": seconds,
                           "post_seconds": time.perf_counter() - t_post,
                           "denoised": bool((done.info["b0"] if directional else done.info).get("denoise", {}).get("denoised", False))})
        rays_total += rays
        texels_total += len(covered)
        bake_seconds += seconds
    stats.update(pages=page_stats, texels=int(texels_total), rays=int(rays_total), lightmap_seconds=bake_seconds,
                 rays_per_s=rays_total / bake_seconds if bake_seconds > 0 else 0.0)

    probes, probe_stats = _finish_probes(probe_layout, probe_out, s)
    stats["probes"] = probe_stats
    stats["probe_seconds"] = probe_seconds
    reflections = None
    if refl is not None:
        reflections, stats["reflections"] = _finish_reflections(scene.reflection_probes, refl, refl_out)
    return Baked(pages=pages, probes=probes, stats=stats, reflections=reflections)


def _bake_page_local(baker, page: int, inp, s: BakeSettings, kw: dict, channels: int, progress):
    """One page's covered texels in batches: (raw (h*w, channels), rays, seconds)."""
    w, h, _, covered, points, normals, ids = inp
    raw = np.zeros((h * w, channels), np.float32)
    rays, t_page = 0, time.perf_counter()
    with _stage(progress, f"bake p{page}", len(covered)) as bar:
        for a in range(0, len(covered), s.batch_texels):
            b = min(a + s.batch_texels, len(covered))
            out, n = baker.bake_points(points[a:b], normals[a:b], ids[a:b], samples=s.samples, **kw)
            raw[covered[a:b]] = out
            rays += n
            seconds = time.perf_counter() - t_page
            bar.note(f"{rays / max(seconds, 1e-9) / 1e6:.2f} Mrays/s")
            bar.advance(b - a)
    return raw, rays, time.perf_counter() - t_page


def _refine_local(baker, r: Refinement, inputs, probe_points, refl_points, refl, s: BakeSettings, samples: int, reflection_samples: int,
                  kw: dict, directional: bool, channels: int, progress):
    """`bake_level`'s local bake going on from `r`'s sums to `samples` and `reflection_samples`;
    returns what the one-shot local path returns, and commits the new sums to `r` only once the
    whole step is done (a step given up leaves `r` as the last one left it)."""
    # Sums with more samples than asked for cannot be taken back: start those over.
    start = r.samples if r.samples <= samples and len(r.pages) == len(inputs) else 0
    refl_start = r.reflection_samples if r.reflection_samples <= reflection_samples and len(r.reflections) == len(refl_points) else 0
    width = 13 if directional else 3
    new_pages, traced = [], []
    for page, (w, h, _, covered, points, normals, ids) in enumerate(inputs):
        sums = r.pages[page].copy() if start else np.zeros((len(covered), width), np.float64)
        rays, t_page = 0, time.perf_counter()
        with _stage(progress, f"bake p{page}", len(covered)) as bar:
            bar.note(f"samples {start} -> {samples}")
            for a in range(0, len(covered), s.batch_texels):
                r.check()
                b = min(a + s.batch_texels, len(covered))
                part = sums[a:b]  # rows of a C-ordered array: contiguous, updated in place
                rays += baker.add_samples(points[a:b], normals[a:b], part, start, samples, ids=ids[a:b], directional=directional, **kw)
                bar.advance(b - a)
        raw = np.zeros((h * w, channels), np.float32)
        raw[covered] = baker.finish_samples(points, normals, sums, samples, directional=directional)
        new_pages.append(sums)
        traced.append((raw, rays, time.perf_counter() - t_page))
    r.check()
    if r.probes is None:
        t_probes = time.perf_counter()
        probes = (_bake_probes_local(baker, probe_points, s, progress, kw), time.perf_counter() - t_probes)
    else:
        probes = r.probes
    new_refl, cubes, refl_rays, t_refl = [], [], 0, time.perf_counter()
    if len(refl_points):
        face, levels, _ = refl
        with _stage(progress, "reflections", len(refl_points)) as bar:
            for i, p in enumerate(refl_points):
                r.check()
                sums = r.reflections[i].copy() if refl_start else np.zeros((6 * face * face, 3), np.float64)
                refl_rays += baker.add_reflection_samples(tuple(float(x) for x in p), i, face, sums, refl_start, reflection_samples, **kw)
                cubes.append(baker.finish_reflection(sums, reflection_samples, face, levels))
                new_refl.append(sums)
                bar.advance()
    refl_out = (cubes, refl_rays, time.perf_counter() - t_refl)
    r.samples, r.pages, r.reflection_samples, r.reflections, r.probes = samples, new_pages, reflection_samples, new_refl, probes
    return traced, probes[0], probes[1], refl_out


def _bake_on_ray(executor, st: StaticScene, inputs, probe_points: np.ndarray, refl_points: np.ndarray, refl, s: BakeSettings, kw: dict,
                 channels: int, progress, stats: dict):
    """Every page's texels in tiles, the probes in batches and each reflection probe as Ray
    tasks, submitted together so the cluster stays busy across page boundaries. Returns what the
    local path returns."""
    from asset_pipeline import executor as ex

    # The baker's arguments (the local bake's, exactly) go into the object store once; tasks
    # carry the reference boxed in a list (a bare ObjectRef argument would be fetched and
    # deserialised for every task).
    ref = executor.put(st.baker_args)
    boxed = [ref]
    key = ref.hex()
    task_kw = {**kw, "threads": 1}  # one CPU per task (executor.RayExecutor._task)
    tiles, probe_batches = [], []
    for page, (_, _, _, covered, points, normals, ids) in enumerate(inputs):
        for a in range(0, len(covered), s.tile_texels):
            b = min(a + s.tile_texels, len(covered))
            tiles.append((page, a, b, (key, boxed, points[a:b], normals[a:b], ids[a:b], {**task_kw, "samples": s.samples, "directional": channels != 3})))
    ids = np.arange(len(probe_points), dtype=np.uint64)
    for a in range(0, len(probe_points), s.probe_tile):
        b = min(a + s.probe_tile, len(probe_points))
        probe_batches.append((a, b, (key, boxed, probe_points[a:b], ids[a:b], {**task_kw, "probe_samples": s.probe_samples})))
    # One task per reflection probe, its id its index as in the local bake.
    refl_tasks = [(key, boxed, tuple(float(x) for x in p), i, _reflection_kw(refl, task_kw)) for i, p in enumerate(refl_points)]

    total = len(refl_tasks) + len(tiles) + len(probe_batches)
    rays = [0]
    workers: set = set()
    builds = [0]
    t0 = time.perf_counter()
    with _stage(progress, "bake tiles", total) as bar:
        def done(result):
            rays[0] += result[-4]
            workers.add(result[-3])
            builds[0] += bool(result[-2])
            bar.note(f"{rays[0] / max(time.perf_counter() - t0, 1e-9) / 1e6:.2f} Mrays/s on {len(workers)} worker(s)")
            bar.advance()

        # Every kind is submitted before waiting on any, so they share the cluster; the reflection
        # probes (the longest tasks) first, so none starts last and holds up the end.
        calls = ([(ex.bake_reflection_probe, r) for r in refl_tasks] + [(ex.bake_tile, t[3]) for t in tiles]
                 + [(ex.bake_probe_batch, p[2]) for p in probe_batches])
        results = executor.run(calls, on_done=lambda i, r: done(r))
    refl_results, results = results[:len(refl_tasks)], results[len(refl_tasks):]
    tile_results, probe_results = results[:len(tiles)], results[len(tiles):]
    wall = time.perf_counter() - t0

    traced = []
    for page, (w, h, _, covered, *_) in enumerate(inputs):
        raw = np.zeros((h * w, channels), np.float32)
        page_rays, page_seconds = 0, 0.0
        for (p, a, b, _), (out, n, _, _, seconds) in zip(tiles, tile_results):
            if p == page:
                raw[covered[a:b]] = out
                page_rays += n
                page_seconds += seconds
        traced.append((raw, page_rays, page_seconds))  # seconds: summed over the page's tasks
    n = len(probe_points)
    sh, sun, back = np.zeros((n, 9, 3), np.float32), np.ones(n, np.float32), np.zeros(n, np.float32)
    probe_rays, probe_seconds = 0, 0.0
    for (a, b, _), (bsh, bsun, bback, r, _, _, seconds) in zip(probe_batches, probe_results):
        sh[a:b], sun[a:b], back[a:b] = bsh, bsun, bback
        probe_rays += r
        probe_seconds += seconds
    # seconds: summed over the probes' tasks
    refl_out = ([r[0] for r in refl_results], sum(int(r[1]) for r in refl_results), sum(r[4] for r in refl_results))
    stats["ray"] = {"tiles": len(tiles), "probe_batches": len(probe_batches), "reflection_tasks": len(refl_tasks),
                    "tile_texels": s.tile_texels, "probe_tile": s.probe_tile,
                    "workers": len(workers), "scene_builds": builds[0], "wall_seconds": wall,
                    "task_seconds": sum(t[2] for t in traced) + probe_seconds + refl_out[2],
                    "rays_per_s": rays[0] / wall if wall > 0 else 0.0}
    return traced, (sh, sun, back, probe_rays), probe_seconds, refl_out


# ---- reflection probes ---------------------------------------------------------------------------


def _reflection_kw(refl: tuple[int, int, int], kw: dict) -> dict:
    """Baker.bake_reflection_probe's keywords but the position and id: the cube's settings, and
    the bake's preset, seed, bounces and threads."""
    face, levels, samples = refl
    return {**kw, "face_size": face, "levels": levels, "samples": samples}


def _bake_reflections_local(baker, points: np.ndarray, refl, kw: dict, progress):
    """(cubes float32 (T, 3) per probe, rays, seconds); a probe's random streams are keyed by its
    index (`id`). Ctrl-C is honoured between probes."""
    cubes, rays = [], 0
    if not len(points):
        return cubes, rays, 0.0
    t0 = time.perf_counter()
    rkw = _reflection_kw(refl, kw)
    with _stage(progress, "reflections", len(points)) as bar:
        for i, p in enumerate(points):
            rgb, n = baker.bake_reflection_probe(tuple(float(x) for x in p), id=i, **rkw)
            cubes.append(rgb)
            rays += n
            bar.note(f"{rays / max(time.perf_counter() - t0, 1e-9) / 1e6:.2f} Mrays/s")
            bar.advance()
    return cubes, rays, time.perf_counter() - t0


def half_rgba(rgb: np.ndarray, what: str = "reflection probe") -> np.ndarray:
    """A cube's float32 (T, 3) radiance as the pack holds it: float16 (T, 4) RGBA, alpha 1, each
    channel clamped to [0, 65504] (half's largest finite value). A value that is not a number is
    a baker bug, refused rather than hidden."""
    rgb = np.asarray(rgb, np.float32)
    if rgb.ndim != 2 or rgb.shape[1] != 3:
        raise ValueError(f"{what}: expected (T, 3) radiance, got {rgb.shape}")
    if np.isnan(rgb).any():
        raise ValueError(f"{what}: the baker returned NaN radiance")
    out = np.ones((len(rgb), 4), np.float16)
    out[:, :3] = np.clip(rgb, 0.0, 65504.0)
    return out


def _finish_reflections(probes: list[ir.ReflectionProbe], refl, traced) -> tuple[ir.ReflectionCubes, dict]:
    face, levels, samples = refl
    raw, rays, seconds = traced
    texels = ir.cube_texels(face, levels)
    cubes = []
    for p, rgb in zip(probes, raw):
        if np.shape(rgb) != (texels, 3):
            raise ValueError(f"reflection probe '{p.name}': the baker returned {np.shape(rgb)} texels, expected ({texels}, 3)")
        cubes.append(half_rgba(rgb, f"reflection probe '{p.name}'"))
    stats = {"count": len(cubes), "face_size": face, "levels": levels, "samples": samples, "rays": int(rays), "seconds": seconds,
             "bytes": int(sum(c.nbytes for c in cubes))}
    return ir.ReflectionCubes(face_size=face, levels=levels, cubes=cubes), stats


# ---- probes -------------------------------------------------------------------------------------


def probe_grid(positions: np.ndarray, spacing: float, max_probes: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(origin, spacing, counts) of a grid covering the bounds of `positions`, cells of about
    `spacing` metres (widened until at most `max_probes`), probes at cell centres."""
    lo, hi = positions.min(axis=0).astype(np.float64), positions.max(axis=0).astype(np.float64)
    extent = np.maximum(hi - lo, 1e-3)
    step = float(spacing)
    while True:
        counts = np.maximum(np.ceil(extent / step).astype(np.int64), 1)
        if counts.prod() <= max_probes:
            break
        step *= 1.05
    cell = extent / counts
    return lo + 0.5 * cell, cell, counts


def _probe_points(st: StaticScene, s: BakeSettings):
    """The probe positions (float32 (n, 3), probe = i + nx (j + ny k)) and the grid (origin, cell, counts)."""
    origin, cell, counts = probe_grid(st.positions, s.probe_spacing, s.max_probes)
    nx, ny, nz = (int(c) for c in counts)
    k, j, i = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
    idx = np.stack([i.ravel(), j.ravel(), k.ravel()], 1)
    return np.ascontiguousarray((origin + idx * cell).astype(np.float32)), (origin, cell, counts)


def _bake_probes_local(baker, points: np.ndarray, s: BakeSettings, progress, kw):
    """(sh, sun visibility, backface, rays) of every probe, in batches."""
    ids = np.arange(len(points), dtype=np.uint64)
    sh = np.zeros((len(points), 9, 3), np.float32)
    sun = np.ones(len(points), np.float32)
    back = np.zeros(len(points), np.float32)
    batch = max(1, s.batch_texels // 64)
    rays = 0
    with _stage(progress, "probes", len(points)) as bar:
        for a in range(0, len(points), batch):
            b = min(a + batch, len(points))
            sh[a:b], sun[a:b], back[a:b], n = baker.bake_probes(points[a:b], ids[a:b], probe_samples=s.probe_samples, **kw)
            rays += n
            bar.advance(b - a)
    return sh, sun, back, rays


def _finish_probes(grid, traced, s: BakeSettings) -> tuple[ir.ProbeGrid, dict]:
    (origin, cell, counts), (sh, sun, back, rays) = grid, traced
    nx, ny, nz = (int(c) for c in counts)
    count = len(back)
    inside = back > s.max_backface
    sh, sun = _fill_invalid(sh.reshape(nz, ny, nx, 27), sun.reshape(nz, ny, nx), inside.reshape(nz, ny, nx))
    grid = ir.ProbeGrid(origin=tuple(float(x) for x in origin), spacing=tuple(float(x) for x in cell), counts=(nx, ny, nz),
                        sh=np.ascontiguousarray(sh.reshape(-1, 9, 3)), sun_visibility=np.ascontiguousarray(sun.reshape(-1)))
    return grid, {"count": int(count), "counts": [nx, ny, nz], "spacing": [float(x) for x in cell],
                  "inside_geometry": int(inside.sum()), "rays": int(rays)}


def _fill_invalid(sh: np.ndarray, sun: np.ndarray, invalid: np.ndarray):
    """Give each invalid probe the mean of its valid face neighbours, ring by ring outward, so
    values spread from open space into walls (where a dynamic object near a wall samples them)."""
    sh, sun, valid = sh.copy(), sun.copy(), ~invalid
    if not valid.any():
        return np.zeros_like(sh), np.ones_like(sun)
    while not valid.all():
        acc_sh, acc_sun, cnt = np.zeros_like(sh), np.zeros_like(sun), np.zeros(sun.shape)
        for axis in range(3):
            for shift in (1, -1):
                v = np.roll(valid, shift, axis)
                # np.roll wraps around: cut the wrapped slab.
                edge = [slice(None)] * 3
                edge[axis] = slice(0, 1) if shift == 1 else slice(-1, None)
                v[tuple(edge)] = False
                acc_sh += np.where(v[..., None], np.roll(sh, shift, axis), 0.0)
                acc_sun += np.where(v, np.roll(sun, shift, axis), 0.0)
                cnt += v
        grow = ~valid & (cnt > 0)
        sh[grow] = acc_sh[grow] / cnt[grow][:, None]
        sun[grow] = acc_sun[grow] / cnt[grow]
        valid = valid | grow
    return sh, sun


# ---- into the scene -----------------------------------------------------------------------------


def attach(scene: ir.Scene, baked: Baked) -> ir.Scene:
    """The scene with the baked pages as textures referenced by its lightmap layout (see
    LIGHTMAP_MODES: B as Rgba16Float; or b0 as Rgba16Float and the direction and the sun's
    visibility as Rgba8Unorm), the probes and the reflection probes' cubes. (The compress stage
    makes them BC6H and BC7.)"""
    from asset_pipeline import _core

    textures = list(scene.textures)
    ids, directions = [], []
    sun_toward, sun_lux = _exposure_sun(scene)
    log_sum, covered = 0.0, 0
    for page, img in enumerate(baked.pages):
        h, w, channels = img.shape
        if channels == DIRECTIONAL_CHANNELS:
            rgba, direction = mono_sh(img)
            directions.append(len(textures) + 1)
        else:
            rgba, direction = np.concatenate([img, np.ones((h, w, 1), np.float32)], axis=2), None
        ids.append(len(textures))
        half = np.ascontiguousarray(np.clip(rgba, 0.0, 65504.0).astype(np.float16))
        textures.append(ir.Texture(name=f"lightmap{page}", width=w, height=h, format="Rgba16Float", mips=[half]))
        if direction is not None:
            textures.append(ir.Texture(name=f"lightmap{page} direction", width=w, height=h, format="Rgba8Unorm", mips=[direction]))
        # The exposure's sum, from the texels as baked (the compress stage changes them later).
        s, n = _core.lightmap_log_average(half, direction, sun_toward, sun_lux)
        log_sum, covered = log_sum + s, covered + n
    log_average = float(np.exp(log_sum / covered)) if covered else 1.0
    layout = None if scene.lightmap is None else dataclasses.replace(scene.lightmap, textures=ids, directions=directions,
                                                                     log_average=log_average if baked.pages else None,
                                                                     samples=baked.stats.get("samples") if baked.pages else None)
    cubes = baked.reflections if baked.reflections is not None and len(baked.reflections.cubes) == len(scene.reflection_probes) else None
    return dataclasses.replace(scene, textures=textures, lightmap=layout, probes=baked.probes, reflection_cubes=cubes)


def _exposure_sun(scene: ir.Scene) -> tuple[list[float], list[float]]:
    """The first sun as the runtime's exposure takes it (pack::exposure::Sun): the unit direction
    toward it and colour times lux; (up, zeros) without one."""
    sun = next((l for l in scene.lights if l.kind == "sun"), None)
    if sun is None:
        return [0.0, 1.0, 0.0], [0.0, 0.0, 0.0]
    toward = -np.asarray(sun.direction, np.float64)
    n = np.linalg.norm(toward)
    return (toward / n if n > 0 else toward).tolist(), (np.asarray(sun.color, np.float64) * sun.intensity).tolist()


# Rec. 709 luminance weights (textures.md section 4.2; shading::sh::LUMINANCE).
LUMINANCE = np.array([0.2126, 0.7152, 0.0722], np.float32)


def mono_sh(page: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A directional page (h, w, 13) as the pack holds it: (b0 rgb, alpha 1 (h, w, 4) float32;
    the luminance's direction t = b1_Y / (2 b0_Y), |t| <= 1, as bytes 128 + 127 t and the sun's
    visibility as byte 255 v in (h, w, 4) uint8). The same reduction as
    shading::sh::MonoSh::from_rgb. (The visibility rides with the direction so the page is RGB,
    which BC6H holds; 8 bits are the shadow masks' precision in other engines too.)"""
    h, w, _ = page.shape
    b0 = page[..., 0:3]
    b1 = page[..., 3:12].reshape(h, w, 3, 3)  # [channel, axis]
    b0_y = b0 @ LUMINANCE
    b1_y = np.einsum("c,hwca->hwa", LUMINANCE, b1)
    t = np.where(b0_y[..., None] > 0.0, b1_y / (2.0 * np.maximum(b0_y, 1e-30))[..., None], 0.0)
    # Non-negative radiance keeps |t| <= 1; noise may not.
    t /= np.maximum(np.linalg.norm(t, axis=-1, keepdims=True), 1.0)
    direction = np.empty((h, w, 4), np.uint8)
    # 128 + 127 t: symmetric, so t = 0 is exactly 128 (the shader decodes (x - 128) / 127).
    direction[..., :3] = np.clip(128.0 + np.rint(127.0 * t), 1, 255).astype(np.uint8)
    direction[..., 3] = np.rint(255.0 * np.clip(page[..., 12], 0.0, 1.0)).astype(np.uint8)
    return np.concatenate([b0, np.ones((h, w, 1), np.float32)], axis=2).astype(np.float32), direction


class _NoBar:
    def advance(self, n: int = 1) -> None:
        pass

    def note(self, text: str) -> None:
        pass


def _stage(progress, name: str, total: int):
    if progress is None:
        from contextlib import nullcontext

        return nullcontext(_NoBar())
    return progress.stage(name, total)


# Instances listed one per line in the report, at most (the rest are summed up in one line).
DESCRIBE_INSTANCES = 40


def describe(stats: dict) -> list[str]:
    """Report lines for the bake."""
    mode = stats.get("lightmap_mode", "irradiance")
    lines = [f"Preset {stats.get('preset')}, {mode} lightmaps; {stats.get('static_triangles', 0)} static triangles."]
    inst = stats.get("instances")
    if inst is not None:
        with_texels = [i for i in inst if i["texels"] > 0]
        lines.append(f"Static instances: {stats.get('static_instances', len(inst))}, {len(with_texels)} with lightmap texels "
                     f"(each instance its own).")
        for i in inst[:DESCRIBE_INSTANCES]:
            lines.append(f"- instance '{i['node']}' (mesh '{i['mesh']}'): {i['texels']} texels")
        if len(inst) > DESCRIBE_INSTANCES:
            rest = inst[DESCRIBE_INSTANCES:]
            lines.append(f"- ... and {len(rest)} more instances: {sum(i['texels'] for i in rest)} texels")
    if stats.get("texels"):
        lines.append(f"Lightmaps: {stats['texels']} texels, {stats['rays'] / 1e6:.1f} M rays in {stats['lightmap_seconds']:.1f} s "
                     f"({stats['rays_per_s'] / 1e6:.2f} M rays/s).")
        for p in stats.get("pages", []):
            lines.append(f"- page {p['page']}: {p['texels']} texels, {p['rays'] / 1e6:.1f} M rays, {p['seconds']:.1f} s bake + "
                         f"{p['post_seconds']:.1f} s clean-up{' (denoised)' if p['denoised'] else ''}")
    r = stats.get("ray")
    if r:
        refl_tasks = f", {r['reflection_tasks']} reflection probe task(s)" if r.get("reflection_tasks") else ""
        lines.append(f"On Ray: {r['tiles']} tiles of {r['tile_texels']} texels and {r['probe_batches']} probe batches of {r['probe_tile']}{refl_tasks} "
                     f"on {r['workers']} worker(s) (scene built {r['scene_builds']} time(s)), {r['wall_seconds']:.1f} s wall, "
                     f"{r['rays_per_s'] / 1e6:.2f} M rays/s across the cluster; per-page seconds are summed over tasks.")
    pr = stats.get("probes")
    if pr:
        lines.append(f"Probes: {pr['count']} ({' x '.join(str(c) for c in pr['counts'])}, cells "
                     f"{' x '.join(f'{x:.2f}' for x in pr['spacing'])} m), {pr['inside_geometry']} inside geometry (filled from "
                     f"neighbours), {pr['rays'] / 1e6:.1f} M rays in {stats.get('probe_seconds', 0.0):.1f} s.")
    rp = stats.get("reflections")
    if rp:
        lines.append(f"Reflection probes: {rp['count']}, cube faces {rp['face_size']} px with {rp['levels']} levels, {rp['samples']} samples per "
                     f"texel; {rp['rays'] / 1e6:.1f} M rays in {rp['seconds']:.1f} s{' (summed over tasks)' if r else ''}; "
                     f"{rp['bytes']} bytes ({rp['bytes'] / 2**20:.2f} MiB, half-float RGBA).")
    return lines

