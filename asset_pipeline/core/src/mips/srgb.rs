//! The sRGB transfer functions (IEC 61966-2-1; FCG 4th ed. L12401-12405), exact to the byte.

use std::sync::OnceLock;

pub fn decode(v: f64) -> f64 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

pub fn encode(c: f64) -> f64 {
    if c <= 0.0031308 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

struct Tables {
    /// Linear value of each byte.
    decode: [f32; 256],
    /// `threshold[k]`: the linear value that encodes to exactly (k + 0.5) / 255, where
    /// rounding moves from byte k to k + 1.
    threshold: [f32; 255],
    /// A first guess for `encode_byte`: the byte of the start of each of `COARSE` bins of [0, 1].
    /// Bins are narrow enough (the steepest slope, 12.92 * 255 / 65536, is 0.05 bytes per bin)
    /// that at most one threshold falls inside one.
    coarse: Vec<u8>,
}

const COARSE: usize = 1 << 16;

fn tables() -> &'static Tables {
    static T: OnceLock<Tables> = OnceLock::new();
    T.get_or_init(|| {
        let decode = std::array::from_fn(|k| self::decode(k as f64 / 255.0) as f32);
        let threshold: [f32; 255] = std::array::from_fn(|k| self::decode((k as f64 + 0.5) / 255.0) as f32);
        let mut coarse = Vec::with_capacity(COARSE);
        let mut byte = 0usize;
        for b in 0..COARSE {
            let x = b as f32 / COARSE as f32;
            while byte < 255 && x >= threshold[byte] {
                byte += 1;
            }
            coarse.push(byte as u8);
        }
        Tables { decode, threshold, coarse }
    })
}

/// The linear value of an sRGB byte.
#[inline]
pub fn decode_byte(b: u8) -> f32 {
    tables().decode[b as usize]
}

/// The byte nearest (in sRGB code values) to the linear value `c`, clamped to [0, 1]: the one
/// rounding of the pipeline. Exact: the same byte as `round(255 * encode(c))`, in a table
/// lookup and one comparison.
#[inline]
pub fn encode_byte(c: f32) -> u8 {
    let t = tables();
    if !(c > 0.0) {
        return 0; // and NaN
    }
    if c >= 1.0 {
        return 255;
    }
    let b = t.coarse[(c * COARSE as f32) as usize];
    if b < 255 && c >= t.threshold[b as usize] {
        b + 1
    } else {
        b
    }
}

/// The full decode table, for loops that want it in hand.
pub fn decode_table() -> &'static [f32; 256] {
    &tables().decode
}
