//! Python face of `cook_core::bake`: `Baker` (a scene with its BVH; B = H/pi per surface point,
//! see `cook_core::bake::integrator`, irradiance probes, `cook_core::bake::probes`, and
//! reflection probes, `cook_core::bake::reflection`) and `trace_rays` (closest hits, for the
//! BVH benchmark).
//! Arrays are read in place and the work runs without the GIL.

use crate::measure::{rows, rows3, vec1};
use cook_core::bake::bvh::Bvh;
use cook_core::bake::integrator::{add_point_samples, add_texel_samples, bake_points, bake_points_directional, finish_point, finish_texel, BakeSettings, TexelSums};
use cook_core::bake::lights::Light;
use cook_core::bake::material::{Material, VertexAttributes};
use cook_core::bake::probes::bake_probes;
use cook_core::bake::reflection::{add_capture_samples, capture, finish_capture, prefilter, PREFILTER_SAMPLES};
use cook_core::bake::scene::{BakeScene, Geometry};
use cook_core::bake::textures::{Texture, TextureInfo};
use cook_core::bake::with_threads;
use numpy::{PyArray1, PyArray2, PyArray3, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3, PyReadwriteArray2, PyUntypedArrayMethods};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use std::borrow::Cow;
use std::sync::atomic::AtomicBool;

fn to_array<'py>(py: Python<'py>, rows: &[[f32; 3]]) -> Bound<'py, PyArray2<f32>> {
    let flat: Vec<f32> = rows.iter().flatten().copied().collect();
    PyArray1::from_vec(py, flat).reshape([rows.len(), 3]).expect("n*3 elements")
}

fn settings(preset: &str, seed: u64, samples: Option<u32>, bounces: Option<u32>, probe_samples: Option<u32>) -> PyResult<BakeSettings> {
    let mut s = BakeSettings::preset(preset, seed).ok_or_else(|| PyValueError::new_err(format!("bake: unknown preset '{preset}' (draft, medium, high)")))?;
    s.samples = samples.unwrap_or(s.samples);
    s.bounces = bounces.unwrap_or(s.bounces);
    s.probe_samples = probe_samples.unwrap_or(s.probe_samples);
    Ok(s)
}

fn ids_for<'a>(ids: &'a Option<PyReadonlyArray1<'_, u64>>, n: usize) -> PyResult<Option<Cow<'a, [u64]>>> {
    let ids = ids.as_ref().map(vec1);
    if ids.as_ref().is_some_and(|i| i.len() != n) {
        return Err(PyValueError::new_err(format!("bake: need one id per point ({n})")));
    }
    Ok(ids)
}

/// A static scene ready to bake (its BVH built once), its materials evaluated where rays hit
/// (see `cook_core::bake::material`).
///
/// `Baker(positions float32 (n, 3), triangles uint32 (m, 3), triangle_materials uint32 (m,),
/// uv0 float32 (n, 2) | None, texcoord1 float32 (n, 2) | None, colors uint8 (n, 4) | None,
/// materials_json, textures, textures_json, lights_json, sky)`: world-space triangles, each
/// with an index into `materials_json` (a JSON list of `ir.Material` dicts: base_color,
/// base_color_texture, base_color_uv, emissive (nits), emissive_texture, emissive_uv,
/// alpha_mode, alpha_cutoff, double_sided; texture indices into `textures`); per-vertex UV sets
/// and linear RGBA colours the materials read (None: absent); `textures` a list of uint8
/// (h, w, 4) level-0 images, rows top to bottom, described by `textures_json` (a JSON list, one
/// `{"name", "format": "Rgba8Srgb" | "Rgba8Unorm", "sampler": ir.Texture.sampling}` each);
/// `lights_json` a JSON list of `ir.Light` dicts; `sky` a uniform radiance (r, g, b) in nits
/// (colour x intensity) or None. Presets draft | medium | high, with `samples`, `bounces`,
/// `probe_samples` overriding them; the same seed gives the same result for any `threads`
/// (None: all cores) and any batching (random streams are keyed by the `ids` given per point).
#[pyclass(frozen, name = "Baker", module = "asset_pipeline._core")]
pub struct PyBaker {
    scene: BakeScene,
}

