//! Python face of `cook_core::compress`: one call compresses a texture's whole chain, without
//! the GIL (its levels in parallel strips).

use cook_core::compress::{self, Class, Effort, Quality, Texels};
use numpy::{IntoPyArray, PyReadonlyArray3, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// `compress_texture(levels, cls, effort="fast") -> (format, [blocks], quality)`: `levels` are a
/// texture's mip levels, level 0 first, each an (h, w, 4) C-contiguous uint8 array (uint16 for a
/// cooked normal map, float16 for hdr); `cls` is colour, data, occlusion, normal, hdr or
/// direction (see cook_core::compress). `format` is the pack's name of the result (Bc7Srgb,
/// Bc7Unorm, Bc4Unorm, Bc5Unorm, Bc6hUfloat), each `blocks` a 1-D uint8 array of one level's 4x4
/// blocks, `quality` {"psnr_db": ...}, {"mean_deg": ..., "p99_deg": ...} or {"median_rel": ...,
/// "p95_rel": ...} over all levels. Bad arguments raise ValueError.
#[pyfunction]
#[pyo3(signature = (levels, cls, effort="fast"))]
fn compress_texture<'py>(py: Python<'py>, levels: Vec<Bound<'py, PyAny>>, cls: &str, effort: &str) -> PyResult<(String, Vec<Py<PyAny>>, Bound<'py, PyDict>)> {
    let bad = |m: String| PyValueError::new_err(m);
    let class = Class::parse(cls).map_err(bad)?;
    let effort = Effort::parse(effort).map_err(bad)?;
    let Some(first) = levels.first() else { return Err(bad("no levels".into())) };
    // uint8, uint16 (UNORM) or float16 (hdr, as their bits), every level like level 0.
    let halves = first.getattr("dtype").and_then(|d| d.getattr("name")).and_then(|n| n.extract::<String>()).is_ok_and(|n| n == "float16");
    let (w8, w16): (Vec<PyReadonlyArray3<'py, u8>>, Vec<PyReadonlyArray3<'py, u16>>) = if first.extract::<PyReadonlyArray3<'py, u8>>().is_ok() {
        (levels.iter().map(|l| l.extract()).collect::<PyResult<_>>().map_err(|_| bad("every level must be an (h, w, 4) uint8 array like level 0".into()))?, vec![])
    } else if halves {
        let bits = levels
            .iter()
            .map(|l| l.call_method1("view", ("uint16",))?.extract())
            .collect::<PyResult<_>>()
            .map_err(|_| bad("every level must be an (h, w, 4) float16 array like level 0".into()))?;
        (vec![], bits)
    } else {
        (vec![], levels.iter().map(|l| l.extract()).collect::<PyResult<_>>().map_err(|_| bad("levels must be (h, w, 4) uint8, uint16 or float16 arrays".into()))?)
    };
    let shape0 = if w8.is_empty() { w16[0].shape().to_vec() } else { w8[0].shape().to_vec() };
    if shape0.len() != 3 || shape0[2] != 4 {
        return Err(bad(format!("level 0 has shape {shape0:?}, expected (h, w, 4)")));
    }
    let (width, height) = (shape0[1] as u32, shape0[0] as u32);
    let contiguous = || bad("levels must be C-contiguous".into());
    let texels: Vec<Texels> = if w8.is_empty() {
        let wrap = if halves { Texels::Half } else { Texels::Rgba16 };
        w16.iter().map(|a| a.as_slice().map(wrap).map_err(|_| contiguous())).collect::<PyResult<_>>()?
    } else {
        w8.iter().map(|a| a.as_slice().map(Texels::Rgba8).map_err(|_| contiguous())).collect::<PyResult<_>>()?
    };
    let c = py.detach(|| compress::compress(class, width, height, &texels, effort)).map_err(bad)?;
    let quality = PyDict::new(py);
    match c.quality {
        Quality::Psnr { db } => quality.set_item("psnr_db", db)?,
        Quality::Angle { mean, p99 } => {
            quality.set_item("mean_deg", mean)?;
            quality.set_item("p99_deg", p99)?;
        }
        Quality::Relative { median, p95 } => {
            quality.set_item("median_rel", median)?;
            quality.set_item("p95_rel", p95)?;
        }
    }
    let blocks = c.levels.into_iter().map(|b| b.into_pyarray(py).into_any().unbind()).collect();
    Ok((format!("{:?}", c.format), blocks, quality))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(compress_texture, m)?)?;
    Ok(())
}
