"""Lightmap page clean-up (asset_pipeline.lightmap_post): dilation, seam stitching, denoising, EXR.

Dilation and bilinear reads are checked on the demo level's real UV2 layout: every chart is filled
with its own constant, and bilinear lookups just inside every chart boundary edge must read exactly
that constant (no black gutter, no other chart). Seams are checked on an xatlas-charted cylinder.
The EXR file is checked by OpenEXR's own tools (exrheader, Debian package `openexr`) and the
`OpenEXR` Python package when present.
"""

from __future__ import annotations

import math
import shutil
import subprocess
import sys

import numpy as np
import pytest

from asset_pipeline import _core, ir, uv2
from asset_pipeline import lightmap_post as lp
import meshes

NONE = lp.NONE


def chebyshev_grow(mask: np.ndarray, n: int) -> np.ndarray:
    h, w = mask.shape
    p = np.pad(mask, n)
    out = np.zeros_like(mask)
    for dy in range(-n, n + 1):
        for dx in range(-n, n + 1):
            out |= p[n + dy:n + dy + h, n + dx:n + dx + w]
    return out


def chart_values(ids: np.ndarray) -> np.ndarray:
    """A distinct positive HDR colour per chart id."""
    ids = ids.astype(np.float64)
    return np.stack([1.0 + (ids % 13) * 0.5, 2.0 + (ids % 7) * 3.0, 0.25 + (ids % 5)], axis=-1).astype(np.float32)


def fill_by_chart(chart: np.ndarray) -> np.ndarray:
    img = np.zeros(chart.shape + (3,), np.float32)
    cov = chart != NONE
    img[cov] = chart_values(chart[cov])
    return img


def boundary_points(m: dict, width: int, height: int, inset: float = 0.02):
    """Points (texel units) along every chart boundary edge of a page mesh, moved `inset` texels
    towards the triangle's centroid, and the chart of each."""
    uv = m["uv"].astype(np.float64) * np.array([width, height])
    tris = m["triangles"].astype(np.int64)
    edges = {}
    for t, (tri, c) in enumerate(zip(tris, m["chart"])):
        for k in range(3):
            a, b = int(tri[k]), int(tri[(k + 1) % 3])
            key = (int(c), min(a, b), max(a, b))
            edges.setdefault(key, []).append(t)
    pts, charts = [], []
    for (c, a, b), ts in edges.items():
        if len(ts) != 1:
            continue  # interior edge of the chart
        tri = tris[ts[0]]
        centroid = uv[tri].mean(axis=0)
        pa, pb = uv[a], uv[b]
        n = max(2, int(math.ceil(np.linalg.norm(pb - pa) * 3)) + 1)
        for t in np.linspace(0, 1, n):
            p = pa + (pb - pa) * t
            d = centroid - p
            pts.append(p + d / max(np.linalg.norm(d), 1e-9) * inset)
            charts.append(c)
    return np.array(pts, np.float64), np.array(charts, np.uint32)


# ---- dilation -------------------------------------------------------------------------------------


def test_dilation_rings_on_a_small_page():
    chart = np.full((20, 24), NONE, np.uint32)
    chart[3:8, 3:9] = 4
    chart[5:12, 12:15] = 2  # 3 empty texels from chart 4: rings of 2 meet
    chart[16, 20] = 9
    img = fill_by_chart(chart)
    out, ch = lp.dilate(img, chart, 2)
    cov = chart != NONE
    filled = (ch != NONE) & ~cov
    np.testing.assert_array_equal(filled, chebyshev_grow(cov, 2) & ~cov)
    np.testing.assert_array_equal(out[cov], img[cov])
    np.testing.assert_array_equal(out[filled], chart_values(ch[filled]))  # exactly one chart's value
    assert (out[ch == NONE] == 0).all()
    # Inputs untouched.
    assert (img[~cov] == 0).all()


def test_dilation_bad_input_is_an_error():
    with pytest.raises(ValueError, match="chart map"):
        lp.dilate(np.zeros((4, 4, 3), np.float32), np.zeros((4, 5), np.uint32), 1)
    with pytest.raises(ValueError, match=r"\(h, w, 3\)"):
        lp.dilate(np.zeros((4, 4), np.float32), np.zeros((4, 4), np.uint32), 1)


@pytest.fixture(scope="module")
def demo(demo_level_uv2):
    _, lods, layout, _, _ = demo_level_uv2
    return lods, layout


