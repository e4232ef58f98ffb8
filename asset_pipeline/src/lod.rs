//! Python face of `cook_core::lod`: one call per LOD level, run without the GIL (so the LOD
//! stage can carry one level's attributes while fast-simplification, which holds the GIL, makes
//! the next level).

use crate::measure::{rows, rows3, vec1};
use cook_core::lod::{self, Attributes, ErrorSettings, Job, Lod0Data, Morphs, Tracked};
use cook_core::measure;
use numpy::{Element, PyArray1, PyArray2, PyArray3, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

fn err(msg: String) -> PyErr {
    PyValueError::new_err(format!("lod: {msg}"))
}

fn array2<'py, T: Element + Copy, const W: usize>(py: Python<'py>, rows: Vec<[T; W]>) -> PyResult<Bound<'py, PyArray2<T>>> {
    let n = rows.len();
    // into_flattened reuses the allocation: no copy of a million rows.
    Ok(PyArray1::from_vec(py, rows.into_flattened()).reshape([n, W])?)
}

/// `d[name] = rows` as an (n, W) array, when there are rows.
fn set<'py, T: Element + Copy, const W: usize>(d: &Bound<'py, PyDict>, name: &str, rows: Option<Vec<[T; W]>>) -> PyResult<()> {
    match rows {
        Some(rows) => d.set_item(name, array2(d.py(), rows)?),
        None => Ok(()),
    }
}

/// Rows of an optional attribute, copied, checked to have one row per LOD 0 vertex.
fn attribute<'py, T: Element + Copy, const W: usize>(attributes: &Bound<'py, PyDict>, name: &str, n: usize) -> PyResult<Option<Vec<[T; W]>>> {
    let Some(a) = attributes.get_item(name)? else { return Ok(None) };
    let a: PyReadonlyArray2<'py, T> = a.extract().map_err(|_| err(format!("{name} must be a {W}-column {} array", std::any::type_name::<T>())))?;
    let rows = rows::<T, W>(&a, name)?.into_owned();
    if rows.len() != n {
        return Err(err(format!("{name} has {} rows for {n} vertices", rows.len())));
    }
    Ok(Some(rows))
}

/// Morph deltas as a float32 (targets, n, 3) array, one list per target, checked to have `n`
/// rows per target (and `targets` targets, when given) and finite values.
fn deltas(a: Option<PyReadonlyArray3<'_, f32>>, name: &str, n: usize, targets: Option<usize>) -> PyResult<Vec<Vec<[f32; 3]>>> {
    let Some(a) = a else { return Ok(Vec::new()) };
    let shape = a.shape();
    if shape[1] != n || shape[2] != 3 || targets.is_some_and(|t| t != shape[0]) {
        return Err(err(format!("{name} is {shape:?}, expected ({}, {n}, 3)", targets.map_or("targets".into(), |t| t.to_string()))));
    }
    let flat: Vec<f32> = a.as_array().iter().copied().collect();
    if flat.iter().any(|x| !x.is_finite()) {
        return Err(err(format!("{name}: a delta is not finite")));
    }
    Ok((0..shape[0]).map(|t| flat[3 * n * t..3 * n * (t + 1)].chunks_exact(3).map(|d| [d[0], d[1], d[2]]).collect()).collect())
}

/// Per-target lists as a float32 (targets, n, 3) array, or None when there are no targets.
fn deltas_array<'py>(py: Python<'py>, d: Vec<Vec<[f32; 3]>>, n: usize) -> PyResult<Option<Bound<'py, PyArray3<f32>>>> {
    if d.is_empty() {
        return Ok(None);
    }
    let t = d.len();
    Ok(Some(PyArray1::from_vec(py, d.into_iter().flatten().flatten().collect()).reshape([t, n, 3])?))
}

