//! Python face of `cook_core::bake`: `bake_points` (B = H/pi per surface point, see
//! `cook_core::bake::integrator`) and `trace_rays` (closest hits, for the BVH benchmark).
//! Arrays are read in place and the work runs without the GIL.

use crate::measure::rows3;
use cook_core::bake::bvh::Bvh;
use cook_core::bake::integrator::{bake_points as bake, BakeScene, BakeSettings};
use cook_core::bake::lights::Light;
use numpy::{PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray2};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use cook_core::bake::with_threads;
use std::sync::atomic::AtomicBool;

fn to_array<'py>(py: Python<'py>, rows: &[[f32; 3]]) -> Bound<'py, PyArray2<f32>> {
    let flat: Vec<f32> = rows.iter().flatten().copied().collect();
    PyArray1::from_vec(py, flat).reshape([rows.len(), 3]).expect("n*3 elements")
}

/// Bake B = H/pi (nits, linear RGB; runtime shading is L_e + albedo * B) at `points` with unit
/// `normals` (float32 (k, 3)) over the scene `positions` float32 (n, 3), `triangles` uint32 (m, 3),
/// per-triangle `albedo` and front-face `emission` (nits) float32 (m, 3). `lights_json`: a JSON
/// list of `ir.Light` dicts; `sky`: uniform sky radiance (r, g, b) in nits (colour * intensity)
/// or None. `preset` draft | medium | high; `samples` / `bounces` override it. Same seed, same
/// result for any `threads` (None: all cores). Returns float32 (k, 3).
#[pyfunction]
#[pyo3(signature = (positions, triangles, albedo, emission, lights_json, sky, points, normals, preset="medium", seed=0, samples=None, bounces=None, threads=None))]
#[allow(clippy::too_many_arguments)]
fn bake_points<'py>(
    py: Python<'py>,
    positions: PyReadonlyArray2<'py, f32>,
    triangles: PyReadonlyArray2<'py, u32>,
    albedo: PyReadonlyArray2<'py, f32>,
    emission: PyReadonlyArray2<'py, f32>,
    lights_json: &str,
    sky: Option<(f32, f32, f32)>,
    points: PyReadonlyArray2<'py, f32>,
    normals: PyReadonlyArray2<'py, f32>,
    preset: &str,
    seed: u64,
    samples: Option<u32>,
    bounces: Option<u32>,
    threads: Option<usize>,
) -> PyResult<Bound<'py, PyArray2<f32>>> {
    let mut settings = BakeSettings::preset(preset, seed)
        .ok_or_else(|| PyValueError::new_err(format!("bake_points: unknown preset '{preset}' (draft, medium, high)")))?;
    settings.samples = samples.unwrap_or(settings.samples);
    settings.bounces = bounces.unwrap_or(settings.bounces);
    let (pos, tri) = (rows3(&positions, "positions")?, rows3(&triangles, "triangles")?);
    let (alb, emi) = (rows3(&albedo, "albedo")?, rows3(&emission, "emission")?);
    let (pts, nrm) = (rows3(&points, "points")?, rows3(&normals, "normals")?);
    if pts.len() != nrm.len() {
        return Err(PyValueError::new_err(format!("bake_points: {} points but {} normals", pts.len(), nrm.len())));
    }
    let lights = Light::from_ir_json(lights_json).map_err(PyValueError::new_err)?;
    let cancel = AtomicBool::new(false);
    let out = py.detach(|| {
        let scene = BakeScene::new(&pos, &tri, &alb, &emi, lights, sky.map(|(r, g, b)| [r, g, b]))?;
        // No progress or cancel from Python yet (the core API has both).
        with_threads(threads, || bake(&scene, &pts, &nrm, &settings, &|_, _| {}, &cancel))
    });
    match out.map_err(|e| PyValueError::new_err(format!("bake_points: {e}")))? {
        Ok(baked) => Ok(to_array(py, &baked.b)),
        Err(_) => Err(PyRuntimeError::new_err("bake cancelled")),
    }
}

/// Closest hits of rays (`origins`, `directions` float32 (k, 3), t in (0, inf)) against the
/// triangles: `(t float32 (k,) (inf on a miss), triangle uint32 (k,) (0xFFFFFFFF on a miss))`.
/// The BVH build is not timed separately; see tools/bench_bvh.py for rays/s.
#[pyfunction]
#[pyo3(signature = (positions, triangles, origins, directions, threads=None))]
fn trace_rays<'py>(
    py: Python<'py>,
    positions: PyReadonlyArray2<'py, f32>,
    triangles: PyReadonlyArray2<'py, u32>,
    origins: PyReadonlyArray2<'py, f32>,
    directions: PyReadonlyArray2<'py, f32>,
    threads: Option<usize>,
) -> PyResult<(Bound<'py, PyArray1<f32>>, Bound<'py, PyArray1<u32>>)> {
    let (pos, tri) = (rows3(&positions, "positions")?, rows3(&triangles, "triangles")?);
    let (org, dir) = (rows3(&origins, "origins")?, rows3(&directions, "directions")?);
    if org.len() != dir.len() {
        return Err(PyValueError::new_err(format!("trace_rays: {} origins but {} directions", org.len(), dir.len())));
    }
    if tri.iter().flatten().any(|&v| v as usize >= pos.len()) {
        return Err(PyValueError::new_err("trace_rays: a triangle indexes past the positions"));
    }
    let (t, id) = py
        .detach(|| {
            let bvh = Bvh::build(&pos, &tri);
            with_threads(threads, || bvh.closest_many(&org, &dir))
        })
        .map_err(PyValueError::new_err)?;
    Ok((PyArray1::from_vec(py, t), PyArray1::from_vec(py, id)))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(bake_points, m)?)?;
    m.add_function(wrap_pyfunction!(trace_rays, m)?)?;
    Ok(())
}