def test_demo_level_dilation_and_bilinear_reads_at_chart_edges(demo):
    lods, layout = demo
    rings = lp.LightmapPostSettings().dilate_rings
    for page, (w, h) in enumerate(layout.pages):
        chart = uv2.rasterize_page(lods, layout, page, surface=False)["chart"]
        cov = chart != NONE
        img = fill_by_chart(chart)
        out, ch = lp.dilate(img, chart, rings)
        # Exactly the N-texel ring around the charts is filled, each texel from one chart.
        filled = (ch != NONE) & ~cov
        np.testing.assert_array_equal(filled, chebyshev_grow(cov, rings) & ~cov)
        np.testing.assert_array_equal(out[filled], chart_values(ch[filled]))
        np.testing.assert_array_equal(out[cov], img[cov])
        # Bilinear lookups just inside every chart boundary edge read that chart's value only.
        pts, pchart = boundary_points(uv2.page_mesh(lods, page), w, h)
        assert len(pts) > 1000
        expect = chart_values(pchart).astype(np.float64)
        before = _core.sample_bilinear(img, pts)
        # Undilated, black gutter texels bleed into a good share of them (the test can fail).
        assert (before < expect - 1e-3).any(axis=1).mean() > 0.05
        after = _core.sample_bilinear(out, pts)
        bad = ~np.isclose(after, expect, rtol=1e-5, atol=1e-5).all(axis=1)
        assert not bad.any(), f"page {page}: {bad.sum()} of {len(pts)} edge samples read another chart or the gutter, e.g. {pts[bad][:3]}"


# ---- seams ------------------------------------------------------------------------------------------


def cylinder_side(radius=1.0, height=2.0, segments=24) -> ir.Lod:
    pos, nrm, tris = meshes.cylinder(radius, height, segments, caps=False)
    attrs = {"position": np.array(pos, np.float32), "normal": np.array(nrm, np.float32)}
    t = np.array(tris, np.uint32)
    return ir.Lod(attributes=attrs, triangles=t, materials=np.zeros(len(t), np.uint32))


@pytest.fixture(scope="module")
def cylinder_page():
    settings = uv2.Uv2Settings(texels_per_metre=12.0)
    placed = uv2.lightmap_uvs([(cylinder_side(), 1.0)], settings)
    (lod,), layout = placed.placed, placed.layout  # the one instance's Lod on the atlas
    assert len(layout.pages) == 1
    r = uv2.rasterize_page([lod], layout, 0, surface=True)
    return lod, layout, r


def test_seams_are_found_on_a_charted_cylinder(cylinder_page):
    lod, layout, r = cylinder_page
    seams = lp.page_seams([lod], layout, 0)
    assert seams.shape[1:] == (2, 2, 2) and len(seams) >= 2  # the wrap seam is 2 texels tall+: >= 2 edges
    w, h = layout.pages[0]
    # Each seam's two sides are the same 3D edge at different UVs.
    assert (np.abs(seams[:, 0] - seams[:, 1]).max(axis=(1, 2)) > 1e-3).all()
    assert (seams >= 0).all() and (seams[..., 0] <= w).all() and (seams[..., 1] <= h).all()


def test_stitching_closes_seams(cylinder_page):
    lod, layout, r = cylinder_page
    seams = lp.page_seams([lod], layout, 0)
    chart = r["chart"]
    cov = chart != NONE
    # A smooth light field over the surface, plus a per-chart offset: every seam is a step.
    pos = r["position"]
    img = np.zeros(chart.shape + (3,), np.float32)
    field = 1.0 + 0.3 * pos[..., 1:2] + 0.2 * pos[..., 0:1]
    img[cov] = (field[cov] + 0.8 * (chart[cov][:, None] % 3 + 1)) * np.array([1.0, 0.6, 0.3], np.float32)
    img, ch = lp.dilate(img, chart, 2)
    before_max, before_mean = _core.seam_mismatch(img, seams)
    assert before_max > 0.3
    out, info = lp.stitch(img, seams)
    assert info["seams"] == len(seams) and info["texels_changed"] > 0
    after_max, after_mean = _core.seam_mismatch(out, seams)
    assert after_max < 0.02 * before_max, info
    assert (after_max, after_mean) == pytest.approx(info["mismatch_after"])
    assert (out >= 0).all()
    # Only texels near a seam move.
    moved = np.abs(out - img).max(axis=2) > 0
    ys, xs = np.nonzero(moved)
    pts = seams.reshape(-1, 2)
    d = np.min([np.hypot(xs + 0.5 - px, ys + 0.5 - py) for px, py in pts], axis=0) if len(pts) < 2000 else None
    seg_len = np.linalg.norm(seams[:, :, 1] - seams[:, :, 0], axis=-1).max()
    if d is not None:
        assert d.max() <= seg_len + 2


