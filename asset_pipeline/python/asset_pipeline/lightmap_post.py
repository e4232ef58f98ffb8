"""From a raw baked lightmap page to a clean HDR lightmap file.

    out = finish_page(raw, chart, seams=page_seams(lods, layout, page), path="page0.exr")

``raw`` is the baker's (h, w, 3) float32 page (linear HDR, ``B = H/pi`` per texel; see
notes/pathtracing.md §1.3), ``chart`` the (h, w) uint32 chart id per texel of the page's
conservative raster (``uv2.rasterize_page(...)["chart"]``, ``NONE`` where no chart is). The work is
the Rust core's (``_core.dilate_lightmap``, ``find_uv_seams``, ``stitch_seams``, ``write_exr``);
this module orders it and runs the optional denoiser.

Order, and why:

1. **Denoise** (optional, ``pyoidn``, OIDN's ``RTLightmap`` filter) chart by chart: each chart's
   covered texels are cut out with a margin, the margin filled by dilating that chart alone (then
   the chart's mean), so the denoiser never sees another chart, a black gutter or the page edge
   of the atlas, and only the chart's own covered texels are taken back. No energy moves between
   charts. ``RTLightmap`` takes no albedo/normal auxiliary images (OIDN's API: colour only; the
   ``pyoidn`` wrapper rejects them), so none are passed. Without ``pyoidn`` this step is skipped
   with a warning.
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
    denoise_margin: int = 8
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


def stitch(rgb: np.ndarray, seams: np.ndarray, settings: LightmapPostSettings | None = None) -> tuple[np.ndarray, dict]:
    """Make both sides of every seam interpolate to the same values; returns ``(rgb, info)``."""
    s = settings or LightmapPostSettings()
    seams = np.ascontiguousarray(seams, np.float64).reshape(-1, 2, 2, 2)
    return _core.stitch_seams(_check(rgb), seams, float(s.seam_samples_per_texel), float(s.seam_strength))


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


def denoise(rgb: np.ndarray, chart: np.ndarray, margin: int = 8) -> tuple[np.ndarray, dict]:
    """Denoise every chart's covered texels with OIDN's RTLightmap filter, each chart on its own
    (see the module notes). Gutter texels are returned unchanged. If ``pyoidn`` cannot be
    imported, warns and returns the page unchanged with ``info["denoised"] = False``."""
    rgb = _check(rgb, chart)
    chart = np.ascontiguousarray(chart, np.uint32)
    pyoidn, why = _load_pyoidn()
    if pyoidn is None:
        warnings.warn(f"lightmap denoising skipped: pyoidn is not available ({why}); "
                      "install the cooker's 'denoise' extra (pip install 'asset_pipeline[denoise]')", RuntimeWarning, stacklevel=2)
        return rgb.copy(), {"denoised": False, "reason": why, "charts": 0}
    out = rgb.copy()
    h, w = chart.shape
    covered = chart != NONE
    ids = np.unique(chart[covered])
    if len(ids) == 0:
        return out, {"denoised": True, "charts": 0}
    # Bounding box per chart, from one pass over the covered texels.
    ys, xs = np.nonzero(covered)
    cid = np.searchsorted(ids, chart[ys, xs])
    y0 = np.full(len(ids), h); y1 = np.zeros(len(ids), np.int64)
    x0 = np.full(len(ids), w); x1 = np.zeros(len(ids), np.int64)
    np.minimum.at(y0, cid, ys); np.maximum.at(y1, cid, ys)
    np.minimum.at(x0, cid, xs); np.maximum.at(x1, cid, xs)
    for k, c in enumerate(ids):
        ya, yb = max(int(y0[k]) - margin, 0), min(int(y1[k]) + margin + 1, h)
        xa, xb = max(int(x0[k]) - margin, 0), min(int(x1[k]) + margin + 1, w)
        mine = chart[ya:yb, xa:xb] == c
        local = np.where(mine[..., None], rgb[ya:yb, xa:xb], 0).astype(np.float32)
        local_chart = np.where(mine, np.uint32(0), np.uint32(NONE)).astype(np.uint32)
        local, local_chart = _core.dilate_lightmap(np.ascontiguousarray(local), local_chart, int(margin))
        rest = local_chart == NONE
        if rest.any():
            local[rest] = rgb[ya:yb, xa:xb][mine].mean(axis=0)
        den = pyoidn.denoise(np.ascontiguousarray(local), hdr=True, filter_type="RTLightmap")
        den = np.maximum(np.nan_to_num(np.asarray(den, np.float32), nan=0.0, posinf=0.0), 0.0)
        region = out[ya:yb, xa:xb]
        region[mine] = den[mine]
    return out, {"denoised": True, "charts": int(len(ids))}


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
    Each goes through the denoiser on its own. The sun's visibility is dilated and stitched, not
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
        img, chart_out, step = _finish_rgb(_check(img, chart), chart, seams, s, denoised=s.denoise and k < 4)
        done.append(img)
        info[["b0", "q_x", "q_y", "q_z", "sun"][k]] = step
    out = np.empty(raw.shape, np.float32)
    out[..., 0:3] = done[0]
    for a in range(3):
        out[..., 3 + a:12:3] = 2.0 * (done[1 + a] - done[0])
    out[..., 12] = np.clip(done[4][..., 0], 0.0, 1.0)
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
