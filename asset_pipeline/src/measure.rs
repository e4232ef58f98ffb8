//! Python face of `cook_core::measure`: closest-point queries on a triangle mesh (`MeshBvh`),
//! sampled one-sided Hausdorff distances, the faces on given edges. Arrays are read in place (numpy,
//! no copies when C-contiguous) and the work runs without the GIL.

use cook_core::measure::{self, Bvh, MeshError};
use numpy::{Element, PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use std::borrow::Cow;

fn value_error(what: &str, e: MeshError) -> PyErr {
    PyValueError::new_err(format!("{what}: {e}"))
}

/// An (n, W) array as rows, borrowed when C-contiguous, copied otherwise.
pub(crate) fn rows<'a, T: Element + Copy, const W: usize>(a: &'a PyReadonlyArray2<'_, T>, what: &str) -> PyResult<Cow<'a, [[T; W]]>> {
    let shape = a.shape();
    if shape[1] != W {
        return Err(PyValueError::new_err(format!("{what}: expected shape (n, {W}), got {shape:?}")));
    }
    Ok(match a.as_slice() {
        // SAFETY: [T; W] has the size of W T and T's alignment, so a contiguous slice of
        // W n T is exactly n rows; the borrow keeps the array alive and unaliased for writes.
        Ok(flat) => Cow::Borrowed(unsafe { std::slice::from_raw_parts(flat.as_ptr() as *const [T; W], flat.len() / W) }),
        Err(_) => Cow::Owned(a.as_array().rows().into_iter().map(|r| std::array::from_fn(|k| r[k])).collect()),
    })
}

/// An (n, 3) array as rows (see [`rows`]).
pub(crate) fn rows3<'a, T: Element + Copy>(a: &'a PyReadonlyArray2<'_, T>, what: &str) -> PyResult<Cow<'a, [[T; 3]]>> {
    rows::<T, 3>(a, what)
}

pub(crate) fn vec1<'a, T: Element + Copy>(a: &'a PyReadonlyArray1<'_, T>) -> Cow<'a, [T]> {
    match a.as_slice() {
        Ok(s) => Cow::Borrowed(s),
        Err(_) => Cow::Owned(a.as_array().iter().copied().collect()),
    }
}

/// A BVH over a triangle mesh for closest-point queries.
///
/// `MeshBvh(positions: float32 (n, 3), triangles: uint32 (m, 3))`.
#[pyclass(frozen, name = "MeshBvh", module = "asset_pipeline._core")]
pub struct PyMeshBvh {
    bvh: Bvh,
}

#[pymethods]
impl PyMeshBvh {
    #[new]
    fn new(py: Python<'_>, positions: PyReadonlyArray2<'_, f32>, triangles: PyReadonlyArray2<'_, u32>) -> PyResult<Self> {
        let pos = rows3(&positions, "positions")?;
        let tri = rows3(&triangles, "triangles")?;
        let bvh = py.detach(|| Bvh::build(&pos, &tri)).map_err(|e| value_error("MeshBvh", e))?;
        Ok(PyMeshBvh { bvh })
    }

    #[getter]
    fn triangle_count(&self) -> usize {
        self.bvh.triangle_count()
    }

    /// Closest points on the mesh to `points` (float32 (k, 3)): returns
    /// `(distance float64 (k,), triangle uint32 (k,), bary float64 (k, 3))` where the closest point
    /// is `bary @ corners of triangle`. `hints` (uint32 (k,), a triangle per point, 0xFFFFFFFF for
    /// none) only speed the search up. An empty mesh gives distance inf and triangle 0xFFFFFFFF.
    #[pyo3(signature = (points, hints=None))]
    #[allow(clippy::type_complexity)]
    fn closest<'py>(
        &self,
        py: Python<'py>,
        points: PyReadonlyArray2<'py, f32>,
        hints: Option<PyReadonlyArray1<'py, u32>>,
    ) -> PyResult<(Bound<'py, PyArray1<f64>>, Bound<'py, PyArray1<u32>>, Bound<'py, PyArray2<f64>>)> {
        let pts = rows3(&points, "points")?;
        let hints = hints.as_ref().map(vec1);
        if let Some(h) = &hints {
            if h.len() != pts.len() {
                return Err(PyValueError::new_err(format!("closest: {} hints for {} points", h.len(), pts.len())));
            }
            let m = self.bvh.triangle_count() as u32;
            if let Some(i) = h.iter().position(|&x| x != u32::MAX && x >= m) {
                return Err(PyValueError::new_err(format!("closest: hint {i} is not a triangle index")));
            }
        }
        if pts.iter().any(|p| !p.iter().all(|x| x.is_finite())) {
            return Err(PyValueError::new_err("closest: a point is not finite"));
        }
        let (dist, tri, bary) = py.detach(|| {
            let hits = self.bvh.closest_many(&pts, hints.as_deref());
            let mut dist = Vec::with_capacity(hits.len());
            let mut tri = Vec::with_capacity(hits.len());
            let mut bary = Vec::with_capacity(3 * hits.len());
            for h in hits {
                match h {
                    Some(h) => {
                        dist.push(h.distance);
                        tri.push(h.triangle);
                        bary.extend(h.bary);
                    }
                    None => {
                        dist.push(f64::INFINITY);
                        tri.push(u32::MAX);
                        bary.extend([0f64; 3]);
                    }
                }
            }
            (dist, tri, bary)
        });
        let n = dist.len();
        let bary = PyArray1::from_vec(py, bary).reshape([n, 3])?;
        Ok((PyArray1::from_vec(py, dist), PyArray1::from_vec(py, tri), bary))
    }

    /// One-sided Hausdorff distance from the mesh (positions, triangles) to this one, sampled on
    /// a barycentric grid per triangle with at most `spacing` between samples (at least
    /// `min_subdiv` subdivisions per edge; spacing widened if the samples would exceed
    /// `max_samples`), then refined by a local search around the largest samples.
    /// `vertex_hints` (uint32 (n,), a triangle of this mesh near each vertex, 0xFFFFFFFF for
    /// none) only speed it up. Returns `(max distance, samples taken, spacing used)`.
    #[pyo3(signature = (positions, triangles, spacing, min_subdiv=1, max_samples=50_000_000, vertex_hints=None))]
    #[allow(clippy::too_many_arguments)]
    fn directed_hausdorff(
        &self,
        py: Python<'_>,
        positions: PyReadonlyArray2<'_, f32>,
        triangles: PyReadonlyArray2<'_, u32>,
        spacing: f64,
        min_subdiv: u32,
        max_samples: u64,
        vertex_hints: Option<PyReadonlyArray1<'_, u32>>,
    ) -> PyResult<(f64, u64, f64)> {
        let pos = rows3(&positions, "positions")?;
        let tri = rows3(&triangles, "triangles")?;
        let hints = vertex_hints.as_ref().map(vec1);
        let d = py
            .detach(|| self.bvh.directed_hausdorff(&pos, &tri, spacing, min_subdiv, max_samples, hints.as_deref()))
            .map_err(|e| value_error("directed_hausdorff", e))?;
        Ok((d.max, d.samples, d.spacing))
    }
}

/// The two faces on each edge (`edges` uint32 (k, 2), vertex indices of `triangles` uint32
/// (m, 3)): uint32 (k, 2), 0xFFFFFFFF twice where the edge does not have exactly two faces.
#[pyfunction]
fn edge_faces<'py>(py: Python<'py>, triangles: PyReadonlyArray2<'py, u32>, edges: PyReadonlyArray2<'py, u32>) -> PyResult<Bound<'py, PyArray2<u32>>> {
    let tri = rows3(&triangles, "triangles")?;
    let edges = rows::<u32, 2>(&edges, "edges")?;
    let out = py.detach(|| measure::edge_faces(&tri, &edges));
    let k = out.len();
    Ok(PyArray1::from_vec(py, out.into_flattened()).reshape([k, 2])?)
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyMeshBvh>()?;
    m.add_function(wrap_pyfunction!(edge_faces, m)?)?;
    Ok(())
}
