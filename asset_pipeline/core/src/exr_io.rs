//! Lightmap pages as OpenEXR files (the `exr` crate): linear HDR RGB stored as half floats.
//!
//! Images cross as flat row-major `f32` arrays of `height * width * 3` (row 0 first, as numpy's
//! (h, w, 3)). Writing is atomic: a temporary file beside the target, renamed into place, so a
//! failed write leaves neither a half-written page nor a stray temporary file.
//!
//! What a half float can hold decides what is written: values above 1 are kept as they are (HDR,
//! never clamped to [0, 1] or tone-mapped); negative values and NaN (a lightmap holds irradiance,
//! which is never negative; a denoiser can overshoot slightly below 0) become 0; values above the
//! largest finite half (65504) and +inf become 65504, so no texel is ever infinite.

use exr::prelude::{f16, read_first_rgba_layer_from_file, AnyChannel, AnyChannels, Encoding, FlatSamples, Image, Layer, LayerAttributes, RgbaChannels, SmallVec, SpecificChannels, Vec2, WritableImage};
use std::path::Path;

/// Largest finite half float: what out-of-range values are written as.
pub const HALF_MAX: f32 = 65504.0;

/// The value actually stored for `v` (before half rounding): see the module notes.
pub fn sanitise(v: f32) -> f32 {
    if v.is_nan() || v <= 0.0 {
        0.0
    } else {
        v.min(HALF_MAX)
    }
}

fn check(rgb: &[f32], width: usize, height: usize) -> Result<(), String> {
    if width == 0 || height == 0 {
        return Err(format!("empty image ({width} x {height})"));
    }
    if rgb.len() != width * height * 3 {
        return Err(format!("{} floats for a {width} x {height} RGB image (expected {})", rgb.len(), width * height * 3));
    }
    Ok(())
}

/// Write `rgb` (`height * width * 3` linear floats) as a half-float RGB OpenEXR file (ZIP
/// compression, scan lines), atomically.
pub fn write_exr(path: &Path, rgb: &[f32], width: usize, height: usize) -> Result<(), String> {
    let file = path.display().to_string();
    check(rgb, width, height).map_err(|e| format!("{file}: {e}"))?;
    let texel = |x: usize, y: usize| {
        let i = (y * width + x) * 3;
        (f16::from_f32(sanitise(rgb[i])), f16::from_f32(sanitise(rgb[i + 1])), f16::from_f32(sanitise(rgb[i + 2])))
    };
    let layer = Layer::new((width, height), LayerAttributes::default(), Encoding::SMALL_LOSSLESS, SpecificChannels::rgb(|Vec2(x, y)| texel(x, y)));
    write_atomically(path, |tmp| Image::from_layer(layer).write().to_file(tmp))
}

/// Write named half-float channels (each `height * width` linear floats, row 0 first, sanitised
/// as `write_exr`'s; OpenEXR's layer naming, "layer.R") as one OpenEXR image, atomically. A
/// directional lightmap page is one file this way, its b0 as the plain "R", "G", "B" that
/// viewers (and `read_exr`) show.
pub fn write_exr_channels(path: &Path, width: usize, height: usize, channels: &[(&str, &[f32])]) -> Result<(), String> {
    let file = path.display().to_string();
    if width == 0 || height == 0 || channels.is_empty() {
        return Err(format!("{file}: empty image ({width} x {height}, {} channels)", channels.len()));
    }
    if let Some((name, data)) = channels.iter().find(|(_, d)| d.len() != width * height) {
        return Err(format!("{file}: channel '{name}' has {} floats for a {width} x {height} image", data.len()));
    }
    let list: SmallVec<[AnyChannel<FlatSamples>; 4]> =
        channels.iter().map(|(name, data)| AnyChannel::new(*name, FlatSamples::F16(data.iter().map(|&v| f16::from_f32(sanitise(v))).collect()))).collect();
    let layer = Layer::new((width, height), LayerAttributes::default(), Encoding::SMALL_LOSSLESS, AnyChannels::sort(list));
    write_atomically(path, |tmp| Image::from_layer(layer).write().to_file(tmp))
}

/// `write(temporary path)` beside `path`, then renamed into place; on failure nothing is left.
fn write_atomically(path: &Path, write: impl FnOnce(&Path) -> exr::error::Result<()>) -> Result<(), String> {
    let file = path.display().to_string();
    let name = path.file_name().ok_or_else(|| format!("{file}: not a file path"))?;
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    if !dir.is_dir() {
        return Err(format!("{file}: output directory '{}' does not exist", dir.display()));
    }
    let tmp = dir.join(format!(".{}.{}.tmp", name.to_string_lossy(), std::process::id()));
    let written = write(&tmp).map_err(|e| format!("{file}: cannot write EXR: {e}"));
    let renamed = written.and_then(|_| std::fs::rename(&tmp, path).map_err(|e| format!("{file}: cannot rename into place: {e}")));
    if renamed.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    renamed
}