#[pymethods]
impl PyBaker {
    #[new]
    #[allow(clippy::too_many_arguments)]
    fn new<'py>(
        py: Python<'py>,
        positions: PyReadonlyArray2<'py, f32>,
        triangles: PyReadonlyArray2<'py, u32>,
        triangle_materials: PyReadonlyArray1<'py, u32>,
        uv0: Option<PyReadonlyArray2<'py, f32>>,
        texcoord1: Option<PyReadonlyArray2<'py, f32>>,
        colors: Option<PyReadonlyArray2<'py, u8>>,
        materials_json: &str,
        textures: Vec<PyReadonlyArray3<'py, u8>>,
        textures_json: &str,
        lights_json: &str,
        sky: Option<(f32, f32, f32)>,
    ) -> PyResult<Self> {
        let bad = |e: String| PyValueError::new_err(format!("bake: {e}"));
        let (pos, tri) = (rows3(&positions, "positions")?, rows3(&triangles, "triangles")?);
        let mats = vec1(&triangle_materials);
        let uv0 = uv0.as_ref().map(|a| rows::<f32, 2>(a, "uv0")).transpose()?;
        let uv1 = texcoord1.as_ref().map(|a| rows::<f32, 2>(a, "texcoord1")).transpose()?;
        let col = colors.as_ref().map(|a| rows::<u8, 4>(a, "colors")).transpose()?;
        let infos: Vec<TextureInfo> = serde_json::from_str(textures_json).map_err(|e| bad(format!("textures JSON: {e}")))?;
        if infos.len() != textures.len() {
            return Err(bad(format!("{} textures but {} texture descriptions", textures.len(), infos.len())));
        }
        let mut images = Vec::with_capacity(textures.len());
        for (info, t) in infos.iter().zip(&textures) {
            let shape = t.shape();
            if shape[2] != 4 {
                return Err(bad(format!("texture '{}' has shape {shape:?}, expected (h, w, 4)", info.name)));
            }
            let rgba = |flat: &[u8]| flat.chunks_exact(4).map(|c| [c[0], c[1], c[2], c[3]]).collect();
            let texels = match t.as_slice() {
                Ok(flat) => rgba(flat),
                Err(_) => rgba(&t.as_array().iter().copied().collect::<Vec<u8>>()),
            };
            images.push(Texture::from_info(info, shape[1], shape[0], texels).map_err(bad)?);
        }
        let materials = Material::from_ir_json(materials_json, images.len()).map_err(bad)?;
        let lights = Light::from_ir_json(lights_json).map_err(PyValueError::new_err)?;
        let attributes = VertexAttributes { uv0: uv0.as_deref(), texcoord1: uv1.as_deref(), color: col.as_deref() };
        let geometry = Geometry { positions: &pos, triangles: &tri, materials: &mats, attributes };
        let scene = py.detach(|| BakeScene::new(geometry, materials, images, lights, sky.map(|(r, g, b)| [r, g, b]))).map_err(bad)?;
        Ok(PyBaker { scene })
    }

    /// B = H/pi (nits, linear RGB; runtime shading is L_e + albedo * B) at `points` with unit
    /// `normals` (float32 (k, 3)); `ids` uint64 (k,) key each point's random streams (default:
    /// 0..k). Returns `(B float32 (k, 3), rays cast)`. With `directional`, a directional
    /// lightmap's texels instead (see `cook_core::bake::integrator::DirectionalTexel`):
    /// `(float32 (k, 13), rays cast)`, per point b0 (r, g, b), b1 of r (x, y, z), of g, of b
    /// (nits; all light but the sun's direct light, B(n) = b0 + b1.n per channel), and the
    /// sun's visibility.
    #[pyo3(signature = (points, normals, ids=None, preset="medium", seed=0, samples=None, bounces=None, threads=None, directional=false))]
    #[allow(clippy::too_many_arguments)]
    fn bake_points<'py>(
        &self,
        py: Python<'py>,
        points: PyReadonlyArray2<'py, f32>,
        normals: PyReadonlyArray2<'py, f32>,
        ids: Option<PyReadonlyArray1<'py, u64>>,
        preset: &str,
        seed: u64,
        samples: Option<u32>,
        bounces: Option<u32>,
        threads: Option<usize>,
        directional: bool,
    ) -> PyResult<(Bound<'py, PyArray2<f32>>, u64)> {
        let s = settings(preset, seed, samples, bounces, None)?;
        let (pts, nrm) = (rows3(&points, "points")?, rows3(&normals, "normals")?);
        if pts.len() != nrm.len() {
            return Err(PyValueError::new_err(format!("bake_points: {} points but {} normals", pts.len(), nrm.len())));
        }
        let ids = ids_for(&ids, pts.len())?;
        let cancel = AtomicBool::new(false);
        let cancelled = |_| PyRuntimeError::new_err("bake cancelled");
        if !directional {
            let out = py.detach(|| with_threads(threads, || bake_points(&self.scene, &pts, &nrm, ids.as_deref(), &s, &|_, _| {}, &cancel)));
            let baked = out.map_err(PyRuntimeError::new_err)?.map_err(cancelled)?;
            return Ok((to_array(py, &baked.b), baked.rays));
        }
        let out = py.detach(|| with_threads(threads, || bake_points_directional(&self.scene, &pts, &nrm, ids.as_deref(), &s, &|_, _| {}, &cancel)));
        let baked = out.map_err(PyRuntimeError::new_err)?.map_err(cancelled)?;
        let flat: Vec<f32> = baked.texels.iter().flat_map(|t| t.b0.into_iter().chain(t.b1.into_iter().flatten()).chain([t.sun_visibility])).collect();
        Ok((PyArray1::from_vec(py, flat).reshape([baked.texels.len(), 13])?, baked.rays))
    }

    /// Irradiance probes at `points` (float32 (k, 3), see `cook_core::bake::probes`): returns
    /// `(sh float32 (k, 9, 3) (B = E/pi, without the sun's direct light), sun_visibility float32
    /// (k,), backface float32 (k,), rays cast)`.
    #[pyo3(signature = (points, ids=None, preset="medium", seed=0, probe_samples=None, bounces=None, threads=None))]
    #[allow(clippy::too_many_arguments, clippy::type_complexity)]
    fn bake_probes<'py>(
        &self,
        py: Python<'py>,
        points: PyReadonlyArray2<'py, f32>,
        ids: Option<PyReadonlyArray1<'py, u64>>,
        preset: &str,
        seed: u64,
        probe_samples: Option<u32>,
        bounces: Option<u32>,
        threads: Option<usize>,
    ) -> PyResult<(Bound<'py, PyArray3<f32>>, Bound<'py, PyArray1<f32>>, Bound<'py, PyArray1<f32>>, u64)> {
        let s = settings(preset, seed, None, bounces, probe_samples)?;
        let pts = rows3(&points, "points")?;
        let ids = ids_for(&ids, pts.len())?;
        let cancel = AtomicBool::new(false);
        let out = py.detach(|| with_threads(threads, || bake_probes(&self.scene, &pts, ids.as_deref(), &s, &|_, _| {}, &cancel)));
        let (probes, rays) = out.map_err(PyRuntimeError::new_err)?.map_err(|_| PyRuntimeError::new_err("bake cancelled"))?;
        let k = probes.len();
        let sh: Vec<f32> = probes.iter().flat_map(|p| p.sh.iter().flatten().copied()).collect();
        Ok((
            PyArray1::from_vec(py, sh).reshape([k, 9, 3])?,
            PyArray1::from_vec(py, probes.iter().map(|p| p.sun_visibility).collect()),
            PyArray1::from_vec(py, probes.iter().map(|p| p.backface).collect()),
            rays,
        ))
    }

    /// A reflection probe at `position` (see `cook_core::bake::reflection`): the radiance cube
    /// seen from there, `face_size`² texels a face (a power of two), path-traced with `samples`
    /// rays a texel (None: the preset's, draft 16, medium 32, high 128) and `bounces`, then
    /// prefiltered into `levels` mips (level k: roughness k / (levels - 1)). Returns `(radiance
    /// float32 (T, 3), rays cast)`, rows [level][face +X -X +Y -Y +Z -Z][row from the top]
    /// [column], nits, the sun's disc left out. `id` keys the probe's random streams.
    #[pyo3(signature = (position, id=0, face_size=128, levels=6, preset="medium", seed=0, samples=None, bounces=None, threads=None))]
    #[allow(clippy::too_many_arguments)]
    fn bake_reflection_probe<'py>(
        &self,
        py: Python<'py>,
        position: [f32; 3],
        id: u64,
        face_size: usize,
        levels: usize,
        preset: &str,
        seed: u64,
        samples: Option<u32>,
        bounces: Option<u32>,
        threads: Option<usize>,
    ) -> PyResult<(Bound<'py, PyArray2<f32>>, u64)> {
        let s = settings(preset, seed, None, bounces, None)?;
        let samples = samples.unwrap_or(match preset {
            "draft" => 16,
            "medium" => 32,
            _ => 128,
        });
        if !face_size.is_power_of_two() || !(4..=2048).contains(&face_size) {
            return Err(PyValueError::new_err(format!("reflection probe: face_size {face_size} is not a power of two in 4..2048")));
        }
        let max_levels = face_size.trailing_zeros() as usize + 1;
        if !(1..=max_levels).contains(&levels) {
            return Err(PyValueError::new_err(format!("reflection probe: {levels} levels for a {face_size}-texel face (1..{max_levels})")));
        }
        if !position.iter().all(|v| v.is_finite()) {
            return Err(PyValueError::new_err(format!("reflection probe: position {position:?} is not finite")));
        }
        let cancel = AtomicBool::new(false);
        let out = py.detach(|| {
            with_threads(threads, || {
                capture(&self.scene, position, id, face_size, samples, s.bounces, s.seed, &|_, _| {}, &cancel).map(|(cube, rays)| (prefilter(&cube, levels, PREFILTER_SAMPLES), rays))
            })
        });
        let (cubes, rays) = out.map_err(PyRuntimeError::new_err)?.map_err(|_| PyRuntimeError::new_err("bake cancelled"))?;
        let rows: Vec<[f32; 3]> = cubes.into_iter().flat_map(|c| c.texels).collect();
        Ok((to_array(py, &rows), rays))
    }

    /// Refinement (`cook --watch`): the samples `start..end` of every point added to its running
    /// sums `sums` (float64, updated in place: (k, 3) for `bake_points`' B, (k, 13) with
    /// `directional`: b0's then b1's sums and the sun samples that saw the sun), as
    /// `bake_points` draws them. `finish_samples` then gives what `bake_points` with `samples`
    /// = end gives, to the bit, whatever steps the samples came in. Returns the rays cast.
    #[pyo3(signature = (points, normals, sums, start, end, ids=None, preset="medium", seed=0, bounces=None, threads=None, directional=false))]
    #[allow(clippy::too_many_arguments)]
    fn add_samples<'py>(
        &self,
        py: Python<'py>,
        points: PyReadonlyArray2<'py, f32>,
        normals: PyReadonlyArray2<'py, f32>,
        mut sums: PyReadwriteArray2<'py, f64>,
        start: u32,
        end: u32,
        ids: Option<PyReadonlyArray1<'py, u64>>,
        preset: &str,
        seed: u64,
        bounces: Option<u32>,
        threads: Option<usize>,
        directional: bool,
    ) -> PyResult<u64> {
        let s = settings(preset, seed, Some(end), bounces, None)?;
        let (pts, nrm) = (rows3(&points, "points")?, rows3(&normals, "normals")?);
        let width = if directional { SUMS_DIRECTIONAL } else { 3 };
        if pts.len() != nrm.len() || sums.shape() != [pts.len(), width] || start > end {
            return Err(PyValueError::new_err(format!(
                "add_samples: {} points, {} normals, sums of shape {:?} (expected ({}, {width})), samples {start}..{end}",
                pts.len(), nrm.len(), sums.shape(), pts.len()
            )));
        }
        let ids = ids_for(&ids, pts.len())?;
        let flat = sums.as_slice_mut().map_err(|_| PyValueError::new_err("add_samples: sums must be a C-contiguous float64 array"))?;
        let cancel = AtomicBool::new(false);
        let quiet = |_: u64, _: u64| {};
        let out = py.detach(|| {
            with_threads(threads, || {
                if directional {
                    let mut acc: Vec<TexelSums> = flat.chunks_exact(SUMS_DIRECTIONAL).map(texel_sums).collect();
                    let rays = add_texel_samples(&self.scene, &pts, &nrm, ids.as_deref(), &s, start..end, &mut acc, &quiet, &cancel);
                    for (row, a) in flat.chunks_exact_mut(SUMS_DIRECTIONAL).zip(&acc) {
                        row.copy_from_slice(&texel_row(a));
                    }
                    rays
                } else {
                    let acc: &mut [[f64; 3]] = bytemuck::cast_slice_mut(flat);
                    add_point_samples(&self.scene, &pts, &nrm, ids.as_deref(), &s, start..end, acc, &quiet, &cancel)
                }
            })
        });
        out.map_err(PyRuntimeError::new_err)?.map_err(|_| PyRuntimeError::new_err("bake cancelled"))
    }

    /// What `bake_points` returns for these points with `samples` samples, from their sums of
    /// that many (`add_samples`): float32 (k, 3), or (k, 13) with `directional`.
    #[pyo3(signature = (points, normals, sums, samples, directional=false))]
    fn finish_samples<'py>(
        &self,
        py: Python<'py>,
        points: PyReadonlyArray2<'py, f32>,
        normals: PyReadonlyArray2<'py, f32>,
        sums: PyReadonlyArray2<'py, f64>,
        samples: u32,
        directional: bool,
    ) -> PyResult<Bound<'py, PyArray2<f32>>> {
        let (pts, nrm) = (rows3(&points, "points")?, rows3(&normals, "normals")?);
        let width = if directional { SUMS_DIRECTIONAL } else { 3 };
        if pts.len() != nrm.len() || sums.shape() != [pts.len(), width] {
            return Err(PyValueError::new_err(format!("finish_samples: {} points, {} normals, sums of shape {:?}", pts.len(), nrm.len(), sums.shape())));
        }
        let flat = sums.as_slice().map_err(|_| PyValueError::new_err("finish_samples: sums must be a C-contiguous float64 array"))?;
        if !directional {
            let rows: Vec<[f32; 3]> = flat.chunks_exact(3).map(|v| finish_point(&[v[0], v[1], v[2]], samples)).collect();
            return Ok(to_array(py, &rows));
        }
        let out: Vec<f32> = flat
            .chunks_exact(SUMS_DIRECTIONAL)
            .zip(pts.iter().zip(nrm.iter()))
            .flat_map(|(row, (&x, &n))| {
                let t = finish_texel(&self.scene, &texel_sums(row), samples, x, n);
                t.b0.into_iter().chain(t.b1.into_iter().flatten()).chain([t.sun_visibility])
            })
            .collect();
        Ok(PyArray1::from_vec(py, out).reshape([pts.len(), 13])?)
    }

    /// Refinement of a reflection probe (as `add_samples`): its capture's samples `start..end`
    /// added to the cube texels' sums (float64 (6 face_size², 3), in place). Returns the rays.
    #[pyo3(signature = (position, id, face_size, sums, start, end, preset="medium", seed=0, bounces=None, threads=None))]
    #[allow(clippy::too_many_arguments)]
    fn add_reflection_samples<'py>(
        &self,
        py: Python<'py>,
        position: [f32; 3],
        id: u64,
        face_size: usize,
        mut sums: PyReadwriteArray2<'py, f64>,
        start: u32,
        end: u32,
        preset: &str,
        seed: u64,
        bounces: Option<u32>,
        threads: Option<usize>,
    ) -> PyResult<u64> {
        let s = settings(preset, seed, None, bounces, None)?;
        if sums.shape() != [6 * face_size * face_size, 3] || start > end || !position.iter().all(|v| v.is_finite()) {
            return Err(PyValueError::new_err(format!(
                "add_reflection_samples: sums of shape {:?} for a {face_size}-texel face, samples {start}..{end}, position {position:?}",
                sums.shape()
            )));
        }
        let flat = sums.as_slice_mut().map_err(|_| PyValueError::new_err("add_reflection_samples: sums must be a C-contiguous float64 array"))?;
        let acc: &mut [[f64; 3]] = bytemuck::cast_slice_mut(flat);
        let cancel = AtomicBool::new(false);
        let out = py.detach(|| with_threads(threads, || add_capture_samples(&self.scene, position, id, face_size, start..end, s.bounces, s.seed, acc, &|_, _| {}, &cancel)));
        out.map_err(PyRuntimeError::new_err)?.map_err(|_| PyRuntimeError::new_err("bake cancelled"))
    }

    /// What `bake_reflection_probe` returns (its first part) from the capture's sums of
    /// `samples` samples.
    fn finish_reflection<'py>(&self, py: Python<'py>, sums: PyReadonlyArray2<'py, f64>, samples: u32, face_size: usize, levels: usize) -> PyResult<Bound<'py, PyArray2<f32>>> {
        if sums.shape() != [6 * face_size * face_size, 3] || !(1..=face_size.trailing_zeros() as usize + 1).contains(&levels) {
            return Err(PyValueError::new_err(format!("finish_reflection: sums of shape {:?}, face {face_size}, {levels} levels", sums.shape())));
        }
        let flat = sums.as_slice().map_err(|_| PyValueError::new_err("finish_reflection: sums must be a C-contiguous float64 array"))?;
        let cube = finish_capture(bytemuck::cast_slice(flat), face_size, samples);
        let cubes = py.detach(|| prefilter(&cube, levels, PREFILTER_SAMPLES));
        let rows: Vec<[f32; 3]> = cubes.into_iter().flat_map(|c| c.texels).collect();
        Ok(to_array(py, &rows))
    }
}