# ---- denoise ----------------------------------------------------------------------------------------


def noisy_page(seed=1):
    rng = np.random.default_rng(seed)
    chart = np.full((96, 128), NONE, np.uint32)
    chart[8:60, 8:60] = 0
    chart[8:60, 63:120] = 1  # 3 texels from chart 0
    chart[66:90, 10:110] = 2
    level = {0: 1.0, 1: 12.0, 2: 3.0}  # HDR, with a bright chart next to a dim one
    img = np.zeros(chart.shape + (3,), np.float32)
    for c, v in level.items():
        m = chart == c
        img[m] = v * (1 + 0.5 * rng.uniform(-1, 1, (m.sum(), 3))).astype(np.float32)
    return img, chart, level


def test_denoise_keeps_energy_per_chart():
    pytest.importorskip("pyoidn", reason="pyoidn (the 'denoise' extra) is not installed")
    img, chart, level = noisy_page()
    out, info = lp.denoise(img, chart)
    assert info["denoised"] and info["charts"] == 3
    for c, v in level.items():
        m = chart == c
        assert out[m].mean() == pytest.approx(img[m].mean(), rel=0.03), c
        assert out[m].std() < 0.5 * img[m].std(), c  # it did denoise
        # No energy moved in from the bright neighbour: the dim chart's edge next to it stays dim.
    edge = out[8:60, 55:60][chart[8:60, 55:60] == 0]
    assert edge.mean() == pytest.approx(level[0], rel=0.05)
    # Gutters untouched, nothing negative.
    np.testing.assert_array_equal(out[chart == NONE], img[chart == NONE])
    assert (out >= 0).all()


