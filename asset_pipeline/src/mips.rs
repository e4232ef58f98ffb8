//! Python face of `cook_core::mips`: one call makes a texture's whole chain, without the GIL.

use cook_core::mips::{self, Edge, Filter, MipSettings, Usage};
use numpy::ndarray::Array3;
use numpy::{IntoPyArray, PyReadonlyArray3, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

/// Levels 1.. of a texture (level 0 is the input itself), each (h, w, 4) of the input's dtype.
///
/// `mip_chain(level0, usage, filter=None, edge="wrap", alpha_cutoff=None)`: `level0` is an
/// (h, w, 4) C-contiguous array, uint8 for usage "color" (sRGB), "data" or "normal", or the
/// float16 bits viewed as uint16 for "hdr". `filter`: box, tent, bspline, mitchell,
/// catmull-rom, lanczos3 (default: mitchell, tent for hdr). `edge`: how taps past the edge read,
/// as the runtime's sampler: wrap (repeating), clamp or mirror, for both axes or per axis
/// ("wrap,clamp": along the width, then the height). `alpha_cutoff`: keep alpha-test coverage at every level (color only). Bad arguments
/// raise ValueError with a one-line message.
#[pyfunction]
#[pyo3(signature = (level0, usage, filter=None, edge="wrap", alpha_cutoff=None))]
fn mip_chain(py: Python<'_>, level0: &Bound<'_, PyAny>, usage: &str, filter: Option<&str>, edge: &str, alpha_cutoff: Option<f32>) -> PyResult<Vec<Py<PyAny>>> {
    let bad = |m: String| PyValueError::new_err(m);
    let usage = Usage::parse(usage).map_err(bad)?;
    let settings = MipSettings {
        usage,
        filter: filter.map(Filter::parse).transpose().map_err(bad)?.unwrap_or(usage.default_filter()),
        edges: Edge::parse_axes(edge).map_err(bad)?,
        alpha_cutoff,
    };
    let sizes = |w: usize, h: usize| (1..mips::level_count(w as u32, h as u32)).map(move |l| mips::level_size(w as u32, h as u32, l));
    if usage == Usage::Hdr {
        let a: PyReadonlyArray3<'_, u16> = level0.extract().map_err(|_| bad("hdr level 0 must be an (h, w, 4) float16 array viewed as uint16".into()))?;
        let (w, h) = shape(a.shape())?;
        let texels = a.as_slice().map_err(|_| bad("level 0 must be C-contiguous".into()))?;
        let levels = py.detach(|| mips::mips_rgba16f(w as u32, h as u32, texels, &settings)).map_err(bad)?;
        return levels.into_iter().zip(sizes(w, h)).map(|(v, (w, h))| array(py, v, w, h)).collect();
    }
    let a: PyReadonlyArray3<'_, u8> = level0.extract().map_err(|_| bad(format!("{} level 0 must be an (h, w, 4) uint8 array", usage.name())))?;
    let (w, h) = shape(a.shape())?;
    let texels = a.as_slice().map_err(|_| bad("level 0 must be C-contiguous".into()))?;
    let levels = py.detach(|| mips::mips_rgba8(w as u32, h as u32, texels, &settings)).map_err(bad)?;
    levels.into_iter().zip(sizes(w, h)).map(|(v, (w, h))| array(py, v, w, h)).collect()
}

/// Every level of a normal map, level 0 included, as (h, w, 4) uint16 (16-bit UNORM, the
/// pack's Rgba16Unorm): `normal_chain(level0, filter=None, edge="wrap")`. `level0` is an
/// (h, w, 4) C-contiguous uint8 or uint16 UNORM array (rgb = n * 0.5 + 0.5, alpha is data).
/// The vectors are filtered, then every texel of every level is renormalised to unit length.
#[pyfunction]
#[pyo3(signature = (level0, filter=None, edge="wrap"))]
fn normal_chain(py: Python<'_>, level0: &Bound<'_, PyAny>, filter: Option<&str>, edge: &str) -> PyResult<Vec<Py<PyAny>>> {
    let bad = |m: String| PyValueError::new_err(m);
    let settings = MipSettings {
        usage: Usage::Normal,
        filter: filter.map(Filter::parse).transpose().map_err(bad)?.unwrap_or(Usage::Normal.default_filter()),
        edges: Edge::parse_axes(edge).map_err(bad)?,
        alpha_cutoff: None,
    };
    let levels = if let Ok(a) = level0.extract::<PyReadonlyArray3<'_, u8>>() {
        let (w, h) = shape(a.shape())?;
        let texels = a.as_slice().map_err(|_| bad("level 0 must be C-contiguous".into()))?;
        (w, h, py.detach(|| mips::normal_levels(w as u32, h as u32, mips::NormalTexels::Unorm8(texels), &settings)).map_err(bad)?)
    } else if let Ok(a) = level0.extract::<PyReadonlyArray3<'_, u16>>() {
        let (w, h) = shape(a.shape())?;
        let texels = a.as_slice().map_err(|_| bad("level 0 must be C-contiguous".into()))?;
        (w, h, py.detach(|| mips::normal_levels(w as u32, h as u32, mips::NormalTexels::Unorm16(texels), &settings)).map_err(bad)?)
    } else {
        return Err(bad("normal map level 0 must be an (h, w, 4) uint8 or uint16 array".into()));
    };
    let (w, h, levels) = levels;
    levels.into_iter().enumerate().map(|(l, v)| {
        let (lw, lh) = mips::level_size(w as u32, h as u32, l as u32);
        array(py, v, lw, lh)
    }).collect()
}

