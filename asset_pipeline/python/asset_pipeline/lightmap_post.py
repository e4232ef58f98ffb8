"""From a raw baked lightmap page to a clean HDR lightmap file.

    out = finish_page(raw, chart, seams=page_seams(lods, layout, page), path="page0.exr")

``raw`` is the baker's (h, w, 3) float32 page (linear HDR, ``B = H/pi`` per texel; see
notes/pathtracing.md §1.3), ``chart`` the (h, w) uint32 chart id per texel of the page's
conservative raster (``uv2.rasterize_page(...)["chart"]``, ``NONE`` where no chart is). The work is
the Rust core's (``_core.dilate_lightmap``, ``find_uv_seams``, ``stitch_seams``, ``write_exr``);
this module orders it and runs the optional denoiser.

Order, and why:

1. **Denoise** (optional, ``pyoidn``, OIDN's ``RTLightmap`` filter), every chart as if alone:
   each chart's covered texels are cut out with a margin, scaled to a mean of 1, the margin
   filled by dilating that chart alone (then the chart's mean), so the denoiser never sees
   another chart's light, a black gutter or the page edge of the atlas, and only the chart's own
   covered texels are taken back, scaled back. No energy moves between charts. The tiles are
   packed into a few sheets, one denoiser call each (``_core.DenoiseMosaic``; why the tiles of a
   sheet stay apart: ``cook_core::lightmap_mosaic``). All-zero charts are not denoised (OIDN
   makes faint light out of zeros). ``RTLightmap`` takes no albedo/normal auxiliary images
   (OIDN's API: colour only; the ``pyoidn`` wrapper rejects them), so none are passed. Without
   ``pyoidn`` this step is skipped with a warning.
2. **Dilate** ``rings`` texels into the gutters (after denoising: the denoiser's output is what
   must be extended, and denoising the dilated ring would blur gutter values back into charts).
3. **Stitch seams**: last of the image steps, since denoising (and dilation) re-open seams; the
   seam footprints at a chart's edge reach into the ring dilation filled.
4. **Write** a half-float RGB OpenEXR file, atomically.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from asset_pipeline import _core, ir

NONE = 0xFFFFFFFF


@dataclass(frozen=True)
class LightmapPostSettings:
    # Gutter rings to fill, as many as uv2's padding (Uv2Settings.padding, 4): every gutter texel
    # within the padding of a chart gets a value (each from its nearest chart), so bicubic sampling,
    # which reads 2 texels past a chart, never reads an unfilled texel; between two charts 4 apart
    # each fills the 2 texels on its side.
    dilate_rings: int = 4
    denoise: bool = True
    # Texels of context around each chart handed to the denoiser (filled from that chart only).
    # 2, not 8: measured on the 100k-triangle benchmark level's page against a second bake with
    # another seed (the mean squared error to an independent unbiased bake ranks denoisers as
    # their error to the truth does), margins of 1-2 came out as good as 8 or better (relative
    # MSE 0.1008 at 2 against 0.1048 at 8, per-chart mean drift 0.36 % against 0.66 %) and denoise
    # 2.4x fewer texels.
    denoise_margin: int = 2
    stitch: bool = True
    seam_samples_per_texel: float = 2.0
    # Least-squares weight of "keep the baked value" against "both sides agree" (smaller closes
    # seams more tightly; 0.03 leaves ~0.2% of a seam's step).
    seam_strength: float = 0.03
    # Sides meeting at a sharper angle than this (cosine of the normals) are hard edges, not seams.
    seam_min_normal_cos: float = 0.9


@dataclass
class PagePost:
    image: np.ndarray  # (h, w, 3) float32: the finished page
    chart: np.ndarray  # (h, w) uint32: chart per texel after dilation (NONE = untouched gutter)
    info: dict = field(default_factory=dict)


def _check(rgb: np.ndarray, chart: np.ndarray | None = None) -> np.ndarray:
    rgb = np.ascontiguousarray(rgb, np.float32)
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ValueError(f"lightmap page has shape {rgb.shape}, expected (h, w, 3)")
    if chart is not None and chart.shape != rgb.shape[:2]:
        raise ValueError(f"chart map has shape {chart.shape}, expected {rgb.shape[:2]}")
    return rgb


def dilate(rgb: np.ndarray, chart: np.ndarray, rings: int) -> tuple[np.ndarray, np.ndarray]:
    """Fill ``rings`` rings of gutter around every chart; returns new ``(rgb, chart)``."""
    chart = np.ascontiguousarray(chart, np.uint32)
    return _core.dilate_lightmap(_check(rgb, chart), chart, int(rings))


def page_seams(lods: Sequence[ir.Lod], layout: ir.LightmapLayout, page: int, *, positions=None, normals=None,
               min_normal_cos: float = 0.9) -> np.ndarray:
    """The UV2 seams of one page: (k, 2, 2, 2) float64 texel-unit endpoints (see ``_core.find_uv_seams``).
    Edges are matched within each Lod (``positions``/``normals`` per Lod default to its own)."""
    from asset_pipeline.uv2 import page_mesh

    w, h = layout.pages[page]
    m = page_mesh(lods, page, positions=positions, normals=normals)
    return _core.find_uv_seams(m["uv"], m["triangles"], m["position"], int(w), int(h), normals=m["normal"], mesh=m["mesh"],
                               min_normal_cos=float(min_normal_cos))


def stitch(img: np.ndarray, seams: np.ndarray, settings: LightmapPostSettings | None = None) -> tuple[np.ndarray, dict]:
    """Make both sides of every seam interpolate to the same values; returns ``(img, info)``.
    ``img`` is (h, w, c) float32 with any number of channels (the system is solved once per
    channel; stacking a page's images stitches them in one call)."""
    s = settings or LightmapPostSettings()
    img = np.ascontiguousarray(img, np.float32)
    if img.ndim != 3 or img.shape[2] < 1:
        raise ValueError(f"lightmap image has shape {img.shape}, expected (h, w, channels)")
    seams = np.ascontiguousarray(seams, np.float64).reshape(-1, 2, 2, 2)
    return _core.stitch_seams(img, seams, float(s.seam_samples_per_texel), float(s.seam_strength))


def _load_pyoidn():
    try:
        import pyoidn
    except (ImportError, OSError) as e:  # OSError: the wheel's native library failed to load
        return None, f"{type(e).__name__}: {e}"
    return pyoidn, None


def denoiser() -> str:
    """What denoising will run: the pyoidn version, or why none will."""
    from asset_pipeline.cache import library_version

    pyoidn, why = _load_pyoidn()
    return library_version("pyoidn") if pyoidn is not None else f"no denoiser ({why})"


def denoise(rgb: np.ndarray, chart: np.ndarray, margin: int = 2) -> tuple[np.ndarray, dict]:
    """Denoise every chart's covered texels with OIDN's RTLightmap filter, each chart as if on
    its own (see the module notes), many charts a call. Gutter texels are returned unchanged. If
    ``pyoidn`` cannot be imported, warns and returns the page unchanged with
    ``info["denoised"] = False``."""
    rgb = _check(rgb, chart)
    chart = np.ascontiguousarray(chart, np.uint32)
    pyoidn, why = _load_pyoidn()
    if pyoidn is None:
        warnings.warn(f"lightmap denoising skipped: pyoidn is not available ({why}); "
                      "install the cooker's 'denoise' extra (pip install 'asset_pipeline[denoise]')", RuntimeWarning, stacklevel=2)
        return rgb.copy(), {"denoised": False, "reason": why, "charts": 0}
    charts = int(len(np.unique(chart[chart != NONE])))
    mosaic = _core.DenoiseMosaic(rgb, chart, int(margin))
    sheets = mosaic.sheets()
    outputs = [np.asarray(pyoidn.denoise(sheet, hdr=True, filter_type="RTLightmap"), np.float32) for sheet in sheets]
    return mosaic.scatter(outputs), {"denoised": True, "charts": charts, "tiles": int(mosaic.tiles), "calls": len(sheets)}


def write_exr(path: str | Path, rgb: np.ndarray) -> None:
    """Write a page as half-float RGB OpenEXR, atomically (HDR kept; negatives/NaN -> 0)."""
    _core.write_exr(Path(path), _check(rgb))


def read_exr(path: str | Path) -> np.ndarray:
    """Read an OpenEXR file's RGB as (h, w, 3) float32."""
    return _core.read_exr(Path(path))


def finish_page(raw: np.ndarray, chart: np.ndarray, *, seams: np.ndarray | None = None,
                settings: LightmapPostSettings | None = None, path: str | Path | None = None) -> PagePost:
    """Denoise -> dilate -> stitch -> (write ``path`` as EXR) for one page; see the module notes."""
    s = _checked(settings)
    chart = np.ascontiguousarray(chart, np.uint32)
    img, chart_out, info = _finish_rgb(_check(raw, chart), chart, seams, s, denoised=s.denoise)
    if path is not None:
        write_exr(path, img)
        info["path"] = str(path)
    return PagePost(img, chart_out, info)


# A directional page's 13 channels (``_core.Baker.bake_points(directional=True)``): b0 (r, g, b), b1 of
# r (x, y, z), of g, of b, and the sun's visibility.
DIRECTIONAL_CHANNELS = 13


def finish_directional_page(raw: np.ndarray, chart: np.ndarray, *, seams: np.ndarray | None = None,
                            settings: LightmapPostSettings | None = None) -> PagePost:
    """``finish_page`` for a directional page, (h, w, 13) (``DIRECTIONAL_CHANNELS``): the same
    steps on RGB images the denoiser can take, which must be non-negative HDR: b0, and for each
    axis a, ``q_a = b0 + b1_a / 2``, the irradiance of a half-strength lobe toward +a (non-negative
    since non-negative radiance keeps ``|b1| <= 2 b0``); b1 is recovered as ``2 (q_a - b0)``.
    Each goes through the denoiser and dilation on its own; the seams are stitched once for all
    of them. The sun's visibility is dilated and stitched, not
    denoised (noise there is a few penumbra texels). Returns the finished (h, w, 13) page."""
    s = _checked(settings)
    chart = np.ascontiguousarray(chart, np.uint32)
    raw = np.asarray(raw, np.float32)
    if raw.ndim != 3 or raw.shape[2] != DIRECTIONAL_CHANNELS or raw.shape[:2] != chart.shape:
        raise ValueError(f"directional page has shape {raw.shape}, expected {chart.shape + (DIRECTIONAL_CHANNELS,)}")
    b0 = raw[..., 0:3]
    b1 = raw[..., 3:12].reshape(raw.shape[:2] + (3, 3))  # [..., channel, axis]
    images = [b0] + [b0 + 0.5 * b1[..., :, a] for a in range(3)] + [np.repeat(raw[..., 12:13], 3, axis=2)]
    done, info, chart_out = [], {}, chart
    for k, img in enumerate(images):
        img, chart_out, step = _finish_rgb(_check(img, chart), chart, None, s, denoised=s.denoise and k < 4)
        done.append(img)
        info[["b0", "q_x", "q_y", "q_z", "sun"][k]] = step
    # Stitched together, after every image is denoised and dilated: one system for the page's
    # 13 channels (b0, q_x, q_y, q_z, one channel of the sun's visibility).
    stacked = np.concatenate(done[:4] + [done[4][..., :1]], axis=2)
    if s.stitch and seams is not None and len(seams):
        stacked, info["stitch"] = stitch(stacked, seams, s)
    out = np.empty(raw.shape, np.float32)
    out[..., 0:3] = stacked[..., 0:3]
    for a in range(3):
        out[..., 3 + a:12:3] = 2.0 * (stacked[..., 3 + 3 * a:6 + 3 * a] - stacked[..., 0:3])
    out[..., 12] = np.clip(stacked[..., 12], 0.0, 1.0)
    return PagePost(out, chart_out, info)


def _checked(settings: LightmapPostSettings | None) -> LightmapPostSettings:
    s = settings or LightmapPostSettings()
    if int(s.dilate_rings) != s.dilate_rings or s.dilate_rings < 0:
        raise ValueError(f"dilate_rings must be a whole number >= 0, not {s.dilate_rings}")
    return s


def _finish_rgb(img: np.ndarray, chart: np.ndarray, seams, s: LightmapPostSettings, denoised: bool) -> tuple[np.ndarray, np.ndarray, dict]:
    """Denoise (when asked) -> dilate -> stitch one RGB image of a page."""
    info: dict = {}
    if denoised:
        img, info["denoise"] = denoise(img, chart, int(s.denoise_margin))
    img, chart_out = dilate(img, chart, int(s.dilate_rings))
    info["dilated_texels"] = int((chart_out != chart).sum())
    if s.stitch and seams is not None and len(seams):
        img, info["stitch"] = stitch(img, seams, s)
    return img, chart_out, info
