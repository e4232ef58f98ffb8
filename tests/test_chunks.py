"""Level chunks (issue 23): the cooker cuts the temple's large static meshes into chunks, each a
mesh and static instance of its own, so the runtime culls, occludes and picks LODs inside the
level.

Real cooks of content/levels/temple.toml (a draft bake of one sample per texel: the tests are
about geometry and bytes, not light), read back with the pack crate's reader
(`_core.read_pack_manifest`) and the pack's own vertex layout: once as `cook` makes it, once with
`--no-chunks`, each with its own cache so the two bakes are made independently."""

from __future__ import annotations

import dataclasses
import json
import re
from pathlib import Path

import numpy as np
import pytest

from asset_pipeline import CookError, _core, ir
from asset_pipeline.chunks import ChunkSettings, partition
from asset_pipeline.cook import cook_detailed
from asset_pipeline.lod import LodSettings, build_lods
from asset_pipeline.pipeline import CookSettings
from conftest import REPO, cook_ok

LEVEL = REPO / "content" / "levels" / "temple.toml"
QUICK = ("--quality", "draft", "--samples", "1", "--probe-samples", "4", "--reflection-face", "8", "--reflection-samples", "1")

# The temple's split, pinned: triangles per chunk, in chunk order (chunk 0 holds the triangles
# longer than the chunk size, 8 m). Any change to the partition or to the level changes these.
TEMPLE_CHUNKS = {
    "temple": [665, 91, 83, 140, 126, 129, 223, 69, 118, 190, 165, 177, 102, 138, 126],
    "courtyard": [121, 60, 60, 152, 147, 149, 152, 36, 147, 152],
}
WHOLE = ("ground", "altar", "braziers", "fountain")  # static but small (or few triangles): never split

# pack::Vertex decoded (`_core.decode_vertices`), 80 bytes.
VERTEX = np.dtype([("position", "<f4", 3), ("normal", "<f4", 3), ("tangent", "<f4", 4), ("uv0", "<f4", 2), ("uv1", "<f4", 2),
                   ("texcoord1", "<f4", 2), ("color", "u1", 4), ("pad", "<u4", 3)])
assert VERTEX.itemsize == 80


# ---- reading packs ------------------------------------------------------------------------------


