//! `asset_pipeline._core`: the Python face of `cook_core`. Only conversions live here; the
//! cooking, checks and writing are `cook_core`'s.

use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;

create_exception!(
    asset_pipeline,
    CookError,
    PyException,
    "A cook failed. str(e) is one line naming the file, the object and the problem."
);

pub(crate) fn raise(e: cook_core::CookError) -> PyErr {
    CookError::new_err(e.to_string())
}

/// Cook a .gltf/.glb file into a pack at `out` (written atomically) and return its summary.
/// `progress(what: str, fraction: float)` is called along the way; if it raises, the cook is
/// abandoned, nothing is written and its exception propagates.
#[pyfunction]
#[pyo3(signature = (source, out, progress=None))]
fn cook_gltf(py: Python<'_>, source: PathBuf, out: PathBuf, progress: Option<Py<PyAny>>) -> PyResult<Py<PyDict>> {
    cook_core::check_output(&out, &source).map_err(raise)?;
    let mut callback_error: Option<PyErr> = None;
    // Cook without the GIL; take it back only for the callback.
    let cooked = py.detach(|| {
        cook_core::cook_gltf(&source, &mut |what, fraction| {
            if let (Some(cb), None) = (&progress, &callback_error) {
                callback_error = Python::attach(|py| cb.call1(py, (what, fraction)).err());
            }
        })
    });
    if let Some(e) = callback_error {
        return Err(e);
    }
    let pack = cooked.map_err(raise)?;
    let bytes = py.detach(|| cook_core::write_pack(&pack, &out)).map_err(raise)?;
    summary(py, &cook_core::Summary::of(&pack, bytes))
}

/// Read and fully validate a pack; return the same summary `cook_gltf` does.
#[pyfunction]
fn read_pack_summary(py: Python<'_>, path: PathBuf) -> PyResult<Py<PyDict>> {
    let pack = py.detach(|| cook_core::read_pack(&path)).map_err(raise)?;
    let bytes = std::fs::metadata(&path).map(|m| m.len()).unwrap_or(0);
    summary(py, &cook_core::Summary::of(&pack, bytes))
}

/// `read_pack(path) -> (manifest JSON, data bytes)`: a pack read and validated once, its data
/// blob decoded (stored zstd-compressed) as the runtime holds it; `BufferRange`s index it.
#[pyfunction]
fn read_pack<'py>(py: Python<'py>, path: PathBuf) -> PyResult<(String, Bound<'py, pyo3::types::PyBytes>)> {
    let pack = py.detach(|| cook_core::read_pack(&path)).map_err(raise)?;
    let doc = serde_json::to_string(&pack.manifest).map_err(|e| pyo3::exceptions::PyValueError::new_err(e.to_string()))?;
    Ok((doc, pyo3::types::PyBytes::new(py, &pack.data)))
}

/// Read and fully validate a pack; return its manifest (meshes, materials, textures, nodes,
/// lights, ...; no bulk data) as JSON text. For tests and tools that inspect what was cooked.
#[pyfunction]
fn read_pack_manifest(py: Python<'_>, path: PathBuf) -> PyResult<String> {
    let pack = py.detach(|| cook_core::read_pack(&path)).map_err(raise)?;
    serde_json::to_string(&pack.manifest).map_err(|e| pyo3::exceptions::PyValueError::new_err(e.to_string()))
}

pub(crate) fn summary(py: Python<'_>, s: &cook_core::Summary) -> PyResult<Py<PyDict>> {
    let d = PyDict::new(py);
    d.set_item("meshes", s.meshes)?;
    d.set_item("submeshes", s.submeshes)?;
    d.set_item("vertices", s.vertices)?;
    d.set_item("indices", s.indices)?;
    d.set_item("triangles", s.triangles)?;
    d.set_item("materials", s.materials)?;
    d.set_item("textures", s.textures)?;
    d.set_item("texture_sizes", s.texture_sizes.clone())?;
    d.set_item("texture_mips", s.texture_mips.clone())?;
    d.set_item("nodes", s.nodes)?;
    d.set_item("lightmap_pages", s.lightmap_pages)?;
    d.set_item("lightmaps_baked", s.lightmaps_baked)?;
    d.set_item("probes", s.probes)?;
    d.set_item("bytes", s.bytes)?;
    Ok(d.unbind())
}

// Each area of the core has its own bindings module with a `register` function; add new ones
// here (one `mod` line and one `register` line).
mod scene;
mod uv_raster;
mod measure;
mod bake;
mod lightmap_post;
mod lod;
mod mips;
mod compress;
mod mesh_opt;

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("CookError", m.py().get_type::<CookError>())?;
    m.add("COOKER", cook_core::COOKER)?;
    m.add_function(wrap_pyfunction!(cook_gltf, m)?)?;
    m.add_function(wrap_pyfunction!(read_pack_summary, m)?)?;
    m.add_function(wrap_pyfunction!(read_pack_manifest, m)?)?;
    m.add_function(wrap_pyfunction!(read_pack, m)?)?;
    scene::register(m)?;
    uv_raster::register(m)?;
    measure::register(m)?;
    bake::register(m)?;
    lightmap_post::register(m)?;
    lod::register(m)?;
    mips::register(m)?;
    compress::register(m)?;
    mesh_opt::register(m)?;
    Ok(())
}