/// Columns of a directional texel's sums in `Baker.add_samples`: L/p (3), L w/p (3 x 3), sun seen.
const SUMS_DIRECTIONAL: usize = 13;

fn texel_sums(row: &[f64]) -> TexelSums {
    TexelSums {
        l: [row[0], row[1], row[2]],
        lw: std::array::from_fn(|c| [row[3 + 3 * c], row[4 + 3 * c], row[5 + 3 * c]]),
        // Exact: a count far below 2^53.
        sun_seen: row[12] as u32,
    }
}

fn texel_row(a: &TexelSums) -> [f64; SUMS_DIRECTIONAL] {
    let mut r = [0.0; SUMS_DIRECTIONAL];
    r[..3].copy_from_slice(&a.l);
    for c in 0..3 {
        r[3 + 3 * c..6 + 3 * c].copy_from_slice(&a.lw[c]);
    }
    r[12] = a.sun_seen as f64;
    r
}

/// `(samples, probe_samples, bounces)` of a bake preset (draft | medium | high): what `Baker`'s
/// methods use where their arguments say None.
#[pyfunction]
fn bake_preset(preset: &str) -> PyResult<(u32, u32, u32)> {
    let s = settings(preset, 0, None, None, None)?;
    Ok((s.samples, s.probe_samples, s.bounces))
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
            // The build runs on the same pool as the rays (it is parallel too).
            with_threads(threads, || Bvh::build(&pos, &tri).closest_many(&org, &dir))
        })
        .map_err(PyValueError::new_err)?;
    Ok((PyArray1::from_vec(py, t), PyArray1::from_vec(py, id)))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyBaker>()?;
    m.add_function(wrap_pyfunction!(trace_rays, m)?)?;
    m.add_function(wrap_pyfunction!(bake_preset, m)?)?;
    Ok(())
}