/// The attribute-carrying and error-measuring side of the LOD stage, on its own thread (see
/// `cook_core::lod::Chain` and `asset_pipeline.lod`): levels go in with `submit` as they are
/// simplified, `finish` returns them split, with attributes and errors.
///
/// `LodChain(positions0 float32 (n0, 3), triangles0 uint32 (m0, 3), keys0 uint32 (m0,),
/// attributes0 {name: array} as ir.ATTRIBUTES, near0 uint32 (w,), measure: bool,
/// sample_spacing: float, min_subdiv: int, morph_positions0=None, morph_normals0=None)`.
/// `near0`: a LOD 0 face around each vertex of LOD 0's welded level. `morph_positions0` /
/// `morph_normals0`: LOD 0's morph deltas, float32 (targets, n0, 3) (normals only with
/// positions); each level gets its own, and its error is the largest of the rest pose and each
/// target at weight 1.
#[pyclass(name = "LodChain", module = "asset_pipeline._core")]
pub struct PyLodChain {
    chain: Option<lod::Chain>,
    lod0_faces: u32,
    vertices: usize, // vertices of the level submitted last (survivors index it)
}

#[pymethods]
impl PyLodChain {
    #[new]
    #[pyo3(signature = (positions0, triangles0, keys0, attributes0, near0, measure, sample_spacing, min_subdiv, morph_positions0=None, morph_normals0=None))]
    #[allow(clippy::too_many_arguments)]
    fn new<'py>(
        positions0: PyReadonlyArray2<'py, f32>,
        triangles0: PyReadonlyArray2<'py, u32>,
        keys0: PyReadonlyArray1<'py, u32>,
        attributes0: &Bound<'py, PyDict>,
        near0: PyReadonlyArray1<'py, u32>,
        measure: bool,
        sample_spacing: f64,
        min_subdiv: u32,
        morph_positions0: Option<PyReadonlyArray3<'py, f32>>,
        morph_normals0: Option<PyReadonlyArray3<'py, f32>>,
    ) -> PyResult<Self> {
        let (positions, triangles) = (rows3(&positions0, "positions0")?.into_owned(), rows3(&triangles0, "triangles0")?.into_owned());
        measure::check_mesh(&positions, &triangles).map_err(|e| err(format!("LOD 0: {e}")))?;
        let (keys, near0) = (vec1(&keys0).into_owned(), vec1(&near0).into_owned());
        let m0 = triangles.len() as u32;
        if keys.len() != triangles.len() || near0.iter().any(|&f| f >= m0) {
            return Err(err("need one key per LOD 0 face and valid near0 faces".into()));
        }
        for key in attributes0.keys() {
            let name: String = key.extract()?;
            if !["position", "normal", "tangent", "uv0", "uv1", "color", "joints", "weights"].contains(&name.as_str()) {
                return Err(err(format!("unknown attribute {name:?}")));
            }
        }
        let n = positions.len();
        let attributes = Attributes {
            normal: attribute(attributes0, "normal", n)?,
            tangent: attribute(attributes0, "tangent", n)?,
            uv0: attribute(attributes0, "uv0", n)?,
            uv1: attribute(attributes0, "uv1", n)?,
            color: attribute(attributes0, "color", n)?,
            joints: attribute(attributes0, "joints", n)?,
            weights: attribute(attributes0, "weights", n)?,
        };
        let morph_positions = deltas(morph_positions0, "morph_positions0", n, None)?;
        if morph_positions.is_empty() && morph_normals0.is_some() {
            return Err(err("morph_normals0 without morph_positions0".into()));
        }
        let morphs = Morphs { normals: deltas(morph_normals0, "morph_normals0", n, Some(morph_positions.len()))?, positions: morph_positions };
        let settings = measure.then_some(ErrorSettings { sample_spacing, min_subdiv, max_samples: 50_000_000 });
        let vertices = near0.len();
        let lod0 = Lod0Data { positions, triangles, keys, attributes, morphs };
        Ok(PyLodChain { chain: Some(lod::Chain::start(lod0, near0, settings)), lod0_faces: m0, vertices })
    }

    /// Queue a simplified level: `points` float32 (n, 3), `faces` uint32 (m, 3), `face_origin`
    /// uint32 (m,), `seamy` bool (n,), `survivor` uint32 (n,) (vertices of the level before).
    fn submit<'py>(
        &mut self,
        points: PyReadonlyArray2<'py, f32>,
        faces: PyReadonlyArray2<'py, u32>,
        face_origin: PyReadonlyArray1<'py, u32>,
        seamy: PyReadonlyArray1<'py, bool>,
        survivor: PyReadonlyArray1<'py, u32>,
    ) -> PyResult<()> {
        let job = Job {
            points: rows3(&points, "points")?.into_owned(),
            faces: rows3(&faces, "faces")?.into_owned(),
            face_origin: vec1(&face_origin).into_owned(),
            seamy: vec1(&seamy).into_owned(),
            survivor: vec1(&survivor).into_owned(),
        };
        let n = job.points.len();
        if job.faces.iter().flatten().any(|&v| v as usize >= n) || job.face_origin.len() != job.faces.len() || job.face_origin.iter().any(|&f| f >= self.lod0_faces) {
            return Err(err("faces or face_origin out of range".into()));
        }
        if job.seamy.len() != n || job.survivor.len() != n || job.survivor.iter().any(|&s| s as usize >= self.vertices) {
            return Err(err("need one seamy flag and one survivor (a vertex of the level before) per point".into()));
        }
        if job.points.iter().flatten().any(|x| !x.is_finite()) {
            return Err(err("a point is not finite".into()));
        }
        let chain = self.chain.as_ref().ok_or_else(|| err("the chain is finished".into()))?;
        self.vertices = n;
        chain.submit(job);
        Ok(())
    }

    /// Block (without the GIL) until every level submitted so far is carried and measured.
    fn wait(&self, py: Python<'_>) {
        if let Some(chain) = self.chain.as_ref() {
            py.detach(|| chain.wait());
        }
    }

    /// Errors of the levels finished so far, in order.
    fn errors(&self) -> Vec<f64> {
        self.chain.as_ref().map(|c| c.errors()).unwrap_or_default()
    }

    /// Wait for every level: a list of `(attributes {name: array} incl. position, triangles
    /// uint32 (m, 3), error, morph_positions, morph_normals)`, the morph deltas float32
    /// (targets, n, 3) like LOD 0's, or None where LOD 0 has none.
    #[allow(clippy::type_complexity)]
    fn finish<'py>(&mut self, py: Python<'py>) -> PyResult<Vec<(Bound<'py, PyDict>, Bound<'py, PyArray2<u32>>, f64, Option<Bound<'py, PyArray3<f32>>>, Option<Bound<'py, PyArray3<f32>>>)>> {
        let chain = self.chain.take().ok_or_else(|| err("the chain is finished".into()))?;
        let levels = py.detach(|| chain.finish()).map_err(err)?;
        levels
            .into_iter()
            .map(|c| {
                let d = PyDict::new(py);
                let n = c.positions.len();
                d.set_item("position", array2(py, c.positions)?)?;
                let a = c.attributes;
                set(&d, "normal", a.normal)?;
                set(&d, "tangent", a.tangent)?;
                set(&d, "uv0", a.uv0)?;
                set(&d, "uv1", a.uv1)?;
                set(&d, "color", a.color)?;
                set(&d, "joints", a.joints)?;
                set(&d, "weights", a.weights)?;
                let (mp, mn) = (deltas_array(py, c.morphs.positions, n)?, deltas_array(py, c.morphs.normals, n)?);
                Ok((d, array2(py, c.triangles)?, c.error, mp, mn))
            })
            .collect()
    }
}

