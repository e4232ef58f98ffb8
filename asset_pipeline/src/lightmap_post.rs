//! Lightmap page clean-up and EXR I/O; the work is `cook_core::lightmap_post`'s and
//! `cook_core::exr_io`'s. Inputs must be C-contiguous with the dtypes named below; results are new
//! arrays (inputs are never modified); the GIL is released while the core works.
//!
//! Seams cross as a (k, 2, 2, 2) float64 array: `[seam][side A/B][endpoint 0/1][x, y]` in texel
//! units of the page (endpoint k of side A is the same 3D point as endpoint k of side B).

use cook_core::exr_io;
use cook_core::lightmap_mosaic::{self, Mosaic};
use cook_core::lightmap_post::{self, Seam, SeamMesh, SeamOptions, StitchOptions};
use numpy::ndarray::{Array2, Array3, Array4};
use numpy::{IntoPyArray, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3, PyReadonlyArray4, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;

fn contiguous<'a, T: numpy::Element, D: numpy::ndarray::Dimension>(
    a: &'a numpy::PyReadonlyArray<'_, T, D>,
    what: &str,
) -> PyResult<&'a [T]> {
    a.as_slice().map_err(|_| PyValueError::new_err(format!("{what} must be a C-contiguous array")))
}

fn image_shape(rgb: &PyReadonlyArray3<'_, f32>) -> PyResult<(usize, usize)> {
    let s = rgb.shape();
    if s[2] != 3 {
        return Err(PyValueError::new_err(format!("image has shape {s:?}, expected (h, w, 3)")));
    }
    Ok((s[0], s[1]))
}

fn cols(shape: &[usize], k: usize, what: &str) -> PyResult<()> {
    if shape.len() != 2 || shape[1] != k {
        return Err(PyValueError::new_err(format!("{what} has shape {shape:?}, expected (n, {k})")));
    }
    Ok(())
}

/// Dilate charts into the gutter: `rgb` (h, w, 3) float32, `chart` (h, w) uint32 with
/// 0xFFFFFFFF for empty texels. Every empty texel within `rings` texels (Chebyshev) of a chart
/// takes the average of its filled neighbours of the nearest chart (ties: lower chart id).
/// Returns `(rgb, chart)`: new arrays, the chart map naming the chart each filled texel came from.
#[pyfunction]
fn dilate_lightmap<'py>(
    py: Python<'py>,
    rgb: PyReadonlyArray3<'py, f32>,
    chart: PyReadonlyArray2<'py, u32>,
    rings: usize,
) -> PyResult<(Bound<'py, numpy::PyArray3<f32>>, Bound<'py, numpy::PyArray2<u32>>)> {
    let (h, w) = image_shape(&rgb)?;
    if chart.shape() != [h, w] {
        return Err(PyValueError::new_err(format!("chart has shape {:?}, expected ({h}, {w})", chart.shape())));
    }
    let mut img = contiguous(&rgb, "rgb")?.to_vec();
    let mut ch = contiguous(&chart, "chart")?.to_vec();
    py.detach(|| lightmap_post::dilate(&mut img, &mut ch, w, h, rings)).map_err(PyValueError::new_err)?;
    Ok((
        Array3::from_shape_vec((h, w, 3), img).expect("page size").into_pyarray(py),
        Array2::from_shape_vec((h, w), ch).expect("page size").into_pyarray(py),
    ))
}

