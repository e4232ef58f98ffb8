//! Python face of `cook_core::lod_carry`: one call per LOD level, run without the GIL (so the LOD
//! stage can carry one level's attributes while fast-simplification, which holds the GIL, makes
//! the next level).

use crate::measure::{rows, rows3, vec1};
use cook_core::lod_carry::{self, Level, Lod0, Sources};
use cook_core::measure::{self, NO_FACE};
use numpy::{Element, PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

fn err(msg: String) -> PyErr {
    PyValueError::new_err(format!("carry_attributes: {msg}"))
}

fn array2<'py, T: Element + Copy, const W: usize>(py: Python<'py>, rows: Vec<[T; W]>) -> PyResult<Bound<'py, PyArray2<T>>> {
    let n = rows.len();
    Ok(PyArray1::from_vec(py, rows.into_iter().flatten().collect()).reshape([n, W])?)
}

/// A level's split vertices and attributes (see `cook_core::lod_carry` and `asset_pipeline.lod`).
///
/// LOD 0: `positions0` float32 (n0, 3), `triangles0` uint32 (m0, 3), `adjacency0` uint32 (m0, 3)
/// (from `face_adjacency`), `attributes0` {name: array} as `ir.ATTRIBUTES` (position is ignored).
/// The welded level: `points` float32 (n, 3), `faces` uint32 (m, 3), `face_origin` uint32 (m,),
/// `seamy` bool (n,), `near` uint32 (n,).
///
/// Returns `(attributes, triangles uint32 (m, 3), source uint32 (k,), near uint32 (n,))`: the
/// output's attributes (position included), its triangles, the LOD 0 face each output vertex lies
/// on, and where each level vertex's walk ended.
#[pyfunction]
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
fn carry_attributes<'py>(
    py: Python<'py>,
    positions0: PyReadonlyArray2<'py, f32>,
    triangles0: PyReadonlyArray2<'py, u32>,
    adjacency0: PyReadonlyArray2<'py, u32>,
    attributes0: &Bound<'py, PyDict>,
    points: PyReadonlyArray2<'py, f32>,
    faces: PyReadonlyArray2<'py, u32>,
    face_origin: PyReadonlyArray1<'py, u32>,
    seamy: PyReadonlyArray1<'py, bool>,
    near: PyReadonlyArray1<'py, u32>,
) -> PyResult<(Bound<'py, PyDict>, Bound<'py, PyArray2<u32>>, Bound<'py, PyArray1<u32>>, Bound<'py, PyArray1<u32>>)> {
    let (pos0, tri0, adj0) = (rows3(&positions0, "positions0")?, rows3(&triangles0, "triangles0")?, rows3(&adjacency0, "adjacency0")?);
    let (pts, fcs) = (rows3(&points, "points")?, rows3(&faces, "faces")?);
    let (origin, seamy, near) = (vec1(&face_origin), vec1(&seamy), vec1(&near));
    measure::check_mesh(&pos0, &tri0).map_err(|e| err(format!("LOD 0: {e}")))?;
    let (n0, m0, n) = (pos0.len(), tri0.len() as u32, pts.len());
    if adj0.len() != tri0.len() || adj0.iter().flatten().any(|&f| f != NO_FACE && f >= m0) {
        return Err(err("adjacency0 does not fit triangles0".into()));
    }
    if fcs.iter().flatten().any(|&v| v as usize >= n) || origin.len() != fcs.len() || origin.iter().any(|&f| f >= m0) {
        return Err(err("faces or face_origin out of range".into()));
    }
    if seamy.len() != n || near.len() != n || near.iter().any(|&f| f >= m0) {
        return Err(err("need one seamy flag and one near face (a valid index) per point".into()));
    }
    if pts.iter().flatten().any(|x| !x.is_finite()) {
        return Err(err("a point is not finite".into()));
    }
    // Attributes by kind, checked for one row per LOD 0 vertex.
    let get = |name: &str| attributes0.get_item(name);
    macro_rules! attr {
        ($name:expr, $t:ty, $w:expr) => {
            match get($name)? {
                None => None,
                Some(a) => {
                    let a: PyReadonlyArray2<'py, $t> = a.extract().map_err(|_| err(format!("{} must be a {}-column {} array", $name, $w, stringify!($t))))?;
                    Some(a)
                }
            }
        };
    }
    for key in attributes0.keys() {
        let name: String = key.extract()?;
        if !["position", "normal", "tangent", "uv0", "uv1", "color", "joints", "weights"].contains(&name.as_str()) {
            return Err(err(format!("unknown attribute {name:?}")));
        }
    }
    let (normal, tangent, uv0, uv1) = (attr!("normal", f32, 3), attr!("tangent", f32, 4), attr!("uv0", f32, 2), attr!("uv1", f32, 2));
    let (color, joints, weights) = (attr!("color", u8, 4), attr!("joints", u16, 4), attr!("weights", f32, 4));
    let normal = normal.as_ref().map(|a| rows::<f32, 3>(a, "normal")).transpose()?;
    let tangent = tangent.as_ref().map(|a| rows::<f32, 4>(a, "tangent")).transpose()?;
    let uv0 = uv0.as_ref().map(|a| rows::<f32, 2>(a, "uv0")).transpose()?;
    let uv1 = uv1.as_ref().map(|a| rows::<f32, 2>(a, "uv1")).transpose()?;
    let color = color.as_ref().map(|a| rows::<u8, 4>(a, "color")).transpose()?;
    let joints = joints.as_ref().map(|a| rows::<u16, 4>(a, "joints")).transpose()?;
    let weights = weights.as_ref().map(|a| rows::<f32, 4>(a, "weights")).transpose()?;
    let lens = [
        normal.as_ref().map(|a| a.len()),
        tangent.as_ref().map(|a| a.len()),
        uv0.as_ref().map(|a| a.len()),
        uv1.as_ref().map(|a| a.len()),
        color.as_ref().map(|a| a.len()),
        joints.as_ref().map(|a| a.len()),
        weights.as_ref().map(|a| a.len()),
    ];
    if lens.iter().flatten().any(|&l| l != n0) {
        return Err(err(format!("an attribute does not have one row per LOD 0 vertex ({n0})")));
    }

    struct Out {
        split: lod_carry::Split,
        normal: Option<Vec<[f32; 3]>>,
        tangent: Option<Vec<[f32; 4]>>,
        uv0: Option<Vec<[f32; 2]>>,
        uv1: Option<Vec<[f32; 2]>>,
        color: Option<Vec<[u8; 4]>>,
        joints: Option<Vec<[u16; 4]>>,
        weights: Option<Vec<[f32; 4]>>,
    }
    let mut out = py.detach(|| {
        let lod0 = Lod0 {
            positions: &pos0,
            triangles: &tri0,
            adjacency: &adj0,
        };
        let level = Level {
            points: &pts,
            faces: &fcs,
            face_origin: &origin,
            seamy: &seamy,
            near: &near,
        };
        let split = lod_carry::split(&lod0, &level);
        let src = Sources {
            triangles: &tri0,
            source: &split.source,
            bary: &split.bary,
        };
        let normal_out = normal.as_ref().map(|a| src.normals(a));
        let tangent_out = tangent.as_ref().map(|t| match &normal_out {
            Some(n) => src.tangents(t, n),
            None => src.interpolate(t),
        });
        let (joints_out, weights_out) = match (&joints, &weights) {
            (Some(j), Some(w)) => {
                let (j, w) = src.skin(j, w);
                (Some(j), Some(w))
            }
            (j, w) => (j.as_ref().map(|j| src.nearest(j)), w.as_ref().map(|w| src.nearest(w))),
        };
        Out {
            normal: normal_out,
            tangent: tangent_out,
            uv0: uv0.as_ref().map(|a| src.interpolate(a)),
            uv1: uv1.as_ref().map(|a| src.interpolate(a)),
            color: color.as_ref().map(|a| src.colors(a)),
            joints: joints_out,
            weights: weights_out,
            split,
        }
    });
    let dict = PyDict::new(py);
    // The input's attribute order.
    for key in attributes0.keys() {
        let name: String = key.extract()?;
        match name.as_str() {
            "position" => dict.set_item(&name, array2(py, std::mem::take(&mut out.split.positions))?)?,
            "normal" => dict.set_item(&name, array2(py, out.normal.take().unwrap())?)?,
            "tangent" => dict.set_item(&name, array2(py, out.tangent.take().unwrap())?)?,
            "uv0" => dict.set_item(&name, array2(py, out.uv0.take().unwrap())?)?,
            "uv1" => dict.set_item(&name, array2(py, out.uv1.take().unwrap())?)?,
            "color" => dict.set_item(&name, array2(py, out.color.take().unwrap())?)?,
            "joints" => dict.set_item(&name, array2(py, out.joints.take().unwrap())?)?,
            _ => dict.set_item(&name, array2(py, out.weights.take().unwrap())?)?,
        }
    }
    let split = out.split;
    Ok((dict, array2(py, split.triangles)?, PyArray1::from_vec(py, split.source), PyArray1::from_vec(py, split.near)))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(carry_attributes, m)?)?;
    Ok(())
}