/// LOD 0 welded by position (see `cook_core::lod::weld`): `positions` float32 (n, 3), `triangles`
/// uint32 (m, 3). Returns `(points float32 (w, 3), faces uint32 (k, 3), face_origin uint32 (k,),
/// seamy bool (w,), seams uint32 (s, 2), near uint32 (w,), diagonal float)`.
#[pyfunction]
#[allow(clippy::type_complexity)]
fn weld_lod0<'py>(
    py: Python<'py>,
    positions: PyReadonlyArray2<'py, f32>,
    triangles: PyReadonlyArray2<'py, u32>,
) -> PyResult<(Bound<'py, PyArray2<f32>>, Bound<'py, PyArray2<u32>>, Bound<'py, PyArray1<u32>>, Bound<'py, PyArray1<bool>>, Bound<'py, PyArray2<u32>>, Bound<'py, PyArray1<u32>>, f64)> {
    let (pos, tri) = (rows3(&positions, "positions")?, rows3(&triangles, "triangles")?);
    measure::check_mesh(&pos, &tri).map_err(|e| err(format!("LOD 0: {e}")))?;
    let w = py.detach(|| lod::weld(&pos, &tri));
    Ok((array2(py, w.points)?, array2(py, w.faces)?, PyArray1::from_vec(py, w.face_origin), PyArray1::from_vec(py, w.seamy), array2(py, w.seams)?, PyArray1::from_vec(py, w.near), w.diagonal))
}

