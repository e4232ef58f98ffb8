//! Texel rasterisation in lightmap (UV2) space, and PNG writing for previews; the work is
//! `cook_core::uv_raster`'s. Arrays cross as numpy arrays without copies (inputs must be
//! C-contiguous with the dtypes named below); the GIL is released while the core works.

use cook_core::uv_raster::{self, Coverage, UvTriangles};
use numpy::ndarray::{Array2, Array3};
use numpy::{IntoPyArray, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3, PyUntypedArrayMethods};
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

fn check_cols(shape: &[usize], k: usize, what: &str) -> PyResult<()> {
    if shape.len() != 2 || shape[1] != k {
        return Err(PyValueError::new_err(format!("{what} has shape {shape:?}, expected (n, {k})")));
    }
    Ok(())
}

/// Rasterise UV2 triangles onto a `width x height` page.
///
/// `uv`: (n, 2) float32 in [0, 1] of the page; `triangles`: (m, 3) uint32; `charts`: (m,) uint32
/// chart id per triangle. `conservative=False` takes texels whose centre a triangle contains;
/// `True` every texel a triangle overlaps (what the baker bakes). Returns a dict of (h, w[, k])
/// arrays: `triangle` uint32 (0xFFFFFFFF = none), `chart` uint32 (same), `charts_here` uint8
/// (distinct charts claiming the texel; 2 means two or more), `barycentric` float32 (of the
/// sample point: the texel centre, or the nearest point of the triangle for edge texels). With
/// `positions` ((n, 3) float32, e.g. world space) also `position` and `normal` float32 (h, w, 3):
/// interpolated at the sample point; `normals` ((n, 3) float32) are interpolated and normalised,
/// else the triangle's geometric normal (counter-clockwise front) is used.
#[pyfunction]
#[pyo3(signature = (uv, triangles, charts, width, height, conservative=true, positions=None, normals=None))]
#[allow(clippy::too_many_arguments)]
fn rasterize_uv<'py>(
    py: Python<'py>,
    uv: PyReadonlyArray2<'py, f32>,
    triangles: PyReadonlyArray2<'py, u32>,
    charts: PyReadonlyArray1<'py, u32>,
    width: usize,
    height: usize,
    conservative: bool,
    positions: Option<PyReadonlyArray2<'py, f32>>,
    normals: Option<PyReadonlyArray2<'py, f32>>,
) -> PyResult<Bound<'py, PyDict>> {
    check_cols(uv.shape(), 2, "uv")?;
    check_cols(triangles.shape(), 3, "triangles")?;
    let tris = UvTriangles {
        uv: contiguous(&uv, "uv")?,
        triangles: contiguous(&triangles, "triangles")?,
        charts: contiguous(&charts, "charts")?,
    };
    let n = tris.vertex_count();
    let pos = match &positions {
        Some(p) => {
            check_cols(p.shape(), 3, "positions")?;
            if p.shape()[0] != n {
                return Err(PyValueError::new_err(format!("{} positions for {n} uv vertices", p.shape()[0])));
            }
            Some(contiguous(p, "positions")?)
        }
        None => None,
    };
    let nrm = match &normals {
        Some(a) => {
            check_cols(a.shape(), 3, "normals")?;
            if pos.is_none() {
                return Err(PyValueError::new_err("normals need positions"));
            }
            Some(contiguous(a, "normals")?)
        }
        None => None,
    };
    let coverage = if conservative { Coverage::Conservative } else { Coverage::Centre };
    let (raster, surface) = py
        .detach(|| -> Result<_, String> {
            let r = uv_raster::rasterize(tris, width, height, coverage)?;
            let s = match pos {
                Some(p) => Some(uv_raster::surface(&r, tris.triangles, p, nrm)?),
                None => None,
            };
            Ok((r, s))
        })
        .map_err(PyValueError::new_err)?;
    let (h, w) = (height, width);
    let d = PyDict::new(py);
    let grid2 = |v| Array2::from_shape_vec((h, w), v).expect("raster size");
    d.set_item("triangle", grid2(raster.triangle).into_pyarray(py))?;
    d.set_item("chart", grid2(raster.chart).into_pyarray(py))?;
    d.set_item("charts_here", Array2::from_shape_vec((h, w), raster.charts_here).expect("raster size").into_pyarray(py))?;
    let grid3 = |v| Array3::from_shape_vec((h, w, 3), v).expect("raster size");
    d.set_item("barycentric", grid3(raster.bary).into_pyarray(py))?;
    if let Some((p, n)) = surface {
        d.set_item("position", grid3(p).into_pyarray(py))?;
        d.set_item("normal", grid3(n).into_pyarray(py))?;
    }
    Ok(d)
}

