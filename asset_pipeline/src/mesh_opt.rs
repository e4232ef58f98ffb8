//! Python face of `cook_core::mesh_opt`: triangle and vertex order of one LOD, and the vertex
//! cache statistics the cook report gives before and after.

use crate::measure::{rows, vec1};
use numpy::{PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

/// `optimize_lod(triangles uint32 (m, 3), keys uint64 (m,), positions float32 (n, 3))` ->
/// `(triangles uint32 (m, 3), triangle_order uint32 (m,), vertices uint32 (k,))`: the new
/// triangles (indexing the new vertices), which input triangle each is, and which input vertex
/// each new vertex is (used ones only). Groups (`keys`) come out contiguous, in ascending order.
#[pyfunction]
fn optimize_lod<'py>(
    py: Python<'py>,
    triangles: PyReadonlyArray2<'py, u32>,
    keys: PyReadonlyArray1<'py, u64>,
    positions: PyReadonlyArray2<'py, f32>,
) -> PyResult<(Bound<'py, PyArray2<u32>>, Bound<'py, PyArray1<u32>>, Bound<'py, PyArray1<u32>>)> {
    let t = rows::<u32, 3>(&triangles, "triangles")?;
    let p = rows::<f32, 3>(&positions, "positions")?;
    let k = vec1(&keys);
    let out = py
        .detach(|| cook_core::mesh_opt::optimize(&t, &k, &p))
        .map_err(|e| PyValueError::new_err(format!("mesh optimisation: {e}")))?;
    let m = out.triangles.len();
    let tris = PyArray1::from_vec(py, out.triangles.into_flattened()).reshape([m, 3])?;
    Ok((tris, PyArray1::from_vec(py, out.triangle_order), PyArray1::from_vec(py, out.vertices)))
}

/// `vertex_cache_stats(triangles uint32 (m, 3), vertex_count)` -> `(acmr, atvr)` with
/// meshoptimizer's FIFO model of `CACHE_SIZE` entries.
#[pyfunction]
fn vertex_cache_stats(triangles: PyReadonlyArray2<'_, u32>, vertex_count: usize) -> PyResult<(f32, f32)> {
    let t = rows::<u32, 3>(&triangles, "triangles")?;
    if let Some(i) = t.iter().flatten().find(|&&i| i as usize >= vertex_count) {
        return Err(PyValueError::new_err(format!("vertex_cache_stats: index {i} is out of range for {vertex_count} vertices")));
    }
    let s = cook_core::mesh_opt::cache_stats(&t, vertex_count);
    Ok((s.acmr, s.atvr))
}

/// `decode_vertices(stored bytes, uv_ranges json)` -> bytes of the decoded 80-byte `pack::Vertex`
/// records (position, normal, tangent, uv0, uv1, texcoord1 as f32, colour u8x4, padding): a
/// LOD's vertices as the pack stores them (quantised, `pack::vertex`) and as the runtime's CPU
/// code reads them. ValueError for a length not a whole number of vertices or bad ranges.
#[pyfunction]
fn decode_vertices<'py>(py: Python<'py>, stored: &[u8], uv_ranges: &str) -> PyResult<Bound<'py, pyo3::types::PyBytes>> {
    if stored.len() % pack::VERTEX_STRIDE != 0 {
        return Err(PyValueError::new_err(format!("decode_vertices: {} bytes is not a whole number of {}-byte vertices", stored.len(), pack::VERTEX_STRIDE)));
    }
    let ranges: pack::UvRanges = serde_json::from_str(uv_ranges).map_err(|e| PyValueError::new_err(format!("decode_vertices: uv_ranges: {e}")))?;
    let v = pack::decode_vertices(stored, &ranges);
    Ok(pyo3::types::PyBytes::new(py, pack::Vertex::slice_as_bytes(&v)))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("VERTEX_STRIDE", pack::VERTEX_STRIDE)?;
    m.add_function(wrap_pyfunction!(decode_vertices, m)?)?;
    m.add_function(wrap_pyfunction!(optimize_lod, m)?)?;
    m.add_function(wrap_pyfunction!(vertex_cache_stats, m)?)?;
    m.add("VERTEX_CACHE_SIZE", cook_core::mesh_opt::CACHE_SIZE)?;
    Ok(())
}
