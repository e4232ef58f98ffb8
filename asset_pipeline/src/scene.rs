//! Scene IR crossing: glTF import into, and pack writing from, Python's `asset_pipeline.ir`.
//! Arrays cross as (numpy dtype string, shape, bytes); see `cook_core::wire`.

use crate::{raise, summary};
use cook_core::wire::{self, RawArray};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};
use std::ffi::OsString;
use std::path::PathBuf;

type PyArrays<'py> = Vec<(String, Vec<usize>, Bound<'py, PyBytes>)>;

/// Import a .gltf/.glb file: returns (json, arrays, files): the scene for
/// `asset_pipeline.ir.from_wire`, and every file the import read (the glTF first, then its
/// external buffers and images, canonical, without duplicates). External buffers and images
/// must lie in `root` (default: the glTF's folder) unless `allow_external_uris`.
#[pyfunction]
#[pyo3(signature = (source, root=None, allow_external_uris=false))]
fn import_gltf<'py>(py: Python<'py>, source: PathBuf, root: Option<PathBuf>, allow_external_uris: bool) -> PyResult<(String, PyArrays<'py>, Vec<OsString>)> {
    let options = cook_core::ImportOptions { root, allow_external_uris };
    let imported = py.detach(|| cook_core::import_gltf(&source, &options, &mut |_, _| {})).map_err(raise)?;
    let (json, arrays) = py.detach(|| wire::to_wire(&imported.scene));
    let arrays = arrays.into_iter().map(|a| (a.dtype, a.shape, PyBytes::new(py, &a.bytes))).collect();
    // As str (OsString converts losslessly, as os.fsdecode would).
    let files = imported.files.into_iter().map(PathBuf::into_os_string).collect();
    Ok((json, arrays, files))
}

/// Write the pack for a scene given in wire form (from `asset_pipeline.ir.to_wire`) to `out`,
/// atomically; returns the pack's summary. Errors name the scene's source file.
#[pyfunction]
fn write_pack(py: Python<'_>, json: &str, arrays: Vec<(String, Vec<usize>, Vec<u8>)>, out: PathBuf) -> PyResult<Py<PyDict>> {
    let raw: Vec<RawArray> = arrays.into_iter().map(|(dtype, shape, bytes)| RawArray { dtype, shape, bytes }).collect();
    let written = py.detach(|| -> Result<_, cook_core::CookError> {
        let scene = wire::from_wire(json, &raw).map_err(|e| cook_core::CookError::Invalid { file: out.display().to_string(), problem: e })?;
        let pack = cook_core::build_pack(&scene)?;
        let bytes = cook_core::write_pack(&pack, &out)?;
        Ok((pack, bytes))
    });
    let (pack, bytes) = written.map_err(raise)?;
    summary(py, &cook_core::Summary::of(&pack, bytes))
}

/// Decode a PNG or JPEG file: returns (width, height, RGBA8 bytes).
#[pyfunction]
fn decode_image<'py>(py: Python<'py>, path: PathBuf) -> PyResult<(u32, u32, Bound<'py, PyBytes>)> {
    let (w, h, rgba) = py.detach(|| cook_core::decode_image(&path)).map_err(raise)?;
    Ok((w, h, PyBytes::new(py, &rgba)))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(import_gltf, m)?)?;
    m.add_function(wrap_pyfunction!(write_pack, m)?)?;
    m.add_function(wrap_pyfunction!(decode_image, m)?)?;
    Ok(())
}