fn shape(s: &[usize]) -> PyResult<(usize, usize)> {
    if s[2] != 4 || s[0] == 0 || s[1] == 0 || s[0] > 1 << 16 || s[1] > 1 << 16 {
        return Err(PyValueError::new_err(format!("level 0 has shape {s:?}, expected (h, w, 4) with 1 <= w, h <= 65536")));
    }
    Ok((s[1], s[0]))
}

fn array<T: numpy::Element>(py: Python<'_>, v: Vec<T>, w: u32, h: u32) -> PyResult<Py<PyAny>> {
    let a = Array3::from_shape_vec((h as usize, w as usize, 4), v).map_err(|e| PyValueError::new_err(e.to_string()))?;
    Ok(a.into_pyarray(py).into_any().unbind())
}

/// Every level of texture `index` in the pack at `path`: `(format, [level arrays])`, each
/// (h, w, 4) uint8, float16 for Rgba16Float, uint16 for Rgba16Unorm; a block-compressed level
/// decoded (pack::bc) to (h, w, c) uint8, c = 4 for BC7, 2 for BC5, 1 for BC4; BC6H to (h, w, 4)
/// float16, alpha 1. For tests and tools.
#[pyfunction]
fn read_pack_texture(py: Python<'_>, path: std::path::PathBuf, index: usize) -> PyResult<(String, Vec<Py<PyAny>>)> {
    let pack = py.detach(|| cook_core::read_pack(&path)).map_err(crate::raise)?;
    let t = pack.manifest.textures.get(index).ok_or_else(|| PyValueError::new_err(format!("{}: texture {index} does not exist", path.display())))?;
    let mut levels = Vec::with_capacity(t.mips.len());
    for (l, r) in t.mips.iter().enumerate() {
        let (w, h) = mips::level_size(t.width, t.height, l as u32);
        let bytes = pack.bytes(*r).to_vec();
        levels.push(match t.format {
            pack::TextureFormat::Rgba16Float => {
                let bits: Vec<u16> = bytes.chunks_exact(2).map(|b| u16::from_le_bytes([b[0], b[1]])).collect();
                let a = array(py, bits, w, h)?;
                a.call_method1(py, "view", ("float16",))?
            }
            pack::TextureFormat::Rgba16Unorm => array(py, bytes.chunks_exact(2).map(|b| u16::from_le_bytes([b[0], b[1]])).collect::<Vec<u16>>(), w, h)?,
            pack::TextureFormat::Rgba8Srgb | pack::TextureFormat::Rgba8Unorm => array(py, bytes, w, h)?,
            f => decoded_array(py, f, w, h, &bytes).map_err(|_| PyValueError::new_err(format!("{}: texture {index} mip {l}: bad blocks", path.display())))?,
        });
    }
    Ok((format!("{:?}", t.format), levels))
}

/// One compressed level decoded (pack::bc): (h, w, c) uint8, or (h, w, 4) float16 for BC6H.
fn decoded_array(py: Python<'_>, f: pack::TextureFormat, w: u32, h: u32, blocks: &[u8]) -> PyResult<Py<PyAny>> {
    let texels = pack::bc::decode(f, w, h, blocks).ok_or_else(|| PyValueError::new_err(format!("{} bytes are not a {w}x{h} {f:?} level", blocks.len())))?;
    if f.decoded() == Some(pack::bc::Decoded::Rgba16F) {
        let bits: Vec<u16> = texels.chunks_exact(2).map(|b| u16::from_le_bytes([b[0], b[1]])).collect();
        return array(py, bits, w, h)?.call_method1(py, "view", ("float16",));
    }
    let channels = f.decoded().map_or(4, |d| d.channels());
    let a = Array3::from_shape_vec((h as usize, w as usize, channels), texels).map_err(|e| PyValueError::new_err(e.to_string()))?;
    Ok(a.into_pyarray(py).into_any().unbind())
}

/// `decode_blocks(format, width, height, blocks) -> array`: one level of a block-compressed
/// format (the pack's name, e.g. "Bc6hUfloat") decoded as `read_pack_texture` decodes it; e.g. a
/// face of a BC6H reflection cube. ValueError for an unknown or plain format or a wrong length.
#[pyfunction]
fn decode_blocks(py: Python<'_>, format: &str, width: u32, height: u32, blocks: Vec<u8>) -> PyResult<Py<PyAny>> {
    let f: pack::TextureFormat = serde_json::from_value(serde_json::Value::String(format.into())).map_err(|_| PyValueError::new_err(format!("unknown texture format '{format}'")))?;
    if !f.is_compressed() {
        return Err(PyValueError::new_err(format!("{format} is not block-compressed")));
    }
    decoded_array(py, f, width, height, &blocks)
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(decode_blocks, m)?)?;
    m.add_function(wrap_pyfunction!(mip_chain, m)?)?;
    m.add_function(wrap_pyfunction!(normal_chain, m)?)?;
    m.add_function(wrap_pyfunction!(read_pack_texture, m)?)?;
    Ok(())
}