/// Where a simplification took a level (see `cook_core::lod::track_collapses`): `faces` uint32
/// (M, 3) as given to fast-simplification (`real` real faces, then flaps), its `collapses` uint32
/// (c, 2) and output `out_faces` uint32 (k, 3), the level's `seamy` bool (n,) and `seams` uint32
/// (e, 2). Returns `(faces uint32 (m, 3), kept uint32 (m,), rows uint32 (v,), seamy bool (v,),
/// seams uint32 (s, 2), survivor uint32 (v,))`.
#[pyfunction]
#[allow(clippy::type_complexity)]
fn track_collapses<'py>(
    py: Python<'py>,
    faces: PyReadonlyArray2<'py, u32>,
    real: usize,
    collapses: PyReadonlyArray2<'py, u32>,
    out_faces: PyReadonlyArray2<'py, u32>,
    seamy: PyReadonlyArray1<'py, bool>,
    seams: PyReadonlyArray2<'py, u32>,
) -> PyResult<(Bound<'py, PyArray2<u32>>, Bound<'py, PyArray1<u32>>, Bound<'py, PyArray1<u32>>, Bound<'py, PyArray1<bool>>, Bound<'py, PyArray2<u32>>, Bound<'py, PyArray1<u32>>)> {
    let (faces, out_faces) = (rows3(&faces, "faces")?, rows3(&out_faces, "out_faces")?);
    let (collapses, seams) = (rows::<u32, 2>(&collapses, "collapses")?, rows::<u32, 2>(&seams, "seams")?);
    let seamy = vec1(&seamy);
    let n = seamy.len() as u32;
    if real > faces.len() || faces[..real].iter().flatten().chain(seams.iter().flatten()).any(|&i| i >= n) {
        return Err(PyValueError::new_err("track_collapses: real faces or seams refer to vertices past seamy"));
    }
    let t: Tracked = py.detach(|| lod::track_collapses(&faces, real, &collapses, &out_faces, &seamy, &seams)).map_err(|e| PyValueError::new_err(format!("lod: {e}")))?;
    Ok((array2(py, t.faces)?, PyArray1::from_vec(py, t.kept), PyArray1::from_vec(py, t.rows), PyArray1::from_vec(py, t.seamy), array2(py, t.seams)?, PyArray1::from_vec(py, t.survivor)))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyLodChain>()?;
    m.add_function(wrap_pyfunction!(weld_lod0, m)?)?;
    m.add_function(wrap_pyfunction!(track_collapses, m)?)?;
    Ok(())
}
