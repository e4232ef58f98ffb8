"""Level spec -> scene IR: brushes through manifold3d into closed meshes, plus materials, props,
lights, spawns, reflection probes and sky.

``build_level(spec) -> ir.Scene``. One mesh per output object (see
``LevelSpec.outputs``), positions in world space under an identity node. Each output triangle
gets the material of the brush whose surface it lies on: every brush is made an *original* in
manifold3d (``as_original``), and the ids survive the booleans as ``run_original_id``.

Vertices are split only where the shading needs it (normals across edges sharper than
SMOOTH_DEG, a change of projection axis for uv0, a change of material); a split vertex is an
exact copy of manifold3d's position, so welding by position gives back the closed, oriented
manifold (tests/test_level.py checks this).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from pathlib import Path

import manifold3d as m3
import numpy as np

from asset_pipeline import gltf_import, ir, obstacles
from asset_pipeline.level import BrushSpec, LevelSpec
from asset_pipeline.procedural_textures import procedural_relief, procedural_texture

SMOOTH_DEG = 40.0  # edges sharper than this keep separate normals (boxes crisp, 24+-gon cylinders smooth)

# World-space box projection for uv0: for a face whose normal is mostly +X, -X, +Y, -Y, +Z, -Z,
# u = P.U / uv_scale and v = P.V / uv_scale. Each face reads its texture upright and unmirrored
# when seen from outside (v grows downwards, as glTF's), so tangents all have w = +1.
PROJ_U = np.array([[0, 0, -1], [0, 0, 1], [1, 0, 0], [-1, 0, 0], [1, 0, 0], [-1, 0, 0]], dtype=np.float64)
PROJ_V = np.array([[0, -1, 0], [0, -1, 0], [0, 0, 1], [0, 0, 1], [0, -1, 0], [0, -1, 0]], dtype=np.float64)

_OPS = {"union": m3.OpType.Add, "difference": m3.OpType.Subtract, "intersection": m3.OpType.Intersect}


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 1e-30, n, 1.0)


def _brush_manifold(b: BrushSpec) -> m3.Manifold:
    s = b.shape
    if b.kind == "box":
        m = m3.Manifold.cube(s["size"], center=True)
    elif b.kind == "cylinder":
        top = s["radius"] if s["radius_top"] is None else s["radius_top"]
        # manifold3d's cylinder runs along +Z; ours along +Y (up)
        m = m3.Manifold.cylinder(s["height"], s["radius"], top, s["segments"], center=True).rotate((-90, 0, 0))
    elif b.kind == "sphere":
        m = m3.Manifold.sphere(s["radius"], s["segments"])
    else:  # extrude: either winding is accepted; manifold3d's fill rule wants counter-clockwise
        pts = np.asarray(s["points"], dtype=np.float64)
        if np.sum(pts[:, 0] * np.roll(pts[:, 1], -1) - np.roll(pts[:, 0], -1) * pts[:, 1]) < 0:
            pts = pts[::-1]
        m = m3.Manifold.extrude(m3.CrossSection([pts]), s["height"]).translate((0, 0, -s["height"] / 2))
    m = m.transform(b.transform[:3, :4])
    count, step = b.repeat
    if count > 1:
        m = m3.Manifold.batch_boolean([m.translate(tuple(k * np.asarray(step))) for k in range(count)], m3.OpType.Add)
    return m.as_original()


def surface(pos: np.ndarray, tris: np.ndarray, tri_mat: np.ndarray, uv_scale: np.ndarray) -> tuple[dict, np.ndarray]:
    """Shading attributes for a closed mesh (pos (n,3) float32, tris (m,3), tri_mat (m,) material
    index, uv_scale per material): returns (attributes, triangles) with vertices split where
    normal, projection axis or material change."""
    p = pos.astype(np.float64)
    t = tris.astype(np.int64)
    m = len(t)
    cross = np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]])
    fn = _unit(cross)
    # corner angles weight the normals, so long thin triangles do not skew them; slivers that
    # booleans leave behind (too thin for their normal to be trusted) do not contribute at all
    a = p[np.roll(t, -1, axis=1)] - p[t]
    b = p[np.roll(t, -2, axis=1)] - p[t]
    angle = np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.sum(a * b, axis=-1))
    sliver = np.linalg.norm(cross, axis=1) < 1e-6 * np.max(np.sum(a * a, axis=-1), axis=1)
    angle = (angle * ~sliver[:, None]).ravel()
    cv, cf = t.ravel(), np.repeat(np.arange(m), 3)

    # each corner's normal: the angle-weighted face normals around its vertex within SMOOTH_DEG of
    # its own face. Pairs of corners sharing a vertex are enumerated with repeat/cumsum, no loops.
    order = np.argsort(cv, kind="stable")
    sv = cv[order]
    start = np.flatnonzero(np.r_[True, sv[1:] != sv[:-1]])
    sizes = np.diff(np.r_[start, len(sv)])
    group = np.repeat(np.arange(len(start)), sizes)
    reps = sizes[group]
    i = np.repeat(np.arange(len(sv)), reps)
    j = start[group][i] + np.arange(len(i)) - np.repeat(np.cumsum(reps) - reps, reps)
    ci, cj = order[i], order[j]
    fj = fn[cf[cj]]
    near = np.sum(fn[cf[ci]] * fj, axis=1) >= np.cos(np.radians(SMOOTH_DEG))

    def gather(w):
        return np.stack([np.bincount(ci, weights=w * fj[:, k], minlength=3 * m) for k in range(3)], axis=1)

    normal = gather(angle[cj] * near)
    lost = np.linalg.norm(normal, axis=1) < 1e-12  # a sliver's corner with no trusted face near it
    if lost.any():
        normal[lost] = gather(angle[cj])[lost]
        lost = np.linalg.norm(normal, axis=1) < 1e-12
        normal[lost] = fn[cf[lost]]
    normal = _unit(normal)

    axis = np.argmax(np.abs(fn), axis=1)
    code = 2 * axis + (fn[np.arange(m), axis] < 0)
    key = np.column_stack([cv, code[cf], tri_mat[cf], np.rint(normal * 1e5).astype(np.int64)])
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)

    vp, vn, vc, vm = p[cv[first]], normal[first], code[cf[first]], tri_mat[cf[first]]
    U, V = PROJ_U[vc], PROJ_V[vc]
    s = uv_scale[vm][:, None]
    uv = np.stack([np.sum(vp * U, axis=1), np.sum(vp * V, axis=1)], axis=1) / s
    # Textures repeat, so each projection's coordinates move by whole repeats to lie around 0
    # (one shift per projection and material: materials repeat at their own scales). Far from
    # the origin a room's uv0 would otherwise span the distance between its faces' axes (u = x
    # on its floor, u = -z on its walls: 400 repeats for one room of the 1M-triangle benchmark
    # level), more than the pack's 16-bit coordinates hold to a quarter texel.
    group = vc.astype(np.int64) * (int(vm.max(initial=0)) + 1) + vm
    for g in np.unique(group):
        at = group == g
        uv[at] -= np.floor(0.5 * (uv[at].min(axis=0) + uv[at].max(axis=0)))
    # tangent = dP/du: in the surface, along which v stays constant (perpendicular to V)
    tan = np.cross(vn, V)
    tan *= np.where(np.sum(tan * U, axis=1) < 0, -1.0, 1.0)[:, None]
    bad = np.linalg.norm(tan, axis=1) < 1e-6
    tan[bad] = U[bad] - vn[bad] * np.sum(U[bad] * vn[bad], axis=1)[:, None]
    tan = _unit(tan)
    # glTF: bitangent = cross(N, T) * w points to decreasing v (up in the image)
    hand = np.where(np.sum(np.cross(vn, tan) * -V, axis=1) < 0, -1.0, 1.0)
    n = len(first)
    attributes = {
        "position": pos[cv[first]].astype(np.float32),
        "normal": vn.astype(np.float32),
        "tangent": np.column_stack([tan, hand]).astype(np.float32),
        "uv0": uv.astype(np.float32),
        "color": np.full((n, 4), 255, dtype=np.uint8),
    }
    return attributes, inverse.reshape(m, 3).astype(np.uint32)


def _texture(spec: LevelSpec, mat_index: int, base_dir: Path) -> ir.Texture:
    m = spec.materials[mat_index]
    if isinstance(m.texture, dict):
        rgba = procedural_texture(m.texture)
        name = f"{m.texture['procedural']}-{hashlib.sha1(json.dumps(m.texture, sort_keys=True).encode()).hexdigest()[:8]}"
    else:
        rgba = gltf_import.decode_image(base_dir / m.texture)
        name = m.texture
    return ir.Texture(name=name, width=rgba.shape[1], height=rgba.shape[0], format="Rgba8Srgb", mips=[rgba])


def _append_meshes(scene: ir.Scene, prop: ir.Scene) -> int:
    """Append `prop`'s meshes, materials and textures to `scene`, their references remapped;
    returns the index the prop's first mesh has in `scene`. A texture the scene already holds
    (the same asset spawned twice, as the level's two golems are) is shared, not copied."""
    mesh0, mat0 = len(scene.meshes), len(scene.materials)
    index = []
    for t in prop.textures:
        same = next((i for i, u in enumerate(scene.textures) if u.same_as(t)), None)
        if same is None:
            same = len(scene.textures)
            scene.textures.append(t)
        index.append(same)
    scene.materials += [mt.with_textures_mapped(index) for mt in prop.materials]
    scene.meshes += [dataclasses.replace(me, lods=[
        dataclasses.replace(l, materials=(l.materials + mat0).astype(np.uint32)) for l in me.lods]) for me in prop.meshes]
    return mesh0


def merge_prop(scene: ir.Scene, prop: ir.Scene, name: str, transform: np.ndarray, static: bool) -> None:
    """Append `prop`'s meshes, materials, textures, nodes and lights to `scene` (which is being
    built and is modified), under a new root node `name` placed by `transform` (4x4). `prop` is
    not modified."""
    mesh0 = _append_meshes(scene, prop)
    root = len(scene.nodes)
    scene.nodes.append(ir.Node(name=name, local=tuple(float(x) for x in transform.ravel(order="F"))))
    # The level's switch decides for every mesh node of the prop (a prop's animation is not
    # brought in, so nothing in a static prop moves).
    scene.nodes += [dataclasses.replace(nd, name=f"{name}/{nd.name}", parent=root if nd.parent is None else root + 1 + nd.parent,
                                        mesh=None if nd.mesh is None else nd.mesh + mesh0, static=static and nd.mesh is not None)
                    for nd in prop.nodes]
    # ir.Light positions are world space: carry the prop's lights along with its transform
    for li in prop.lights:
        pos = transform @ np.array([*li.position, 1.0])
        d = _unit(transform[:3, :3] @ np.asarray(li.direction, dtype=np.float64))
        scene.lights.append(dataclasses.replace(li, name=f"{name}/{li.name}", position=tuple(float(x) for x in pos[:3]),
                                                direction=tuple(float(x) for x in d)))


def _spawn_asset(spec: LevelSpec, index: int, label: str, import_gltf) -> tuple[str, ir.Scene]:
    """Spawn `index`'s `asset` (a glTF relative to the toml) imported, with its name; errors
    name the spawn as "<label> '<spawn>'"."""
    sp = spec.spawns[index]
    key = ("spawns", index, "params", "asset")
    asset = sp.params.get("asset")
    if not isinstance(asset, str) or not asset.lower().endswith((".gltf", ".glb")):
        raise spec.error(key, f"{label} '{sp.name}': expected a .gltf or .glb asset, got {asset!r}")
    path = spec.check_file(key, asset, f"{label} '{sp.name}': asset")
    try:
        return asset, import_gltf(path)
    except Exception as e:  # the importer's message names the problem; the level error names the spawn
        raise spec.error(key, f"{label} '{sp.name}': cannot import '{asset}': {e}") from None


def merge_character(scene: ir.Scene, spec: LevelSpec, index: int, import_gltf) -> None:
    """Bring in the glTF of character spawn `index` (`asset`, relative to the toml) as dynamic
    meshes under a root node named after the spawn, placed at its position and rotation, with
    its skins and clips remapped onto the merged nodes. Clips are renamed "<spawn>/<clip>" so
    two characters from one asset keep apart; the runtime plays "<spawn>/<animation>"."""
    sp = spec.spawns[index]
    key = ("spawns", index, "params", "asset")
    asset, prop = _spawn_asset(spec, index, "character", import_gltf)
    if not prop.skins:
        raise spec.error(key, f"character '{sp.name}': '{asset}' has no skin")
    animation = sp.params.get("animation")
    clips = [c.name for c in prop.clips]
    if animation is not None and animation not in clips:
        raise spec.error(("spawns", index, "params", "animation"),
                         f"character '{sp.name}': '{asset}' has no clip '{animation}' (it has: {', '.join(clips) or 'none'})")
    q = np.asarray(sp.rotation, dtype=np.float64)
    x, y, z, w = q / max(np.linalg.norm(q), 1e-12)
    transform = np.eye(4)
    transform[:3, :3] = [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                         [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                         [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]
    transform[:3, 3] = sp.position
    node0, skin0 = len(scene.nodes) + 1, len(scene.skins)  # +1: merge_prop's root node
    merge_prop(scene, prop, sp.name, transform, static=False)
    scene.files += [f for f in prop.files if f not in scene.files]
    for nd in scene.nodes[node0:]:
        if nd.skin is not None:
            nd.skin += skin0
    scene.skins += [dataclasses.replace(sk, name=f"{sp.name}/{sk.name}", joints=[j + node0 for j in sk.joints]) for sk in prop.skins]
    scene.clips += [ir.Clip(name=f"{sp.name}/{c.name}", channels=[dataclasses.replace(ch, node=ch.node + node0) for ch in c.channels])
                    for c in prop.clips]


def merge_boid_mesh(scene: ir.Scene, spec: LevelSpec, index: int, import_gltf) -> None:
    """Bring in the glTF of boids spawn `index` (`asset`, relative to the toml): its one mesh,
    as authored in mesh space (a bird facing +Z with up +Y, at its size in metres), joins the
    scene's meshes with no node, and the spawn's `mesh` parameter names it for the runtime, which
    draws every bird of the flock with it. Content decides what a flock looks like."""
    sp = spec.spawns[index]
    key = ("spawns", index, "params", "asset")
    asset, prop = _spawn_asset(spec, index, "boids", import_gltf)
    used = sorted({nd.mesh for nd in prop.nodes if nd.mesh is not None})
    if len(used) != 1:
        raise spec.error(key, f"boids '{sp.name}': '{asset}' must hold one mesh (the bird), it has {len(used)}")
    if prop.skins or any(me.morph_weights for me in prop.meshes):
        raise spec.error(key, f"boids '{sp.name}': '{asset}' is skinned or morphed; a flock draws one rigid mesh per bird")
    mesh = _append_meshes(scene, prop) + used[0]
    scene.files += [f for f in prop.files if f not in scene.files]
    scene.spawns[index] = dataclasses.replace(sp, params={**sp.params, "mesh": mesh})


def build_level(spec: LevelSpec, *, import_gltf=None) -> ir.Scene:
    """Build the scene of a loaded level. Relative paths (textures, props) resolve against the
    spec's directory. `import_gltf(path) -> ir.Scene` loads props (default:
    asset_pipeline.gltf_import.import_gltf, keeping their URIs inside the level's folder tree).
    The scene's `files` lists every file read. Raises CookError on an empty object."""
    base_dir = spec.path.parent
    if import_gltf is None:
        # Props' and characters' buffers and images must stay inside the level's folder tree too.
        def import_gltf(path):
            return gltf_import.import_gltf(path, root=spec.path.parent, allow_external_uris=spec.allow_external)
    # The level's lightmap density rides in a layout with no pages yet: the uv2 stage lays it out.
    scene = ir.Scene(name=spec.name, source=str(spec.path), sky=spec.sky, lights=list(spec.lights),
                     spawns=list(spec.spawns), reflection_probes=list(spec.reflection_probes),
                     lightmap=ir.LightmapLayout(spec.texels_per_metre, pages=[]), files=[str(spec.path)])

    # A texture table (or path) -> its textures' indices: base colour, and for procedural relief
    # the normal map and the occlusion-roughness-metalness map.
    textures: dict[str, tuple[int, int | None, int | None]] = {}
    for i, m in enumerate(spec.materials):
        tex = normal = orm = None
        if m.texture is not None:
            k = json.dumps(m.texture, sort_keys=True)
            if k not in textures:
                tex = len(scene.textures)
                base = _texture(spec, i, base_dir)
                scene.textures.append(base)
                if isinstance(m.texture, str):
                    scene.files.append(str(base_dir / m.texture))
                relief = procedural_relief(m.texture) if isinstance(m.texture, dict) else None
                if relief is not None:
                    normal, orm = tex + 1, tex + 2
                    for suffix, rgba, usage in (("normal", relief[0], "normal"), ("orm", relief[1], "data")):
                        scene.textures.append(ir.Texture(name=f"{base.name}-{suffix}", width=rgba.shape[1], height=rgba.shape[0],
                                                         format="Rgba8Unorm", mips=[rgba], usage=usage))
                textures[k] = (tex, normal, orm)
            tex, normal, orm = textures[k]
        scene.materials.append(ir.Material(name=m.name, base_color=m.base_color, base_color_texture=tex, metallic=m.metallic,
                                           roughness=m.roughness, emissive=m.emissive, double_sided=m.double_sided,
                                           normal_texture=normal, metallic_roughness_texture=orm, occlusion_texture=orm))

    brushes = {b.name: i for i, b in enumerate(spec.brushes)}
    solids: dict[str, m3.Manifold] = {}
    brush_of_id: dict[int, int] = {}

    def solid(name: str) -> m3.Manifold:
        if name not in solids:
            i = brushes[name]
            m = _brush_manifold(spec.brushes[i])
            if m.is_empty() or m.status() != m3.Error.NoError:
                raise spec.error(("brushes", i), f"brush '{name}' has no volume ({m.status().name})")
            brush_of_id[m.original_id()] = i
            solids[name] = m
        return solids[name]

    for i, o in enumerate(spec.objects):
        m = m3.Manifold.batch_boolean([solid(n) for n in o.operands], _OPS[o.op])
        if m.status() != m3.Error.NoError:
            raise spec.error(("objects", i), f"object '{o.name}': manifold3d failed: {m.status().name}")
        if m.is_empty():
            raise spec.error(("objects", i, "op"), f"object '{o.name}': the {o.op} of {', '.join(o.operands)} is empty")
        solids[o.name] = m

    uv_scale = np.array([m.uv_scale for m in spec.materials], dtype=np.float64)
    brush_material = np.array([b.material for b in spec.brushes], dtype=np.uint32)
    for i in spec.outputs:
        o = spec.objects[i]
        mesh = solids[o.name].to_mesh()
        pos = np.asarray(mesh.vert_properties)[:, :3]
        # manifold3d keeps surfaces that merely touch (brushes meeting along an edge or at a
        # point) as separate vertices at one position; welded by position, as every later stage
        # sees the mesh, that is not a closed surface. Say where, so the author can fix it.
        uniq, count = np.unique(pos, axis=0, return_counts=True)
        if len(uniq) < len(pos):
            x, y, z = uniq[np.argmax(count > 1)]
            raise spec.error(("objects", i), f"object '{o.name}': surfaces touch without merging at ({x:.3f}, {y:.3f}, {z:.3f}) "
                                             "(brushes meeting along an edge or at a point): move them apart or overlap them")
        runs = np.asarray(mesh.run_index, dtype=np.int64) // 3
        brush = np.repeat([brush_of_id[r] for r in mesh.run_original_id], np.diff(runs))
        tri_mat = brush_material[brush]
        attrs, tris = surface(pos, np.asarray(mesh.tri_verts), tri_mat, uv_scale)
        scene.nodes.append(ir.Node(name=o.name, mesh=len(scene.meshes), static=o.static))
        scene.meshes.append(ir.Mesh(name=o.name, lods=[ir.Lod(attributes=attrs, triangles=tris, materials=tri_mat)],
                                    texels_per_metre=o.texels_per_metre))

    for i, p in enumerate(spec.props):
        prop = import_gltf(base_dir / p.gltf)
        merge_prop(scene, prop, p.name, p.transform, p.static)
        scene.files += [f for f in [str(base_dir / p.gltf), *prop.files] if f not in scene.files]
    for i, sp in enumerate(spec.spawns):
        if sp.kind == "character" and "asset" in sp.params:
            merge_character(scene, spec, i, import_gltf)
        elif sp.kind == "boids":
            merge_boid_mesh(scene, spec, i, import_gltf)
    scene.pillars = obstacles.pillars(spec)

    scene.validate()
    return scene