/// UV2 seams of a page's triangles: `uv` (n, 2) float32 in [0, 1] of the page, `triangles`
/// (m, 3) uint32, `positions` (n, 3) float32 (welded within `weld_eps`), optional `normals`
/// (n, 3) float32 (shading normals; else geometric), optional `mesh` (m,) uint32 (edges match
/// only within one mesh). Sides whose normals differ (cosine < `min_normal_cos`) are hard edges,
/// not seams. Returns (k, 2, 2, 2) float64 (see the module notes).
#[pyfunction]
#[pyo3(signature = (uv, triangles, positions, width, height, normals=None, mesh=None, weld_eps=1e-5, min_normal_cos=0.9))]
#[allow(clippy::too_many_arguments)]
fn find_uv_seams<'py>(
    py: Python<'py>,
    uv: PyReadonlyArray2<'py, f32>,
    triangles: PyReadonlyArray2<'py, u32>,
    positions: PyReadonlyArray2<'py, f32>,
    width: usize,
    height: usize,
    normals: Option<PyReadonlyArray2<'py, f32>>,
    mesh: Option<PyReadonlyArray1<'py, u32>>,
    weld_eps: f32,
    min_normal_cos: f32,
) -> PyResult<Bound<'py, numpy::PyArray4<f64>>> {
    cols(uv.shape(), 2, "uv")?;
    cols(triangles.shape(), 3, "triangles")?;
    cols(positions.shape(), 3, "positions")?;
    if let Some(n) = &normals {
        cols(n.shape(), 3, "normals")?;
    }
    let m = SeamMesh {
        uv: contiguous(&uv, "uv")?,
        triangles: contiguous(&triangles, "triangles")?,
        positions: contiguous(&positions, "positions")?,
        normals: match &normals {
            Some(n) => Some(contiguous(n, "normals")?),
            None => None,
        },
        mesh: match &mesh {
            Some(x) => Some(contiguous(x, "mesh")?),
            None => None,
        },
    };
    let opt = SeamOptions { weld_eps, min_normal_cos, ..Default::default() };
    let seams = py.detach(|| lightmap_post::find_seams(&m, width, height, &opt)).map_err(PyValueError::new_err)?;
    Ok(seams_to_array(&seams).into_pyarray(py))
}

fn seams_to_array(seams: &[Seam]) -> Array4<f64> {
    let flat: Vec<f64> = seams.iter().flat_map(|s| [s.a[0], s.a[1], s.b[0], s.b[1]]).flatten().collect();
    Array4::from_shape_vec((seams.len(), 2, 2, 2), flat).expect("seam count")
}

fn seams_from_array(a: &PyReadonlyArray4<'_, f64>) -> PyResult<Vec<Seam>> {
    let s = a.shape();
    if s[1..] != [2, 2, 2] {
        return Err(PyValueError::new_err(format!("seams have shape {s:?}, expected (k, 2, 2, 2)")));
    }
    let f = contiguous(a, "seams")?;
    Ok(f.chunks_exact(8).map(|c| Seam { a: [[c[0], c[1]], [c[2], c[3]]], b: [[c[4], c[5]], [c[6], c[7]]] }).collect())
}

/// Stitch the seams of a page: returns `(image, info)`, a new (h, w, c) float32 image (any
/// number of channels c: a directional page's images stacked are stitched in one call) whose
/// two sides of every seam interpolate (bilinearly) to nearly the same values, and a dict with
/// `seams`, `constraints`, `groups`, `texels_changed`, `iterations`,
/// `mismatch_before`/`mismatch_after` ((max, mean) absolute difference along the seams).
#[pyfunction]
#[pyo3(signature = (image, seams, samples_per_texel=2.0, strength=0.03, max_iterations=1000))]
fn stitch_seams<'py>(
    py: Python<'py>,
    image: PyReadonlyArray3<'py, f32>,
    seams: PyReadonlyArray4<'py, f64>,
    samples_per_texel: f64,
    strength: f64,
    max_iterations: usize,
) -> PyResult<(Bound<'py, numpy::PyArray3<f32>>, Bound<'py, PyDict>)> {
    let (h, w, c) = (image.shape()[0], image.shape()[1], image.shape()[2]);
    let seams = seams_from_array(&seams)?;
    let mut img = contiguous(&image, "image")?.to_vec();
    let opt = StitchOptions { samples_per_texel, lambda: strength, max_iterations };
    let st = py.detach(|| lightmap_post::stitch_seams_channels(&mut img, c, w, h, &seams, &opt)).map_err(PyValueError::new_err)?;
    let d = PyDict::new(py);
    d.set_item("seams", st.seams)?;
    d.set_item("constraints", st.constraints)?;
    d.set_item("groups", st.groups)?;
    d.set_item("texels_changed", st.texels_changed)?;
    d.set_item("iterations", st.iterations)?;
    d.set_item("mismatch_before", st.mismatch_before)?;
    d.set_item("mismatch_after", st.mismatch_after)?;
    Ok((Array3::from_shape_vec((h, w, c), img).expect("page size").into_pyarray(py), d))
}

/// `(max, mean)` absolute difference between the two sides' bilinear lookups along the seams.
#[pyfunction]
#[pyo3(signature = (rgb, seams, samples_per_texel=2.0))]
fn seam_mismatch(py: Python<'_>, rgb: PyReadonlyArray3<'_, f32>, seams: PyReadonlyArray4<'_, f64>, samples_per_texel: f64) -> PyResult<(f64, f64)> {
    let (h, w) = image_shape(&rgb)?;
    let seams = seams_from_array(&seams)?;
    let img = contiguous(&rgb, "rgb")?;
    py.detach(|| lightmap_post::seam_mismatch(img, w, h, &seams, samples_per_texel)).map_err(PyValueError::new_err)
}