def many_charts_page(seed=4, n=240):
    """n small charts (3-9 texels a side, 2 texels apart) on one page, levels spread over six
    decades in a random order (bright next to dim), with 25 % noise; every 10th chart all zero."""
    rng = np.random.default_rng(seed)
    per_row = 24
    chart = np.full((n // per_row * 11 + 2, per_row * 11 + 2), NONE, np.uint32)
    img = np.zeros(chart.shape + (3,), np.float32)
    level = {}
    for c in range(n):
        y, x = 2 + (c // per_row) * 11, 2 + (c % per_row) * 11
        h, w = rng.integers(3, 10, 2)
        chart[y:y + h, x:x + w] = c
        level[c] = 0.0 if c % 10 == 0 else float(10 ** rng.uniform(-3, 3))
        img[y:y + h, x:x + w] = level[c] * rng.gamma(16, 1 / 16, (h, w, 3)) * np.array([1.0, 0.8, 0.6])
    return img.astype(np.float32), chart, level


def test_denoise_puts_many_charts_in_one_call_and_each_gets_what_it_gets_alone():
    pytest.importorskip("pyoidn", reason="pyoidn (the 'denoise' extra) is not installed")
    img, chart, level = many_charts_page()
    out, info = lp.denoise(img, chart)
    assert info["charts"] == 240 and info["tiles"] == 216 and info["calls"] == 1, info
    for c, v in level.items():
        m = chart == c
        if v == 0.0:
            # All-zero charts are not denoised: OIDN would make faint light out of nothing.
            assert not out[m].any(), c
            continue
        # Each chart's light stays its own: its mean within 3 % of the input's, next to
        # neighbours up to a million times brighter or dimmer.
        # (6 %: a 3 x 3 chart's input mean itself carries ~5 % of noise; denoised on one page with
        # its neighbours, as the cooker did before charts were isolated, the worst is 2 250 %.)
        assert out[m].mean() == pytest.approx(img[m].mean(), rel=0.06), (c, v)
    # Against the same chart denoised alone (a page with only that chart: one tile, one call):
    # close, though not equal, since OIDN sees a sheet of other charts at 1.0 around the margin.
    for c in (1, 7, 55, 133, 239):
        alone = np.where(chart == c, chart, NONE).astype(np.uint32)
        solo, solo_info = lp.denoise(np.where((chart == c)[..., None], img, 0), alone)
        assert solo_info["calls"] == 1
        m = chart == c
        assert np.abs(out[m] - solo[m]).mean() < 0.1 * solo[m].mean(), c
    assert (out[chart == NONE] == img[chart == NONE]).all()


def test_denoise_is_skipped_with_a_warning_without_pyoidn(monkeypatch):
    monkeypatch.setitem(sys.modules, "pyoidn", None)  # `import pyoidn` now raises ImportError
    img, chart, _ = noisy_page()
    with pytest.warns(RuntimeWarning, match="denoising skipped: pyoidn is not available"):
        out, info = lp.denoise(img, chart)
    assert info["denoised"] is False
    np.testing.assert_array_equal(out, img)
    with pytest.warns(RuntimeWarning, match="pyoidn"):
        res = lp.finish_page(img, chart)
    assert res.info["denoise"]["denoised"] is False and res.info["dilated_texels"] > 0


# ---- EXR ---------------------------------------------------------------------------------------------


def hdr_page(h=37, w=53, seed=3):
    rng = np.random.default_rng(seed)
    img = (rng.uniform(0, 4, (h, w, 3)) ** 3).astype(np.float32)  # 0..64
    img[0, 0] = [1000.0, 20000.0, 0.001]
    return img


def test_exr_round_trip_is_exact_to_half_precision(tmp_path):
    img = hdr_page()
    p = tmp_path / "page.exr"
    lp.write_exr(p, img)
    back = lp.read_exr(p)
    assert back.shape == img.shape and back.dtype == np.float32
    np.testing.assert_array_equal(back, img.astype(np.float16).astype(np.float32))
    assert back.max() > 1000  # HDR survives, never clamped to 1
    assert [x.name for x in tmp_path.iterdir()] == ["page.exr"]  # no temporary left


def test_exr_never_holds_negatives_or_infinities(tmp_path):
    img = np.array([[[-1.0, np.nan, 1e9], [np.inf, 0.5, 3.0]]], np.float32)
    p = tmp_path / "s.exr"
    lp.write_exr(p, img)
    back = lp.read_exr(p)
    np.testing.assert_array_equal(back, [[[0.0, 0.0, 65504.0], [65504.0, 0.5, 3.0]]])


def test_exr_errors_name_the_file(tmp_path):
    with pytest.raises(_core.CookError, match="does not exist"):
        lp.write_exr(tmp_path / "missing" / "a.exr", hdr_page())
    (tmp_path / "junk.exr").write_bytes(b"nope")
    with pytest.raises(_core.CookError, match="junk.exr"):
        lp.read_exr(tmp_path / "junk.exr")


def test_exr_is_readable_by_openexr_tools(tmp_path):
    img = hdr_page()
    p = tmp_path / "page.exr"
    lp.write_exr(p, img)
    tool = shutil.which("exrheader")
    if tool is None:
        pytest.skip("exrheader not found (Debian package 'openexr'): cannot check the file with OpenEXR's tools")
    out = subprocess.run([tool, str(p)], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    text = out.stdout
    assert "16-bit floating-point" in text or "half" in text, text
    for ch in ("R,", "G,", "B,"):
        assert ch in text, text
    assert f"(0 0) - ({img.shape[1] - 1} {img.shape[0] - 1})" in text, text


def test_exr_is_readable_by_the_openexr_python_package(tmp_path):
    OpenEXR = pytest.importorskip("OpenEXR")
    img = hdr_page()
    p = tmp_path / "page.exr"
    lp.write_exr(p, img)
    with OpenEXR.File(str(p)) as f:
        chans = f.channels()
        if "RGB" in chans:
            rgb = np.asarray(chans["RGB"].pixels)
        else:
            rgb = np.stack([np.asarray(chans[c].pixels) for c in "RGB"], axis=-1)
    assert rgb.dtype == np.float16
    np.testing.assert_array_equal(rgb.astype(np.float32), img.astype(np.float16).astype(np.float32))


# ---- the whole page ---------------------------------------------------------------------------------


def test_finish_page_writes_a_clean_exr(cylinder_page, tmp_path):
    lod, layout, r = cylinder_page
    chart = r["chart"]
    cov = chart != NONE
    rng = np.random.default_rng(0)
    raw = np.zeros(chart.shape + (3,), np.float32)
    raw[cov] = (2.0 + 0.2 * rng.standard_normal((cov.sum(), 3))).clip(0).astype(np.float32)
    seams = lp.page_seams([lod], layout, 0)
    settings = lp.LightmapPostSettings(denoise="pyoidn" in sys.modules or _has_pyoidn())
    res = lp.finish_page(raw, chart, seams=seams, settings=settings, path=tmp_path / "lm.exr")
    back = lp.read_exr(tmp_path / "lm.exr")
    np.testing.assert_array_equal(back, res.image.astype(np.float16).astype(np.float32))
    filled = res.chart != NONE
    np.testing.assert_array_equal(filled, chebyshev_grow(cov, settings.dilate_rings))
    assert (res.image[filled] > 0.5).all()  # no black texel where bilinear may read
    assert res.info["stitch"]["mismatch_after"][0] <= res.info["stitch"]["mismatch_before"][0]


def _has_pyoidn() -> bool:
    try:
        import pyoidn  # noqa: F401
    except (ImportError, OSError):
        return False
    return True


def directional_page(seed=2):
    """`noisy_page`'s charts with directional texels (13 channels): per chart a b0 and a b1 of
    directionality 0.4 along its own axis, each texel's estimate noisy; and the sun's
    visibility, 1 on chart 0 and 0 elsewhere."""
    rng = np.random.default_rng(seed)
    _, chart, level = noisy_page()
    axes = {0: (0.0, 1.0, 0.0), 1: (0.6, 0.8, 0.0), 2: (0.0, 0.6, -0.8)}
    truth = np.zeros(chart.shape + (13,), np.float32)
    raw = truth.copy()
    for c, v in level.items():
        m = chart == c
        b0 = np.array([v, 0.5 * v, 0.25 * v], np.float32)
        b1 = 0.8 * b0[:, None] * np.array(axes[c], np.float32)[None, :]  # [channel, axis], |b1| = 0.8 b0
        truth[m, 0:3], truth[m, 3:12], truth[m, 12] = b0, b1.ravel(), float(c == 0)
        noise = 1 + 0.3 * rng.uniform(-1, 1, (m.sum(), 12))
        raw[m, 0:12] = truth[m, 0:12] * noise
        raw[m, 12] = truth[m, 12]
    return raw, truth, chart


def test_directional_pages_are_denoised_dilated_and_keep_their_direction():
    raw, truth, chart = directional_page()
    # Without the denoiser, covered texels come back as they were (b1 through q = b0 + b1/2
    # and back), and gutters are filled from their chart, every channel alike.
    plain = lp.finish_directional_page(raw, chart, settings=lp.LightmapPostSettings(denoise=False, stitch=False))
    covered = chart != NONE
    np.testing.assert_allclose(plain.image[covered], raw[covered], rtol=1e-5, atol=1e-5)
    ring = (plain.chart != NONE) & ~covered
    assert ring.sum() > 0 and np.isfinite(plain.image).all()
    near = plain.chart[ring]
    np.testing.assert_array_equal(plain.image[ring][:, 12], (near == 0).astype(np.float32))
    with pytest.raises(ValueError, match="directional page has shape"):
        lp.finish_directional_page(raw[..., :12], chart)
    # With it: each chart's b0 and b1 are closer to the truth, their means kept.
    pytest.importorskip("pyoidn", reason="pyoidn (the 'denoise' extra) is not installed")
    done = lp.finish_directional_page(raw, chart, settings=lp.LightmapPostSettings(stitch=False))
    for c in range(3):
        m = chart == c
        for name, ch in (("b0", slice(0, 3)), ("b1", slice(3, 12))):
            before = np.abs(raw[m, ch] - truth[m, ch]).mean()
            after = np.abs(done.image[m, ch] - truth[m, ch]).mean()
            assert after < 0.5 * before, (c, name, before, after)
            np.testing.assert_allclose(done.image[m, ch].mean(axis=0), truth[m, ch].mean(axis=0), rtol=0.05, atol=0.02 * truth[m, 0].mean())
        np.testing.assert_array_equal(done.image[m, 12], truth[m, 12])
    assert set(done.info) == {"b0", "q_x", "q_y", "q_z", "sun"} and done.info["b0"]["denoise"]["denoised"]