class Pack:
    """A cooked pack as the runtime reads it: its manifest (validated by the pack crate) and data."""

    def __init__(self, path: Path):
        self.path = path
        doc, self.data = _core.read_pack(path)
        self.doc = json.loads(doc)
        self.world = _world(self.doc["nodes"])

    def mesh(self, name: str) -> int:
        [i] = [i for i, m in enumerate(self.doc["meshes"]) if m["name"] == name]
        return i

    def lod(self, mesh: int, level: int = 0) -> dict:
        """A LOD's vertices (VERTEX records), triangles (m, 3) and per triangle its material and
        lightmap block (from its submesh)."""
        lod = self.doc["meshes"][mesh]["lods"][level]
        v, i = lod["vertices"], lod["indices"]
        stored = self.data[v["offset"]:v["offset"] + v["len"]]
        vertices = np.frombuffer(_core.decode_vertices(stored, json.dumps(lod["uv_ranges"])), VERTEX)
        indices = np.frombuffer(self.data, {"u16": "<u2", "u32": "<u4"}[lod["index_format"]], lod["index_count"], i["offset"])
        materials = np.zeros(len(indices) // 3, np.int64)
        blocks = np.full(len(indices) // 3, -1, np.int64)
        for s in lod["submeshes"]:
            t = slice(s["first_index"] // 3, (s["first_index"] + s["index_count"]) // 3)
            materials[t] = s["material"]
            blocks[t] = -1 if s["lightmap_block"] is None else s["lightmap_block"]
        return {"vertices": vertices, "triangles": indices.reshape(-1, 3).astype(np.int64), "materials": materials, "blocks": blocks,
                "error": lod["error"]}

    def instances(self, mesh: int) -> list[int]:
        return [k for k, n in enumerate(self.doc["nodes"]) if n["mesh"] == mesh]


def _world(nodes: list[dict]) -> list[np.ndarray]:
    out: list[np.ndarray] = []
    for n in nodes:
        local = np.array(n["local"], np.float64).reshape(4, 4).T
        out.append(out[n["parent"]] @ local if n["parent"] is not None else local)
    return out


def chunk_names(pack: Pack, mesh: str) -> list[str]:
    """The chunk meshes of `mesh`, in chunk order."""
    names = {m["name"] for m in pack.doc["meshes"]}
    return [f"{mesh}#{k}" for k in range(len(names)) if f"{mesh}#{k}" in names]


def triangle_rows(pack: Pack, mesh: int, node: int) -> np.ndarray:
    """Every triangle of `mesh`'s LOD 0 placed by `node` as one byte row: its three corners' world
    positions (float64), every other attribute's bytes, its material and lightmap block."""
    lod = pack.lod(mesh)
    w = pack.world[node]
    v = lod["vertices"]
    world = v["position"].astype(np.float64) @ w[:3, :3].T + w[:3, 3]
    rest = v.copy()
    rest["position"] = 0
    per_vertex = np.concatenate([world.view(np.uint8).reshape(len(v), -1), rest.view(np.uint8).reshape(len(v), -1)], axis=1)
    t = lod["triangles"]
    rows = np.concatenate([per_vertex[t].reshape(len(t), -1), lod["materials"][:, None].view(np.uint8),
                           lod["blocks"][:, None].view(np.uint8)], axis=1)
    return np.ascontiguousarray(rows)


def sorted_rows(rows: np.ndarray) -> np.ndarray:
    return rows[np.lexsort(rows.T[::-1])]


def border_edges(positions: np.ndarray, triangles: np.ndarray) -> set[bytes]:
    """The open border of a mesh welded by position: edges (as their two positions' bytes, in
    order) that only one triangle has."""
    keys = np.ascontiguousarray(positions, np.float32).view(np.dtype((np.void, 12))).ravel()
    _, vid = np.unique(keys, return_inverse=True)
    vid = vid.ravel()
    t = vid[triangles]
    e = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    e = e[e[:, 0] != e[:, 1]]
    e.sort(axis=1)
    uniq, count = np.unique(e, axis=0, return_counts=True)
    first = np.zeros(vid.max() + 1, np.int64)
    first[vid] = np.arange(len(vid))
    p = np.ascontiguousarray(positions, np.float32)
    once = uniq[count == 1]
    return {p[first[a]].tobytes() + p[first[b]].tobytes() if p[first[a]].tobytes() < p[first[b]].tobytes()
            else p[first[b]].tobytes() + p[first[a]].tobytes() for a, b in once}


# ---- the cooks ----------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def cooks(tmp_path_factory) -> dict[str, Pack]:
    """The temple cooked as `cook` does (chunks) and with --no-chunks, each with its own cache."""
    out = {}
    for name, extra in (("chunks", ()), ("whole", ("--no-chunks",))):
        d = tmp_path_factory.mktemp(name)
        cook_ok(LEVEL, d / "temple.pack", "-q", *QUICK, *extra)
        out[name] = Pack(d / "temple.pack")
    return out


def test_the_temple_is_cut_into_its_pinned_chunks_and_small_meshes_stay_whole(cooks):
    pack = cooks["chunks"]
    for mesh, triangles in TEMPLE_CHUNKS.items():
        names = chunk_names(pack, mesh)
        assert len(names) == len(triangles), (mesh, names)
        assert [pack.doc["meshes"][pack.mesh(n)]["lods"][0]["index_count"] // 3 for n in names] == triangles, mesh
        assert not any(m["name"] == mesh for m in pack.doc["meshes"]), f"{mesh} is still in the pack whole"
        # Its node stays (name, transform, static) and places nothing; a static child per chunk.
        [node] = [k for k, n in enumerate(pack.doc["nodes"]) if n["name"] == mesh]
        assert pack.doc["nodes"][node]["mesh"] is None and pack.doc["nodes"][node]["lightmap"] is None
        assert pack.doc["nodes"][node]["is_static"]
        children = [n for n in pack.doc["nodes"] if n["parent"] == node]
        assert [c["name"] for c in children] == names
        assert all(c["is_static"] and c["mesh"] == pack.mesh(c["name"]) for c in children)
        assert all(np.array_equal(pack.world[pack.doc["nodes"].index(c)], pack.world[node]) for c in children)
    assert sum(len(t) for t in TEMPLE_CHUNKS.values()) == 25
    for mesh in WHOLE:
        pack.mesh(mesh)  # exactly one, whole
    assert not any("#" in m["name"] for m in pack.doc["meshes"] if m["name"].split("#")[0] not in TEMPLE_CHUNKS)
    # The mesh indices the level's spawns name (the doves' bird) did not move.
    doves = next(s for s in pack.doc["spawns"] if s["kind"] == "boids")
    assert pack.doc["meshes"][doves["params"]["mesh"]]["name"] == "dove"
    # The report lists the chunks per split mesh.
    report = pack.path.with_suffix(".report.md").read_text()
    assert "## Level chunks" in report
    for mesh, triangles in TEMPLE_CHUNKS.items():
        assert re.search(rf"^\| {mesh} \| {sum(triangles)} \| {len(triangles)} \| ", report, re.M), report
    assert "| chunks | 2 |" in report


def test_the_chunks_together_are_exactly_the_original_mesh(cooks):
    chunked, whole = cooks["chunks"], cooks["whole"]
    for mesh in TEMPLE_CHUNKS:
        original = whole.mesh(mesh)
        [node] = whole.instances(original)
        expected = sorted_rows(triangle_rows(whole, original, node))
        parts = []
        for name in chunk_names(chunked, mesh):
            m = chunked.mesh(name)
            [child] = chunked.instances(m)
            lod = chunked.lod(m)
            # Only the vertices its triangles use.
            assert np.array_equal(np.unique(lod["triangles"]), np.arange(len(lod["vertices"]))), name
            parts.append(triangle_rows(chunked, m, child))
        got = sorted_rows(np.concatenate(parts))
        assert got.shape == expected.shape, (mesh, got.shape, expected.shape)
        assert np.array_equal(got, expected), f"{mesh}: the chunks' triangles are not the mesh's, bit for bit"
        # Every chunk vertex is one of the mesh's vertices, every attribute bit for bit.
        original_vertices = {r.tobytes() for r in whole.lod(original)["vertices"]}
        for name in chunk_names(chunked, mesh):
            assert {r.tobytes() for r in chunked.lod(chunked.mesh(name))["vertices"]} <= original_vertices, name


def test_meshes_that_are_not_split_keep_their_lods(cooks):
    """The other meshes (static props, characters, lanterns, the bird) keep their index and
    their LOD chain, bit for bit: the LOD stage's settings are unchanged for them."""
    chunked, whole = cooks["chunks"], cooks["whole"]
    kept = 0
    for i, m in enumerate(whole.doc["meshes"]):
        if m["name"] in TEMPLE_CHUNKS:
            assert chunked.doc["meshes"][i]["name"] == f"{m['name']}#0"
            continue
        assert chunked.doc["meshes"][i]["name"] == m["name"]
        assert len(chunked.doc["meshes"][i]["lods"]) == len(m["lods"]), m["name"]
        for level in range(len(m["lods"])):
            x, y = chunked.lod(i, level), whole.lod(i, level)
            assert x["vertices"].tobytes() == y["vertices"].tobytes() and np.array_equal(x["triangles"], y["triangles"]), (m["name"], level)
            assert x["error"] == y["error"]
        kept += len(m["lods"]) > 1
    assert kept >= 4  # altar, braziers, fountain, the golems at least have chains


def test_every_lod_of_every_chunk_keeps_its_whole_border(cooks):
    """Chunk LODs are simplified with their open borders locked: each level's open border is LOD
    0's, the same edges between the same positions, bit for bit, with the same lightmap UVs; so
    two neighbours' shared border is the same chain of edges at any pair of LODs, and reads the
    same lightmap texels."""
    pack = cooks["chunks"]
    simplified = 0
    shared_edges = 0
    borders: dict[str, list[set[bytes]]] = {}
    for mesh in TEMPLE_CHUNKS:
        for name in chunk_names(pack, mesh):
            m = pack.mesh(name)
            levels = [pack.lod(m, k) for k in range(len(pack.doc["meshes"][m]["lods"]))]
            base = border_edges(levels[0]["vertices"]["position"], levels[0]["triangles"])
            assert base, f"{name} has no open border"
            lightmap0 = {(r["position"].tobytes(), r["uv1"].tobytes()) for r in levels[0]["vertices"]}
            for k, lod in enumerate(levels[1:], 1):
                simplified += 1
                assert lod["triangles"].shape[0] < levels[0]["triangles"].shape[0]
                assert border_edges(lod["vertices"]["position"], lod["triangles"]) == base, f"{name} LOD {k}: its border moved"
                # Border vertices keep their position and their lightmap UVs.
                on_border = {e[i:i + 12] for e in base for i in (0, 12)}
                kept = {(r["position"].tobytes(), r["uv1"].tobytes()) for r in lod["vertices"] if r["position"].tobytes() in on_border}
                assert kept <= lightmap0, f"{name} LOD {k}: a border vertex's lightmap UV changed"
                assert {p for p, _ in kept} == on_border
            borders[name] = base
    # Neighbours share border edges (so the property above is what keeps them closed).
    names = list(borders)
    for a in range(len(names)):
        for b in range(a + 1, len(names)):
            shared_edges += len(borders[names[a]] & borders[names[b]])
    assert simplified >= 5, f"only {simplified} chunk LODs: the test would prove little"
    assert shared_edges > 100, shared_edges


def test_without_locked_borders_a_chunk_lod_would_open_a_crack():
    """What the lock is for: a courtyard chunk (149 triangles) simplified with the LOD stage's
    plain settings moves its border; with the lock, not an edge of it."""
    from asset_pipeline.csg import build_level
    from asset_pipeline.level import load_level

    scene = build_level(load_level(LEVEL))
    courtyard = next(m for m in scene.meshes if m.name == "courtyard").base
    labels = partition(courtyard.attributes["position"], courtyard.triangles, 8.0, ChunkSettings())
    assert np.bincount(labels).tolist() == TEMPLE_CHUNKS["courtyard"]
    sel = np.flatnonzero(labels == 5)
    used, local = np.unique(courtyard.triangles[sel], return_inverse=True)
    chunk = ir.Lod(attributes={k: np.ascontiguousarray(v[used]) for k, v in courtyard.attributes.items()},
                   triangles=local.reshape(-1, 3).astype(np.uint32), materials=courtyard.materials[sel])
    base = border_edges(chunk.attributes["position"], chunk.triangles)
    plain = build_lods(chunk, LodSettings())
    locked = build_lods(chunk, LodSettings(lock_borders=True))
    assert plain and locked
    assert all(border_edges(l.attributes["position"], l.triangles) != base for l in plain)
    assert all(border_edges(l.attributes["position"], l.triangles) == base for l in locked)


def test_chunks_share_their_nodes_lightmap_and_the_pages_are_those_of_the_whole_mesh(cooks):
    """Every chunk has its mesh's region; a vertex two chunks share has the same lightmap UV and
    block in both, so it reads the same texels of the same (byte-identical) page: no seam."""
    chunked, whole = cooks["chunks"], cooks["whole"]
    # The baked pages: byte-identical, in the pack and beside it.
    for p in range(len(whole.doc["lightmap"]["pages"])):
        exr = f"temple.lightmap{p}.exr"
        assert (chunked.path.parent / exr).read_bytes() == (whole.path.parent / exr).read_bytes(), exr
    assert chunked.doc["lightmap"]["pages"] == whole.doc["lightmap"]["pages"]
    for key in ("textures", "directions"):
        for a, b in zip(chunked.doc["lightmap"][key], whole.doc["lightmap"][key]):
            fa, la = _core.read_pack_texture(chunked.path, a)
            fb, lb = _core.read_pack_texture(whole.path, b)
            assert fa == fb and len(la) == len(lb) == 1 and np.asarray(la[0]).tobytes() == np.asarray(lb[0]).tobytes(), key
    shared = 0
    for mesh in TEMPLE_CHUNKS:
        [node] = [n for n in whole.doc["nodes"] if n["name"] == mesh]
        region = node["lightmap"]
        assert region is not None
        # Per chunk: vertex bytes -> (atlas UV, page) where its lightmap is read.
        seen: dict[bytes, tuple[str, tuple]] = {}
        for name in chunk_names(chunked, mesh):
            m = chunked.mesh(name)
            [child] = [chunked.doc["nodes"][k] for k in chunked.instances(m)]
            assert child["lightmap"] == region, name
            lod = chunked.lod(m)
            v = lod["vertices"]
            # A vertex's lightmap block is its faces' (one chart, one block).
            block = np.full(len(v), -1)
            block[lod["triangles"].ravel()] = np.repeat(lod["blocks"], 3)
            again = np.full(len(v), -1)
            again[lod["triangles"][::-1].ravel()] = np.repeat(lod["blocks"][::-1], 3)
            assert np.array_equal(block, again), f"{name}: a vertex on faces of two lightmap blocks"
            atlas = v["uv1"].astype(np.float64) * region["scale"] + region["offset"]
            for k in range(len(v)):
                where = (atlas[k].tobytes(), int(region["page"] + block[k]))
                key = v[k].tobytes()
                if key in seen and seen[key][0] != name:
                    shared += 1
                    assert seen[key][1] == where, f"{name} and {seen[key][0]} read a shared vertex's lightmap in different places"
                seen.setdefault(key, (name, where))
    assert shared > 200, f"only {shared} vertices shared between chunks"


def test_the_switch_off_gives_the_mesh_whole_and_no_chunk_stage(cooks):
    from asset_pipeline.csg import build_level
    from asset_pipeline.level import load_level

    whole = cooks["whole"]
    scene = build_level(load_level(LEVEL))
    assert [m["name"] for m in whole.doc["meshes"]] == [m.name for m in scene.meshes]
    assert [(n["name"], n["mesh"]) for n in whole.doc["nodes"]] == [(n.name, n.mesh) for n in scene.nodes]
    report = whole.path.with_suffix(".report.md").read_text()
    assert "## Level chunks" not in report and "| chunks |" not in report
    stages = re.findall(r"^\| (\w+) \| \d+ \| \d+ \| [\d.]+ \|$", report, re.M)
    assert stages == ["level", "uv2", "bake", "lod", "mesh_opt", "textures", "compress", "write"], stages
    stages = re.findall(r"^\| (\w+) \| \d+ \| \d+ \| [\d.]+ \|$", cooks["chunks"].path.with_suffix(".report.md").read_text(), re.M)
    assert stages == ["level", "uv2", "bake", "chunks", "lod", "mesh_opt", "textures", "compress", "write"], stages


def test_a_cook_that_splits_nothing_is_the_no_chunks_cook_byte_for_byte(cooks, tmp_path):
    """The chunk stage leaves a scene it does not split as it was, and the bake before the LODs
    bakes what it baked after them: a cook whose chunk settings split nothing is byte-identical
    to --no-chunks (pack and pages)."""
    whole = cooks["whole"]
    out = tmp_path / "temple.pack"
    cache = whole.path.parent / ".cook-cache"  # stage caches shared: only the chunk stage has work of its own
    result = cook_detailed(LEVEL, out, progress=False, settings=_quick(chunk=ChunkSettings(min_mesh_triangles=10**9), cache_dir=cache))
    assert {s.name: s.items for s in result.stages}["chunks"] == 0
    assert out.read_bytes() == whole.path.read_bytes()
    assert out.with_name("temple.lightmap0.exr").read_bytes() == whole.path.with_name("temple.lightmap0.exr").read_bytes()


def test_the_chunk_size_switch_changes_the_split(run_cook, tmp_path):
    counts = {}
    for size in ("8", "16"):
        out = tmp_path / f"temple{size}.pack"
        r = run_cook(LEVEL, "-o", out, "-q", "--no-bake", "--no-lods", "--chunk-size", size)
        assert r.returncode == 0, r.stderr
        counts[size] = sum(len(chunk_names(Pack(out), m)) for m in TEMPLE_CHUNKS)
    assert counts == {"8": 25, "16": 12}, counts


def _quick(**kw) -> CookSettings:
    from asset_pipeline.bake import BakeSettings

    return CookSettings(bake=BakeSettings(preset="draft", samples=1, probe_samples=4, reflection_face=8, reflection_samples=1), **kw)


@pytest.mark.parametrize("args, fragment", [
    (("--chunk-size", "0"), "argument --chunk-size: 0 is not a positive number"),
    (("--chunk-size", "nan"), "argument --chunk-size: nan is not a positive number"),
    (("--chunk-triangles", "0"), "argument --chunk-triangles: 0 is not 1 or more"),
    (("--chunk-triangles", "40"), "max_triangles (--chunk-triangles) 40 is below twice min_triangles (32)"),
    (("--no-chunks", "--chunk-size", "4"), "--chunk-size and --chunk-triangles need level chunks"),
])
def test_bad_chunk_settings_are_one_line_errors(run_cook, tmp_path, args, fragment):
    out = tmp_path / "temple.pack"
    r = run_cook(LEVEL, "-o", out, "-q", "--no-bake", *args)
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    errors = [l for l in r.stderr.splitlines() if l.startswith("cook: error:")]
    assert len(errors) == 1 and fragment in errors[0], r.stderr
    assert all(l.startswith(("usage:", " ", "cook: error:")) for l in r.stderr.splitlines()), r.stderr
    assert not out.exists()


@pytest.mark.parametrize("settings, fragment", [
    (ChunkSettings(size=-1.0), "size (--chunk-size) must be a positive number of metres, got -1.0"),
    (ChunkSettings(size=float("inf")), "size (--chunk-size) must be a positive number of metres, got inf"),
    (ChunkSettings(min_triangles=0), "min_triangles must be a whole number >= 1, got 0"),
    (ChunkSettings(max_triangles=2.5), "max_triangles (--chunk-triangles) must be a whole number >= 1, got 2.5"),
    (ChunkSettings(min_mesh_triangles=-3), "min_mesh_triangles must be a whole number >= 0, got -3"),
])
def test_bad_chunk_settings_through_the_api_are_one_line_cook_errors(tmp_path, settings, fragment):
    out = tmp_path / "temple.pack"
    with pytest.raises(CookError) as e:
        cook_detailed(LEVEL, out, progress=False, settings=CookSettings(chunk=settings, baking=False))
    assert fragment in str(e.value) and "\n" not in str(e.value), str(e.value)
    assert not out.exists()
    # Off, the chunk settings are not read.
    assert cook_detailed(LEVEL, out, progress=False, settings=CookSettings(chunks=False, chunk=settings, baking=False, lods=False)).chunks == {}


# ---- which meshes are split, and how their placements follow ----------------------------------


def grid(cells: int, metres: float) -> ir.Lod:
    """A flat square of cells x cells quads (2 triangles each), `metres` wide, with uv1 and one block."""
    k = np.arange(cells + 1, dtype=np.float32) * np.float32(metres / cells)
    x, z = np.meshgrid(k, k, indexing="xy")
    pos = np.stack([x.ravel(), np.zeros(x.size, np.float32), z.ravel()], 1)
    i = np.arange(cells)
    a = (i[None, :] + (cells + 1) * i[:, None]).ravel()
    tris = np.concatenate([np.stack([a, a + cells + 1, a + 1], 1), np.stack([a + 1, a + cells + 1, a + cells + 2], 1)])
    return ir.Lod(attributes={"position": pos, "uv1": np.ascontiguousarray(pos[:, [0, 2]] * 4)}, triangles=tris.astype(np.uint32),
                  materials=np.zeros(len(tris), np.uint32), lightmap_blocks=np.zeros(len(tris), np.uint32))


def scale(s: float, x: float = 0.0) -> tuple[float, ...]:
    return (s, 0, 0, 0, 0, s, 0, 0, 0, 0, s, 0, x, 0, 0, 1)


def test_a_mesh_placed_twice_splits_once_and_each_placement_gets_every_chunk():
    from asset_pipeline.chunks import split_chunks

    region = lambda p: {"page": 0, "scale": [0.01, 0.01], "offset": [p, 0.0]}
    scene = ir.Scene(name="s", source="s", materials=[ir.Material()], meshes=[ir.Mesh("floor", [grid(32, 16.0)]), ir.Mesh("small", [grid(8, 4.0)])],
                     nodes=[ir.Node("group"), ir.Node("a", parent=0, local=scale(1.0), mesh=0, static=True, lightmap=region(0.0)),
                            ir.Node("b", local=scale(2.0, 50.0), mesh=0, static=True, lightmap=region(0.5)),
                            ir.Node("prop", mesh=1, static=True)])
    out, stats = split_chunks(scene, ChunkSettings(min_mesh_triangles=100))
    out.validate()
    [m] = stats["meshes"]
    # 16 m of floor at twice its size: 32 m in the world, so cut in 4 x 4 cells of 8 m (4 m of its own).
    assert (m["mesh"], m["nodes"], m["chunks"]) == ("floor", ["a", "b"], 16)
    assert m["chunk_triangles"] == [128] * 16 and len(out.meshes) == 2 + 15
    assert [x.name for x in out.meshes[:2]] == ["floor#0", "small"]
    assert stats["chunk_meshes"] == [0, *range(2, 17)]
    world = out.world_matrices()
    for k, name in ((1, "a"), (2, "b")):
        assert out.nodes[k].name == name and out.nodes[k].mesh is None and out.nodes[k].lightmap is None
        children = [j for j, n in enumerate(out.nodes) if n.parent == k]
        assert [out.nodes[j].name for j in children] == [f"{name}#{c}" for c in range(16)]
        assert [out.nodes[j].mesh for j in children] == stats["chunk_meshes"]
        assert all(out.nodes[j].lightmap == scene.nodes[k].lightmap and out.nodes[j].static for j in children)
        assert all(np.array_equal(world[j], world[k]) for j in children)
    # The pieces are the floor: the same triangles (as vertex rows), uv1 and blocks kept.
    whole = grid(32, 16.0)
    corners = lambda lod: {np.concatenate([lod.attributes["position"], lod.attributes["uv1"]], 1)[t].tobytes() for t in lod.triangles}
    assert set().union(*(corners(x.base) for x in out.meshes if x.name.startswith("floor#"))) == corners(whole)
    assert out.meshes[1] is scene.meshes[1] and out.nodes[3] == scene.nodes[3]


def test_meshes_that_move_morph_are_small_or_a_flock_draws_stay_whole():
    from asset_pipeline.chunks import split_chunks

    base = ir.Scene(name="s", source="s", materials=[ir.Material()], meshes=[ir.Mesh("floor", [grid(32, 16.0)])])
    cases = {
        "one placement moves": dict(nodes=[ir.Node("a", mesh=0, static=True), ir.Node("b", mesh=0, static=False)]),
        "a flock's bird": dict(nodes=[ir.Node("a", mesh=0, static=True)], spawns=[ir.Spawn("birds", "boids", params={"mesh": 0})]),
        "placed nowhere": dict(nodes=[]),
        "too few triangles": dict(nodes=[ir.Node("a", mesh=0, static=True)]),  # 2048, below min_mesh_triangles=4096 here
        "morph targets": dict(nodes=[ir.Node("a", mesh=0, static=True)],
                              meshes=[ir.Mesh("floor", [dataclasses.replace(base.meshes[0].base, morph_positions=np.zeros((1, 33 * 33, 3), np.float32))])]),
    }
    for what, kw in cases.items():
        scene = dataclasses.replace(base, **kw)
        settings = ChunkSettings(min_mesh_triangles=4096 if what == "too few triangles" else 100)
        out, stats = split_chunks(scene, settings)
        assert stats["meshes"] == [] and out.meshes == scene.meshes and out.nodes == scene.nodes, what
    # Within the size it stays whole too; above it, it is cut.
    scene = dataclasses.replace(base, nodes=[ir.Node("a", mesh=0, static=True)])
    assert split_chunks(scene, ChunkSettings(size=16.5, min_mesh_triangles=100))[1]["meshes"] == []
    assert split_chunks(scene, ChunkSettings(size=15.5, min_mesh_triangles=100))[1]["meshes"][0]["chunks"] == 4