/// Bilinear lookups (the runtime sampler's: texel centres at half texels, clamp to edge) of
/// `rgb` (h, w, 3) float32 at `points` (n, 2) float64 in texel units: (n, 3) float64.
#[pyfunction]
fn sample_bilinear<'py>(py: Python<'py>, rgb: PyReadonlyArray3<'py, f32>, points: PyReadonlyArray2<'py, f64>) -> PyResult<Bound<'py, numpy::PyArray2<f64>>> {
    let (h, w) = image_shape(&rgb)?;
    cols(points.shape(), 2, "points")?;
    let img = contiguous(&rgb, "rgb")?;
    let p = contiguous(&points, "points")?;
    let out: Vec<f64> = py.detach(|| p.chunks_exact(2).flat_map(|q| lightmap_post::bilinear(img, w, h, [q[0], q[1]])).collect());
    Ok(Array2::from_shape_vec((p.len() / 2, 3), out).expect("point count").into_pyarray(py))
}

/// Write `rgb` ((h, w, 3) float32, linear) as a half-float RGB OpenEXR file at `path`,
/// atomically. HDR values are kept; negatives and NaN become 0, values beyond 65504 become
/// 65504. Raises CookError naming the file on failure.
#[pyfunction]
fn write_exr(py: Python<'_>, path: PathBuf, rgb: PyReadonlyArray3<'_, f32>) -> PyResult<()> {
    let (h, w) = image_shape(&rgb)?;
    let img = contiguous(&rgb, "rgb")?;
    py.detach(|| exr_io::write_exr(&path, img, w, h)).map_err(crate::CookError::new_err)
}

/// Write `channels` (name -> (h, w) float32, all one size; OpenEXR layer names such as "sun.Y")
/// as one half-float OpenEXR image at `path`, atomically, values sanitised as `write_exr`'s.
#[pyfunction]
fn write_exr_channels(py: Python<'_>, path: PathBuf, channels: Vec<(String, PyReadonlyArray2<'_, f32>)>) -> PyResult<()> {
    let Some((_, first)) = channels.first() else { return Err(PyValueError::new_err("write_exr_channels: no channels")) };
    let (h, w) = (first.shape()[0], first.shape()[1]);
    let mut data = Vec::with_capacity(channels.len());
    for (name, a) in &channels {
        if a.shape() != [h, w] {
            return Err(PyValueError::new_err(format!("write_exr_channels: channel '{name}' is {:?}, not ({h}, {w})", a.shape())));
        }
        data.push((name.as_str(), a.as_slice().map_err(|_| PyValueError::new_err(format!("write_exr_channels: channel '{name}' is not contiguous")))?));
    }
    py.detach(|| exr_io::write_exr_channels(&path, w, h, &data)).map_err(crate::CookError::new_err)
}

/// Read the first RGB(A) layer of an OpenEXR file as (h, w, 3) float32 (alpha dropped).
#[pyfunction]
fn read_exr<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, numpy::PyArray3<f32>>> {
    let (w, h, rgb) = py.detach(|| exr_io::read_exr(&path)).map_err(crate::CookError::new_err)?;
    Ok(Array3::from_shape_vec((h, w, 3), rgb).expect("exr size").into_pyarray(py))
}

/// `lightmap_log_average(page, direction, sun_toward, sun_lux) -> (sum, count)`: one baked page's
/// part of the scene's exposure (`pack::exposure::LogAverage`, the runtime's own sum): `page`
/// (h, w, 4) float16 as the pack holds it, `direction` (h, w, 4) uint8 or None, the sun's unit
/// direction toward it and its illuminance (zeros without a sun). The cooker adds the pages'
/// sums and stores the log-average, exp(sum / count), in the pack.
#[pyfunction]
fn lightmap_log_average(page: Bound<'_, PyAny>, direction: Option<PyReadonlyArray3<'_, u8>>, sun_toward: [f32; 3], sun_lux: [f32; 3]) -> PyResult<(f64, u64)> {
    let bits: PyReadonlyArray3<'_, u16> = page.call_method1("view", ("uint16",))?.extract()?;
    let (h, w) = (bits.shape()[0], bits.shape()[1]);
    if bits.shape()[2] != 4 || direction.as_ref().is_some_and(|d| d.shape() != [h, w, 4]) {
        return Err(PyValueError::new_err("page and direction must be (h, w, 4) arrays of one size"));
    }
    let bytes: Vec<u8> = contiguous(&bits, "page")?.iter().flat_map(|v| v.to_le_bytes()).collect();
    let dir = direction.as_ref().map(|d| contiguous(d, "direction")).transpose()?;
    let mut sum = pack::exposure::LogAverage::default();
    sum.add_page(&bytes, dir, Some(pack::exposure::Sun { toward: sun_toward, lux: sun_lux }));
    Ok((sum.sum, sum.count))
}