/// For every covered texel of a raster (its `chart` and `charts_here` maps), the Chebyshev
/// distance in texels to the nearest texel of another chart: 0 where two charts claim the texel,
/// `limit + 1` when none is within `limit`, 255 where no chart is. A padding of `p` texels is
/// respected when every covered texel's value is greater than `p`. Returns (h, w) uint8.
#[pyfunction]
fn chart_separation<'py>(
    py: Python<'py>,
    chart: PyReadonlyArray2<'py, u32>,
    charts_here: PyReadonlyArray2<'py, u8>,
    limit: u8,
) -> PyResult<Bound<'py, numpy::PyArray2<u8>>> {
    let shape = chart.shape().to_vec();
    if charts_here.shape() != shape.as_slice() {
        return Err(PyValueError::new_err(format!("chart {shape:?} and charts_here {:?} differ in shape", charts_here.shape())));
    }
    let (c, here) = (contiguous(&chart, "chart")?, contiguous(&charts_here, "charts_here")?);
    let sep = py.detach(|| uv_raster::separation(c, here, shape[1], shape[0], limit)).map_err(PyValueError::new_err)?;
    Ok(Array2::from_shape_vec((shape[0], shape[1]), sep).expect("raster size").into_pyarray(py))
}

/// Write `rgba` ((h, w, 4) uint8, rows top to bottom) as a PNG at `path`, atomically (temporary
/// file + rename). Raises CookError naming the file when it cannot be written.
#[pyfunction]
fn encode_png(py: Python<'_>, path: PathBuf, rgba: PyReadonlyArray3<'_, u8>) -> PyResult<()> {
    let shape = rgba.shape().to_vec();
    if shape[2] != 4 {
        return Err(PyValueError::new_err(format!("rgba has shape {shape:?}, expected (h, w, 4)")));
    }
    let (w, h) = (u32::try_from(shape[1]), u32::try_from(shape[0]));
    let (Ok(w), Ok(h)) = (w, h) else {
        return Err(PyValueError::new_err(format!("image of shape {shape:?} is too large")));
    };
    let bytes = contiguous(&rgba, "rgba")?;
    py.detach(|| uv_raster::write_png_atomic(&path, w, h, bytes)).map_err(crate::CookError::new_err)
}

/// Connected components of triangles ((m, 3) uint32) through shared vertex ids: (m,) uint32
/// component ids, numbered in order of first appearance.
#[pyfunction]
fn triangle_components<'py>(py: Python<'py>, triangles: PyReadonlyArray2<'py, u32>, vertex_count: usize) -> PyResult<Bound<'py, numpy::PyArray1<u32>>> {
    check_cols(triangles.shape(), 3, "triangles")?;
    let t = contiguous(&triangles, "triangles")?;
    let c = py.detach(|| uv_raster::triangle_components(t, vertex_count)).map_err(PyValueError::new_err)?;
    Ok(c.into_pyarray(py))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(rasterize_uv, m)?)?;
    m.add_function(wrap_pyfunction!(chart_separation, m)?)?;
    m.add_function(wrap_pyfunction!(encode_png, m)?)?;
    m.add_function(wrap_pyfunction!(triangle_components, m)?)?;
    m.add("UV_NONE", uv_raster::NONE)?;
    Ok(())
}