/// Read the first RGB(A) layer of an OpenEXR file: `(width, height, rgb)` with `rgb` row-major
/// `height * width * 3` f32 (alpha, if any, is dropped; missing channels read as 0).
pub fn read_exr(path: &Path) -> Result<(usize, usize, Vec<f32>), String> {
    let file = path.display().to_string();
    if !path.exists() {
        return Err(format!("{file}: not found"));
    }
    let image = read_first_rgba_layer_from_file(
        path,
        |size: Vec2<usize>, _: &RgbaChannels| (size.0, vec![0f32; size.0 * size.1 * 3]),
        |px: &mut (usize, Vec<f32>), pos: Vec2<usize>, (r, g, b, _a): (f32, f32, f32, f32)| {
            let i = (pos.1 * px.0 + pos.0) * 3;
            px.1[i] = r;
            px.1[i + 1] = g;
            px.1[i + 2] = b;
        },
    )
    .map_err(|e| format!("{file}: cannot read EXR: {e}"))?;
    let size = image.layer_data.size;
    Ok((size.0, size.1, image.layer_data.channel_data.pixels.1))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tmpdir(tag: &str) -> std::path::PathBuf {
        let d = std::env::temp_dir().join(format!("exr_io_{tag}_{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn round_trip_is_exact_to_half_precision_and_keeps_hdr() {
        let (w, h) = (7usize, 5usize);
        let rgb: Vec<f32> = (0..w * h * 3).map(|i| (i as f32 * 0.37).sin().abs() * 40.0 + if i % 11 == 0 { 3000.0 } else { 0.0 }).collect();
        let dir = tmpdir("rt");
        let p = dir.join("page.exr");
        write_exr(&p, &rgb, w, h).unwrap();
        let (rw, rh, back) = read_exr(&p).unwrap();
        assert_eq!((rw, rh), (w, h));
        for (a, b) in rgb.iter().zip(&back) {
            assert_eq!(f16::from_f32(*a).to_f32(), *b);
        }
        assert!(back.iter().any(|&v| v > 1000.0));
        // Only the page in the directory: no temporary left behind.
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);
        std::fs::remove_dir_all(dir).unwrap();
    }

    #[test]
    fn negatives_nan_and_overflow_are_sanitised() {
        let rgb = [-1.0, f32::NAN, 1e9, f32::INFINITY, 0.5, 2.0];
        let dir = tmpdir("san");
        let p = dir.join("s.exr");
        write_exr(&p, &rgb, 2, 1).unwrap();
        let (_, _, back) = read_exr(&p).unwrap();
        assert_eq!(back, vec![0.0, 0.0, HALF_MAX, HALF_MAX, 0.5, 2.0]);
        std::fs::remove_dir_all(dir).unwrap();
    }

    #[test]
    fn named_channels_round_trip_with_rgb_readable() {
        let (w, h) = (3usize, 2usize);
        let r: Vec<f32> = (0..6).map(|i| i as f32 * 100.0).collect();
        let ones = vec![1.0f32; 6];
        let q: Vec<f32> = (0..6).map(|i| 0.5 + i as f32).collect();
        let dir = tmpdir("chan");
        let p = dir.join("dir.exr");
        write_exr_channels(&p, w, h, &[("R", &r), ("G", &ones), ("B", &ones), ("qx.R", &q), ("sun.Y", &ones)]).unwrap();
        // The plain RGB is what read_exr (and any viewer) sees.
        let (_, _, back) = read_exr(&p).unwrap();
        assert_eq!(back.chunks(3).map(|c| c[0]).collect::<Vec<_>>(), r);
        let image = exr::prelude::read_all_flat_layers_from_file(&p).unwrap();
        let names: Vec<String> = image.layer_data[0].channel_data.list.iter().map(|c| c.name.to_string()).collect();
        assert_eq!(names, ["B", "G", "R", "qx.R", "sun.Y"]);
        let qx = &image.layer_data[0].channel_data.list[3].sample_data;
        assert_eq!((0..6).map(|i| qx.value_by_flat_index(i).to_f32()).collect::<Vec<_>>(), q);
        assert!(write_exr_channels(&p, w, h, &[("R", &r[..5])]).unwrap_err().contains("channel 'R' has 5 floats"));
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);
        std::fs::remove_dir_all(dir).unwrap();
    }

    #[test]
    fn bad_input_is_an_error_and_writes_nothing() {
        let dir = tmpdir("bad");
        assert!(write_exr(&dir.join("a.exr"), &[0.0; 5], 2, 1).is_err());
        assert!(write_exr(&dir.join("missing").join("a.exr"), &[0.0; 6], 2, 1).unwrap_err().contains("does not exist"));
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 0);
        std::fs::write(dir.join("junk.exr"), b"not an exr").unwrap();
        assert!(read_exr(&dir.join("junk.exr")).unwrap_err().contains("cannot read EXR"));
        std::fs::remove_dir_all(dir).unwrap();
    }
}