/// A page's charts packed for denoising in few calls (`cook_core::lightmap_mosaic`):
/// `DenoiseMosaic(rgb, chart, margin)` plans the tiles of `rgb` (h, w, 3) float32 with `chart`
/// (h, w) uint32; `sheets()` gives the images to denoise, `scatter(outputs)` the page with every
/// tiled chart's texels replaced by the denoised ones (a new array; the rest as in `rgb`).
#[pyclass(frozen, name = "DenoiseMosaic", module = "asset_pipeline._core")]
pub struct PyDenoiseMosaic {
    mosaic: Mosaic,
    rgb: Vec<f32>,
    chart: Vec<u32>,
    h: usize,
    w: usize,
}

#[pymethods]
impl PyDenoiseMosaic {
    #[new]
    fn new(py: Python<'_>, rgb: PyReadonlyArray3<'_, f32>, chart: PyReadonlyArray2<'_, u32>, margin: usize) -> PyResult<Self> {
        let (h, w) = image_shape(&rgb)?;
        if chart.shape() != [h, w] {
            return Err(PyValueError::new_err(format!("chart has shape {:?}, expected ({h}, {w})", chart.shape())));
        }
        let rgb = contiguous(&rgb, "rgb")?.to_vec();
        let chart = contiguous(&chart, "chart")?.to_vec();
        let mosaic = py.detach(|| lightmap_mosaic::plan(&rgb, &chart, w, h, margin)).map_err(PyValueError::new_err)?;
        Ok(PyDenoiseMosaic { mosaic, rgb, chart, h, w })
    }

    /// Charts tiled (the all-zero ones are not).
    #[getter]
    fn tiles(&self) -> usize {
        self.mosaic.tiles.len()
    }

    /// The sheets to denoise: a list of (h, w, 3) float32 arrays.
    fn sheets<'py>(&self, py: Python<'py>) -> Vec<Bound<'py, numpy::PyArray3<f32>>> {
        let sheets = py.detach(|| lightmap_mosaic::gather(&self.mosaic, &self.rgb, &self.chart, self.w));
        sheets
            .into_iter()
            .zip(&self.mosaic.sheets)
            .map(|(s, &(h, w))| Array3::from_shape_vec((h, w, 3), s).expect("sheet size").into_pyarray(py))
            .collect()
    }

    /// The page with the denoised sheets (`outputs`, as `sheets()` gave them) put back.
    fn scatter<'py>(&self, py: Python<'py>, outputs: Vec<PyReadonlyArray3<'py, f32>>) -> PyResult<Bound<'py, numpy::PyArray3<f32>>> {
        let views: Vec<&[f32]> = outputs.iter().map(|o| contiguous(o, "sheet")).collect::<PyResult<_>>()?;
        let mut out = self.rgb.clone();
        py.detach(|| lightmap_mosaic::scatter(&self.mosaic, &views, &mut out, &self.chart, self.w)).map_err(PyValueError::new_err)?;
        Ok(Array3::from_shape_vec((self.h, self.w, 3), out).expect("page size").into_pyarray(py))
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(lightmap_log_average, m)?)?;
    m.add_function(wrap_pyfunction!(dilate_lightmap, m)?)?;
    m.add_class::<PyDenoiseMosaic>()?;
    m.add_function(wrap_pyfunction!(find_uv_seams, m)?)?;
    m.add_function(wrap_pyfunction!(stitch_seams, m)?)?;
    m.add_function(wrap_pyfunction!(seam_mismatch, m)?)?;
    m.add_function(wrap_pyfunction!(sample_bilinear, m)?)?;
    m.add_function(wrap_pyfunction!(write_exr, m)?)?;
    m.add_function(wrap_pyfunction!(write_exr_channels, m)?)?;
    m.add_function(wrap_pyfunction!(read_exr, m)?)?;
    m.add("EXR_HALF_MAX", exr_io::HALF_MAX)?;
    Ok(())
}
