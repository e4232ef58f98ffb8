"""Lightmap UVs (asset_pipeline.uv2): overlap-free, padded, at the requested density.

Meshes are generated here (boxes, a cylinder, a plane with a hole, a scaled mesh); the demo level
is used when the level loader and CSG modules exist. Coverage is checked twice: by the Rust
rasteriser the stage itself uses, and by an independent numpy test of texel centres against
triangles, with the padding rule checked by dilating each chart.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from asset_pipeline import _core, ir, uv2
from asset_pipeline._core import CookError
import meshes



# ---- generated meshes ---------------------------------------------------------------------------


def make_lod(pos, tris, normals=None, material=0) -> ir.Lod:
    pos = np.asarray(pos, np.float32)
    attrs = {"position": pos}
    if normals is not None:
        attrs["normal"] = np.asarray(normals, np.float32)
    # A colour per vertex to check every attribute is carried, not only positions.
    attrs["color"] = (np.arange(len(pos) * 4, dtype=np.uint32).reshape(-1, 4) % 251).astype(np.uint8)
    attrs["uv0"] = pos[:, :2] * 0.5
    tris = np.asarray(tris, np.uint32).reshape(-1, 3)
    mats = (np.arange(len(tris)) % 3 + material).astype(np.uint32)
    lod = ir.Lod(attributes=attrs, triangles=tris, materials=mats)
    lod.validate("generated")
    return lod


def box(size, centre=(0, 0, 0)) -> ir.Lod:
    """A box with a separate set of 4 vertices per face (hard edges), as CSG output has."""
    sx, sy, sz = (s / 2 for s in size)
    cx, cy, cz = centre
    pos, nrm, tris = [], [], []
    for axis in range(3):
        for sign in (-1, 1):
            n = np.zeros(3)
            n[axis] = sign
            u = np.zeros(3)
            u[(axis + 1) % 3] = 1
            v = np.cross(n, u)
            half = np.array([sx, sy, sz])
            base = len(pos)
            for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                pos.append(np.array([cx, cy, cz]) + n * half + u * half * a + v * half * b)
                nrm.append(n)
            tris += [[base, base + 1, base + 2], [base, base + 2, base + 3]]
    return make_lod(pos, tris, nrm)


def cylinder(radius, height, segments=24) -> ir.Lod:
    pos, nrm, tris = meshes.cylinder(radius, height, segments)
    return make_lod(pos, tris, nrm)


def plane_with_hole(size=6.0, cells=6) -> ir.Lod:
    step = size / cells
    pos = [[x * step, 0, z * step] for z in range(cells + 1) for x in range(cells + 1)]
    tris = []
    hole = {(cells // 2 - 1, cells // 2 - 1), (cells // 2, cells // 2 - 1), (cells // 2 - 1, cells // 2), (cells // 2, cells // 2)}
    for z in range(cells):
        for x in range(cells):
            if (x, z) in hole:
                continue
            a = z * (cells + 1) + x
            tris += [[a, a + cells + 1, a + 1], [a + 1, a + cells + 1, a + cells + 2]]
    return make_lod(pos, tris, [[0, 1, 0]] * len(pos))


def generated_meshes():
    """(lod, world_scale, texels_per_metre override, name)"""
    return [
        (box((1, 2, 3)), 1.0, None, "box 1x2x3"),
        (box((4, 0.5, 0.5), (5, 0, 0)), 1.0, None, "beam"),
        (box((0.3, 0.3, 0.3)), 1.0, None, "small box"),
        (cylinder(0.8, 2.5), 1.0, None, "cylinder"),
        (plane_with_hole(), 1.0, None, "plane with hole"),
        (box((1, 1, 1)), 2.5, None, "scaled box"),  # a 2.5 m cube in the world
        (box((1, 1, 2)), 1.0, 20.0, "dense box"),  # per-object density override
    ]


SETTINGS = uv2.Uv2Settings(texels_per_metre=10.0)


def placed(r: uv2.Uv2Result):
    """(instances' Lods on the atlas, layout, stats): what the page checks read."""
    return r.placed, r.layout, r.stats


@pytest.fixture(scope="module")
def generated():
    meshes = generated_meshes()
    lods, layout, stats = placed(uv2.lightmap_uvs([m[:3] for m in meshes], SETTINGS, names=[m[3] for m in meshes]))
    return meshes, lods, layout, stats


# ---- independent checks in numpy ------------------------------------------------------------------


def centre_coverage(lods, layout, page):
    """Per chart, the texels whose centre lies inside one of its triangles (closed test with a
    tiny tolerance, so it is stricter than any fill rule): (h, w) int chart map with -1 empty
    and -2 where two charts claim the texel."""
    w, h = layout.pages[page]
    m = uv2.page_mesh(lods, page)
    out = np.full((h, w), -1, np.int64)
    uv = m["uv"].astype(np.float64) * [w, h]
    for t, chart in zip(m["triangles"], m["chart"]):
        a, b, c = uv[t]
        lo = np.floor(np.minimum(np.minimum(a, b), c) - 0.5).astype(int)
        hi = np.ceil(np.maximum(np.maximum(a, b), c) + 0.5).astype(int)
        xs = np.arange(max(lo[0], 0), min(hi[0], w))
        ys = np.arange(max(lo[1], 0), min(hi[1], h))
        if len(xs) == 0 or len(ys) == 0:
            continue
        X, Y = np.meshgrid(xs + 0.5, ys + 0.5)
        d = (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1])
        if abs(d) < 1e-12:
            continue
        l1 = ((X - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (Y - a[1])) / d
        l2 = ((b[0] - a[0]) * (Y - a[1]) - (X - a[0]) * (b[1] - a[1])) / d
        inside = (l1 >= -1e-9) & (l2 >= -1e-9) & (1 - l1 - l2 >= -1e-9)
        sub = out[np.ix_(ys, xs)]
        other = inside & (sub >= 0) & (sub != chart) | inside & (sub == -2)
        sub[inside & (sub == -1)] = chart
        sub[other] = -2
        out[np.ix_(ys, xs)] = sub
    return out


def padding_violations(chart_map: np.ndarray, charts_here: np.ndarray, padding: int) -> int:
    """Dilate every chart by `padding` texels (a square) and count other charts' texels inside."""
    bad = int((charts_here > 1).sum())
    h, w = chart_map.shape
    for c in np.unique(chart_map[charts_here == 1]):
        mask = (chart_map == c) & (charts_here == 1)
        grown = np.zeros_like(mask)
        padded = np.pad(mask, padding)
        for dy in range(2 * padding + 1):
            for dx in range(2 * padding + 1):
                grown |= padded[dy:dy + h, dx:dx + w]
        bad += int((grown & (charts_here > 0) & ~mask).sum())
    return bad


def check_layout(lods, layout, min_padding):
    for p in range(len(layout.pages)):
        centre = centre_coverage(lods, layout, p)
        assert (centre == -2).sum() == 0, f"page {p}: texel centres claimed by two charts"
        r = uv2.rasterize_page(lods, layout, p, conservative=True, surface=False)
        assert padding_violations(r["chart"], r["charts_here"], min_padding) == 0, f"page {p}: padding of {min_padding} texels broken"
        # The rasteriser's centre coverage is the numpy one without the centres exactly on a
        # chart's outline (its fill rule takes those only on some edges; xatlas puts chart
        # outlines through texel centres), with the same chart at every texel.
        rc = uv2.rasterize_page(lods, layout, p, conservative=False, surface=False)
        claimed = rc["charts_here"] > 0
        assert (centre[claimed] >= 0).all()
        assert (centre[claimed] == rc["chart"][claimed]).all()
        # Every texel whose centre a chart covers is also baked (conservative coverage).
        assert ((rc["charts_here"] > 0) <= (r["charts_here"] > 0)).all()


# ---- the tests -----------------------------------------------------------------------------------


def test_generated_meshes_have_no_overlap_and_keep_padding(generated):
    meshes, lods, layout, stats = generated
    assert layout.padding == SETTINGS.padding >= 2
    assert stats["overlapping_texels"] == 0 and stats["texels_within_padding"] == 0
    assert stats["min_chart_gap_texels"] >= SETTINGS.padding
    check_layout(lods, layout, SETTINGS.padding)
    for lod in lods:
        uv = lod.attributes["uv1"]
        assert uv.dtype == np.float32 and (uv >= 0).all() and (uv <= 1).all()
        assert lod.lightmap_blocks is not None and int(lod.lightmap_blocks.max()) < len(layout.pages)
    for w, h in layout.pages:
        assert w % 4 == 0 and h % 4 == 0 and 0 < w <= SETTINGS.max_page_size and 0 < h <= SETTINGS.max_page_size
    assert len(set(layout.pages)) == 1, "pages share one size (the runtime's array texture)"


def test_density_within_ten_percent_per_mesh_with_scale_and_override(generated):
    meshes, lods, layout, stats = generated
    assert abs(stats["density_ratio"] - 1) < 0.1
    for (lod_in, scale, tpm, name), lod, m in zip(meshes, lods, stats["instances"]):
        want = tpm or SETTINGS.texels_per_metre
        d, w = uv2.triangle_densities(lod, scale, layout.pages)
        measured = float((d * w).sum() / w.sum())
        assert abs(measured / want - 1) < 0.1, f"{name}: {measured} texels/m for {want}"
        assert m["name"] == name and m["density_ratio"] == pytest.approx(measured / want, abs=1e-3)
    # The scaled box is a 2.5 m cube: its faces are ~25 texels across, not 10.
    scaled = lods[5]
    extent = np.ptp(scaled.attributes["uv1"][scaled.triangles[:2].ravel()], axis=0) * layout.pages[int(scaled.lightmap_blocks[0])]
    assert 24 <= max(extent) <= 27, extent


def test_attributes_and_triangles_are_carried(generated):
    meshes, lods, layout, stats = generated
    for (lod_in, *_), lod in zip(meshes, lods):
        assert lod.triangle_count == lod_in.triangle_count
        np.testing.assert_array_equal(lod.materials, lod_in.materials)
        assert set(lod.attributes) == set(lod_in.attributes) | {"uv1"}
        for name, a in lod_in.attributes.items():
            # Triangle t's corners carry the attributes of the input triangle t's corners.
            np.testing.assert_array_equal(lod.attributes[name][lod.triangles], a[lod_in.triangles], err_msg=name)
        # Vertices are split at chart seams; only unreferenced ones disappear.
        assert lod.vertex_count >= len(np.unique(lod_in.triangles))
        lod.validate("out")


def test_charts_recovered_from_uv_topology_match_xatlas(generated):
    meshes, lods, layout, stats = generated
    total = 0
    for p in range(len(layout.pages)):
        total += len(np.unique(uv2.page_mesh(lods, p)["chart"]))
    assert total == stats["charts"]


def test_multiple_pages_when_the_level_exceeds_the_max_page_size():
    meshes = generated_meshes()
    small = dataclasses.replace(SETTINGS, max_page_size=64)
    lods, layout, stats = placed(uv2.lightmap_uvs([m[:3] for m in meshes], small))
    assert len(layout.pages) > 1 and stats["pages"] == len(layout.pages)
    assert all(w <= 64 and h <= 64 for w, h in layout.pages)
    assert set(np.concatenate([l.lightmap_blocks for l in lods])) == set(range(len(layout.pages)))
    assert stats["overlapping_texels"] == 0 and stats["texels_within_padding"] == 0
    check_layout(lods, layout, small.padding)
    assert abs(stats["density_ratio"] - 1) < 0.1


def test_a_big_level_packs_in_groups_of_a_page_each_in_parallel_and_keeps_the_rules(monkeypatch):
    # Groups are for levels of thousands of charts (one brute-force packing of all of them
    # scans every full page for every chart); here a small level is made to use them.
    monkeypatch.setattr(uv2, "_GROUP_MIN_CHARTS", 0)
    monkeypatch.setattr(uv2, "_GROUP_FILL", 0.3)
    meshes = generated_meshes()
    small = dataclasses.replace(SETTINGS, max_page_size=128)
    entries = [m[:3] for m in meshes]
    one = uv2.lightmap_uvs(entries, dataclasses.replace(small, workers=1))
    lods, layout, stats = placed(one)
    assert len(layout.pages) >= 3, layout.pages  # several groups, a page or more each
    assert set(np.concatenate([l.lightmap_blocks for l in lods])) == set(range(len(layout.pages)))
    assert stats["overlapping_texels"] == 0 and stats["texels_within_padding"] == 0
    check_layout(lods, layout, small.padding)
    assert abs(stats["density_ratio"] - 1) < 0.1
    # The same layout from worker processes.
    par = uv2.lightmap_uvs(entries, dataclasses.replace(small, workers=2))
    assert par.layout == one.layout and par.regions == one.regions
    for x, y in zip(one.lods, par.lods):
        np.testing.assert_array_equal(x.attributes["uv1"], y.attributes["uv1"])
        np.testing.assert_array_equal(x.lightmap_blocks, y.lightmap_blocks)


def test_deterministic_and_parallel_charting_gives_the_same_result():
    meshes = [m[:3] for m in generated_meshes()]
    a = uv2.lightmap_uvs(meshes, SETTINGS)
    b = uv2.lightmap_uvs(meshes, SETTINGS)
    par = uv2.lightmap_uvs(meshes, dataclasses.replace(SETTINGS, workers=2, parallel_min_triangles=0))
    for other in (b, par):
        assert other.layout == a.layout and other.stats == a.stats and other.regions == a.regions
        for x, y in zip(a.lods, other.lods):
            for k in x.attributes:
                np.testing.assert_array_equal(x.attributes[k], y.attributes[k])
            np.testing.assert_array_equal(x.triangles, y.triangles)
            np.testing.assert_array_equal(x.lightmap_blocks, y.lightmap_blocks)


class DictCache:
    """The StageCache interface (load/store), in memory."""

    def __init__(self):
        self.entries, self.loads, self.hits = {}, 0, 0

    def load(self, stage, key):
        self.loads += 1
        hit = self.entries.get((stage, key))
        self.hits += hit is not None
        return hit

    def store(self, stage, key, meta, arrays):
        self.entries[(stage, key)] = (meta, [np.array(a) for a in arrays])


def test_charts_are_cached_per_mesh():
    meshes = [m[:3] for m in generated_meshes()]
    cache = DictCache()
    first = uv2.lightmap_uvs(meshes, SETTINGS, cache=cache)
    assert len(cache.entries) == len(meshes) and cache.hits == 0
    # Change one mesh: only it is charted again; the result equals an uncached run.
    changed = list(meshes)
    changed[0] = (box((1, 2, 3.5)), 1.0, None)
    second = uv2.lightmap_uvs(changed, SETTINGS, cache=cache)
    assert cache.hits == len(meshes) - 1 and len(cache.entries) == len(meshes) + 1
    fresh = uv2.lightmap_uvs(changed, SETTINGS)
    assert fresh.layout == second.layout and fresh.stats == second.stats
    np.testing.assert_array_equal(fresh.lods[3].attributes["uv1"], second.lods[3].attributes["uv1"])
    assert first.layout != second.layout or first.stats != second.stats


def test_surface_samples_lie_on_their_triangles(generated):
    meshes, lods, layout, stats = generated
    lod_index = 0  # box 1x2x3, centred at the origin
    page = int(lods[lod_index].lightmap_blocks[0])
    r = uv2.rasterize_page(lods, layout, page, conservative=True)
    covered = r["triangle"] != _core.UV_NONE
    mine = covered.copy()
    mine[covered] = r["mesh"][r["triangle"][covered]] == lod_index
    pos, nrm = r["position"][mine], r["normal"][mine]
    assert len(pos) > 100
    # Every sample is on the box's surface and its normal is the face's.
    half = np.array([0.5, 1.0, 1.5])
    on_face = np.isclose(np.abs(pos), half, atol=1e-4)
    assert on_face.any(axis=1).all()
    assert np.allclose(np.linalg.norm(nrm, axis=1), 1, atol=1e-5)
    axis = np.abs(nrm).argmax(axis=1)
    assert np.allclose(np.abs(pos[np.arange(len(pos)), axis]), half[axis], atol=1e-4)
    assert (np.abs(pos) <= half + 1e-4).all()
    # Texels the chart only touches (centre outside) are baked too: more texels than centres.
    rc = uv2.rasterize_page(lods, layout, page, conservative=False, surface=False)
    centre_mine = (rc["triangle"] != _core.UV_NONE)
    centre_mine[centre_mine] = rc["mesh"][rc["triangle"][centre_mine]] == lod_index
    assert mine.sum() > centre_mine.sum()


# ---- several placements of one mesh -------------------------------------------------------------


def test_every_placement_of_a_mesh_gets_its_own_texels_scaled_by_its_world_scale():
    """One box placed three times (twice at scale 1, once at 2.5) and a beam placed once: one set
    of box vertices, three regions of their own, the large one 2.5 times as wide."""
    lods = [box((1, 1, 1)), box((4, 0.5, 0.5), (5, 0, 0))]
    instances = [uv2.Instance(0, 1.0), uv2.Instance(1, 1.0), uv2.Instance(0, 1.0), uv2.Instance(0, 2.5)]
    r = uv2.lightmap_uvs(lods, SETTINGS, instances=instances, names=["box", "beam"], instance_names=["a", "beam", "b", "big"])
    assert len(r.lods) == 2 and len(r.regions) == 4
    assert r.lods[0].vertex_count < 2 * 24, "the box's vertices are not copied per placement"
    box_regions = [r.regions[k] for k in (0, 2, 3)]
    assert len({(g["page"], *g["offset"]) for g in box_regions}) == 3, "each placement has texels of its own"
    a, b, big = box_regions
    assert a["scale"] == b["scale"]
    np.testing.assert_allclose(np.divide(big["scale"], a["scale"]), 2.5, rtol=1e-6)
    assert r.stats["overlapping_texels"] == 0 and r.stats["texels_within_padding"] == 0
    check_layout(r.placed, r.layout, SETTINGS.padding)
    for inst, m in zip(instances, r.stats["instances"]):
        assert abs(m["density_ratio"] - 1) < 0.1, m
        assert m["texels"] > 0
    # The 2.5 m cube bakes about 2.5^2 times the texels of a 1 m one.
    texels = [m["texels"] for m in r.stats["instances"]]
    assert 2.5 ** 2 * 0.8 < texels[3] / texels[0] < 2.5 ** 2 * 1.2, texels


def row_of_boxes(count: int) -> ir.Lod:
    """`count` unit boxes in a row, as one mesh."""
    parts = [box((1, 1, 1), (2 * i, 0, 0)) for i in range(count)]
    pos = np.concatenate([p.attributes["position"] for p in parts])
    nrm = np.concatenate([p.attributes["normal"] for p in parts])
    tris = np.concatenate([p.triangles + 24 * i for i, p in enumerate(parts)])
    return make_lod(pos, tris, nrm)


def test_a_mesh_of_several_blocks_placed_twice_takes_whole_pages_each():
    small = dataclasses.replace(SETTINGS, max_page_size=64)
    r = uv2.lightmap_uvs([row_of_boxes(12), box((1, 1, 1))], small, instances=[uv2.Instance(0), uv2.Instance(0), uv2.Instance(1)])
    blocks = int(r.lods[0].lightmap_blocks.max()) + 1
    assert blocks > 1
    first, second = r.regions[0], r.regions[1]
    assert first["offset"] == second["offset"] == [0.0, 0.0] and abs(first["page"] - second["page"]) >= blocks
    assert len(r.layout.pages) >= 2 * blocks
    assert r.stats["overlapping_texels"] == 0 and r.stats["texels_within_padding"] == 0
    check_layout(r.placed, r.layout, small.padding)


def test_a_placement_too_large_for_a_page_gets_a_lower_density_and_a_warning():
    lods = [box((1, 1, 1))]
    small = dataclasses.replace(SETTINGS, max_page_size=64)
    r = uv2.lightmap_uvs(lods, small, instances=[uv2.Instance(0, 1.0), uv2.Instance(0, 20.0)], instance_names=["small", "huge"])
    assert len(r.stats["warnings"]) == 1 and r.stats["warnings"][0].startswith("huge: lightmap density lowered from 10 to ")
    assert r.stats["overlapping_texels"] == 0 and r.stats["texels_within_padding"] == 0
    check_layout(r.placed, r.layout, small.padding)


def test_a_triangle_larger_than_a_page_is_a_clear_error():
    floor = make_lod([[0, 0, 0], [50, 0, 0], [50, 0, 50], [0, 0, 50]], [[0, 2, 1], [0, 3, 2]])
    with pytest.raises(CookError, match="floor.*does not fit a 256-texel page"):
        uv2.lightmap_uvs([(floor, 1.0)], uv2.Uv2Settings(texels_per_metre=16, max_page_size=256), names=["floor"])


def test_bad_settings_and_inputs_are_errors():
    for bad in (dict(padding=0), dict(max_page_size=1000 + 2), dict(texels_per_metre=0), dict(texels_per_metre=float("nan"))):
        with pytest.raises(CookError):
            uv2.lightmap_uvs([(box((1, 1, 1)), 1.0)], uv2.Uv2Settings(**bad))
    with pytest.raises(CookError, match="world scale"):
        uv2.lightmap_uvs([(box((1, 1, 1)), 0.0)])
    r = uv2.lightmap_uvs([])
    assert r.lods == [] and r.regions == [] and r.layout.pages == []


def test_degenerate_triangles_are_carried_without_breaking_the_layout():
    b = box((1, 1, 1))
    pos = np.vstack([b.attributes["position"], [[0, 0, 0], [0, 0, 0], [1, 0, 0]]]).astype(np.float32)
    lod = make_lod(pos, np.vstack([b.triangles, [[24, 25, 26]]]), None)
    (out,), layout, stats = placed(uv2.lightmap_uvs([(lod, 1.0)], SETTINGS))
    assert out.triangle_count == 13 and stats["overlapping_texels"] == 0
    np.testing.assert_array_equal(out.attributes["position"][out.triangles], lod.attributes["position"][lod.triangles])
    assert np.isfinite(out.attributes["uv1"]).all()


def test_previews_are_written(generated, tmp_path):
    from PIL import Image

    meshes = generated_meshes()
    r = uv2.lightmap_uvs([m[:3] for m in meshes], SETTINGS)
    layout = r.layout
    scene = ir.Scene(name="t", source="generated", meshes=[ir.Mesh(name=m[3], lods=[l]) for m, l in zip(meshes, r.lods)],
                     nodes=[ir.Node(m[3], mesh=i, static=True, lightmap=reg) for i, (m, reg) in enumerate(zip(meshes, r.regions))],
                     materials=[ir.Material()] * 3, lightmap=layout)
    paths = uv2.write_previews(scene, tmp_path / "previews")
    assert [p.name for p in paths] == [f"uv2_page{i}.png" for i in range(len(layout.pages))]
    for p, (w, h) in zip(paths, layout.pages):
        img = np.asarray(Image.open(p).convert("RGBA"))
        k = img.shape[1] // w
        assert img.shape == (h * k, w * k, 4) and max(img.shape[:2]) >= 512
        # No red (overlap) or magenta (padding) texels.
        rgb = img[..., :3].reshape(-1, 3)
        assert not ((rgb == [255, 0, 0]).all(1) | (rgb == [255, 0, 255]).all(1)).any()
    assert sorted(x.name for x in (tmp_path / "previews").iterdir()) == [p.name for p in paths]


def test_png_encoding_is_atomic_and_reports_the_file(tmp_path):
    img = np.zeros((3, 5, 4), np.uint8)
    img[..., 0] = np.arange(5)
    _core.encode_png(tmp_path / "a.png", img)
    from PIL import Image

    np.testing.assert_array_equal(np.asarray(Image.open(tmp_path / "a.png")), img)
    with pytest.raises(CookError, match="missing"):
        _core.encode_png(tmp_path / "missing" / "b.png", img)
    assert [p.name for p in tmp_path.iterdir()] == ["a.png"]


# ---- the demo level ------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def demo(demo_level_uv2):
    return demo_level_uv2


def test_demo_level_meets_the_acceptance_numbers(demo):
    static, lods, layout, stats, settings = demo
    assert stats["overlapping_texels"] == 0
    assert stats["texels_within_padding"] == 0 and stats["min_chart_gap_texels"] >= settings.padding
    assert stats["utilisation"] >= 0.6, stats["page_utilisation"]
    assert abs(stats["density_ratio"] - 1) < 0.1
    for m in stats["instances"]:
        assert abs(m["density_ratio"] - 1) < 0.1, m
    for w, h in layout.pages:
        assert max(w, h) <= settings.max_page_size
    total = sum(len(np.unique(uv2.page_mesh(lods, p)["chart"])) for p in range(len(layout.pages)))
    assert total == stats["charts"]


def test_demo_level_independent_overlap_check(demo):
    static, lods, layout, stats, settings = demo
    for p in range(len(layout.pages)):
        centre = centre_coverage(lods, layout, p)
        assert (centre == -2).sum() == 0
        assert (centre >= 0).sum() / (layout.pages[p][0] * layout.pages[p][1]) == pytest.approx(stats["page_utilisation"][p], abs=0.01)


def test_demo_level_over_several_pages(demo):
    static, lods_one, layout_one, stats_one, settings = demo
    small = dataclasses.replace(settings, max_page_size=512)
    lods, layout, stats = placed(uv2.lightmap_uvs([(m.base, 1.0, m.texels_per_metre) for m in static], small))
    assert len(layout.pages) > 1
    assert stats["overlapping_texels"] == 0 and stats["texels_within_padding"] == 0
    assert stats["utilisation"] >= 0.6 and abs(stats["density_ratio"] - 1) < 0.1
