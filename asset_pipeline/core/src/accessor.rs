//! Accessors, checked before a single element is read.
//!
//! `check` proves that every byte an accessor (and its sparse part) refers to lies inside its
//! buffer view and buffer, and that its type is one the semantic allows. Only a `Checked` can be
//! decoded, so decoding never indexes out of bounds and never reads one type as another.

use gltf::accessor::{Accessor, DataType, Dimensions};

/// An upper bound on elements per accessor. Views bound real data by the file's size, but a
/// sparse accessor without a view declares its count freely; this keeps a bad count from
/// becoming a multi-gigabyte allocation.
const MAX_ELEMENTS: usize = 1 << 26;

/// The storage a semantic allows (glTF 2.0 spec, "Meshes" / "Accessor data types").
pub(crate) struct Expect {
    dims: &'static [Dimensions],
    types: &'static [DataType],
}

use DataType::{F32, I16, I8, U16, U32, U8};
pub(crate) const VEC3_F32: Expect = Expect { dims: &[Dimensions::Vec3], types: &[F32] };
pub(crate) const VEC4_F32: Expect = Expect { dims: &[Dimensions::Vec4], types: &[F32] };
pub(crate) const TEXCOORD: Expect = Expect { dims: &[Dimensions::Vec2], types: &[F32, U8, U16] };
pub(crate) const COLOR: Expect = Expect { dims: &[Dimensions::Vec3, Dimensions::Vec4], types: &[F32, U8, U16] };
pub(crate) const INDICES: Expect = Expect { dims: &[Dimensions::Scalar], types: &[U8, U16, U32] };
pub(crate) const JOINTS: Expect = Expect { dims: &[Dimensions::Vec4], types: &[U8, U16] };
pub(crate) const WEIGHTS: Expect = Expect { dims: &[Dimensions::Vec4], types: &[F32, U8, U16] };
pub(crate) const MAT4_F32: Expect = Expect { dims: &[Dimensions::Mat4], types: &[F32] };
pub(crate) const KEY_TIMES: Expect = Expect { dims: &[Dimensions::Scalar], types: &[F32] };
pub(crate) const ROTATIONS: Expect = Expect { dims: &[Dimensions::Vec4], types: &[F32, I8, U8, I16, U16] };
pub(crate) const MORPH_WEIGHTS: Expect = Expect { dims: &[Dimensions::Scalar], types: &[F32, I8, U8, I16, U16] };

/// An accessor whose data has been bounds- and type-checked.
pub(crate) struct Checked<'a> {
    pub count: usize,
    dims: usize,
    ty: DataType,
    normalized: bool,
    /// Bytes from the first element on, and the stride between elements. `None`: all zeros.
    base: Option<(&'a [u8], usize)>,
    /// Sparse substitutions: target element indices (strictly increasing, < count) and their
    /// tightly packed values.
    sparse: Option<(Vec<u32>, &'a [u8])>,
}

/// Check `acc`, used as `role` (e.g. "NORMAL"), against the buffers. Errors name the accessor.
pub(crate) fn check<'a>(acc: &Accessor, buffers: &'a [Vec<u8>], role: &str, expect: &Expect) -> Result<Checked<'a>, String> {
    let label = format!("accessor {} ({role})", acc.index());
    let (ty, dim) = (acc.data_type(), acc.dimensions());
    if !expect.dims.contains(&dim) || !expect.types.contains(&ty) {
        let want: Vec<String> = expect.dims.iter().map(|d| dim_name(*d).to_string()).collect();
        return Err(format!(
            "{label} is {} of {ty:?}, expected {} of {:?}",
            dim_name(dim),
            want.join(" or "),
            expect.types
        ));
    }
    let count = acc.count();
    if count == 0 {
        return Err(format!("{label} has no elements (count 0)"));
    }
    if count > MAX_ELEMENTS {
        return Err(format!("{label} has {count} elements, more than the cooker's limit of {MAX_ELEMENTS}"));
    }
    let elem = acc.size();
    let base = match acc.view() {
        Some(view) => {
            let stride = view.stride().unwrap_or(elem);
            if stride < elem {
                return Err(format!("{label}: buffer view {} has stride {stride}, less than the {elem}-byte element", view.index()));
            }
            let bytes = view_bytes(&view, buffers)?;
            Some((span(&label, view.index(), bytes, acc.offset(), stride, count, elem)?, stride))
        }
        None if acc.sparse().is_some() => None,
        None => return Err(format!("{label} has no buffer view (compressed or extension data is not supported)")),
    };
    let sparse = match acc.sparse() {
        None => None,
        Some(sp) => {
            let n = sp.count();
            if n == 0 || n > count {
                return Err(format!("{label}: sparse count {n} is not in 1..={count}"));
            }
            let (iv, vv) = (sp.indices(), sp.values());
            let isize = iv.index_type().size();
            let ibytes = span(&format!("{label} sparse indices"), iv.view().index(), view_bytes(&iv.view(), buffers)?, iv.offset(), isize, n, isize)?;
            let vbytes = span(&format!("{label} sparse values"), vv.view().index(), view_bytes(&vv.view(), buffers)?, vv.offset(), elem, n, elem)?;
            let mut targets = Vec::with_capacity(n);
            for k in 0..n {
                let b = &ibytes[k * isize..];
                let t = match isize {
                    1 => b[0] as u32,
                    2 => u16::from_le_bytes([b[0], b[1]]) as u32,
                    _ => u32::from_le_bytes([b[0], b[1], b[2], b[3]]),
                };
                if t as usize >= count {
                    return Err(format!("{label}: sparse index {k} is {t}, past the accessor's {count} elements"));
                }
                if targets.last().is_some_and(|&prev| t <= prev) {
                    return Err(format!("{label}: sparse indices are not strictly increasing (index {k} is {t})"));
                }
                targets.push(t);
            }
            Some((targets, vbytes))
        }
    };
    Ok(Checked { count, dims: dim.multiplicity(), ty, normalized: acc.normalized(), base, sparse })
}

/// The bytes of a buffer view, after checking the view lies inside its buffer.
pub(crate) fn view_bytes<'a>(view: &gltf::buffer::View, buffers: &'a [Vec<u8>]) -> Result<&'a [u8], String> {
    let (buffer, start, len) = (view.buffer(), view.offset(), view.length());
    let end = start as u128 + len as u128;
    let outside = || {
        format!(
            "buffer view {} (bytes {start}..{end}) does not fit in buffer {} ({} bytes)",
            view.index(),
            buffer.index(),
            buffer.length()
        )
    };
    if end > buffer.length() as u128 {
        return Err(outside());
    }
    buffers.get(buffer.index()).and_then(|b| b.get(start..start + len)).ok_or_else(outside)
}

/// The part of a view holding `count` elements of `elem` bytes, `stride` apart, from `offset`.
fn span<'a>(label: &str, view: usize, bytes: &'a [u8], offset: usize, stride: usize, count: usize, elem: usize) -> Result<&'a [u8], String> {
    let needs = offset as u128 + stride as u128 * (count as u128 - 1) + elem as u128;
    if needs > bytes.len() as u128 {
        return Err(format!("{label} needs {needs} bytes but buffer view {view} holds {}", bytes.len()));
    }
    Ok(&bytes[offset..needs as usize])
}

fn dim_name(d: Dimensions) -> &'static str {
    match d {
        Dimensions::Scalar => "SCALAR",
        Dimensions::Vec2 => "VEC2",
        Dimensions::Vec3 => "VEC3",
        Dimensions::Vec4 => "VEC4",
        Dimensions::Mat2 => "MAT2",
        Dimensions::Mat3 => "MAT3",
        Dimensions::Mat4 => "MAT4",
    }
}

impl Checked<'_> {
    /// Visit every element's bytes: the base values, then the sparse substitutions over them.
    fn for_each(&self, mut f: impl FnMut(usize, &[u8])) {
        if let Some((bytes, stride)) = self.base {
            for i in 0..self.count {
                f(i, &bytes[i * stride..]);
            }
        }
        if let Some((targets, values)) = &self.sparse {
            let elem = self.dims * self.ty.size();
            for (k, &t) in targets.iter().enumerate() {
                f(t as usize, &values[k * elem..]);
            }
        }
    }

    /// Elements as float vectors (normalized integers mapped as glTF says); components the
    /// accessor lacks are `pad` (e.g. alpha 1 for an RGB colour).
    pub fn vecs<const N: usize>(&self, pad: f32) -> Vec<[f32; N]> {
        let mut out = vec![[pad; N]; self.count];
        let (dims, cs) = (self.dims.min(N), self.ty.size());
        self.for_each(|i, b| {
            for (c, v) in out[i].iter_mut().take(dims).enumerate() {
                *v = component(&b[c * cs..], self.ty, self.normalized);
            }
        });
        out
    }

    /// Scalar unsigned integers (indices).
    pub fn uints(&self) -> Vec<u32> {
        let mut out = vec![0u32; self.count];
        self.for_each(|i, b| {
            out[i] = match self.ty {
                U8 => b[0] as u32,
                U16 => u16::from_le_bytes([b[0], b[1]]) as u32,
                _ => u32::from_le_bytes([b[0], b[1], b[2], b[3]]),
            }
        });
        out
    }
}

fn component(b: &[u8], ty: DataType, normalized: bool) -> f32 {
    let (v, max) = match ty {
        F32 => return f32::from_le_bytes([b[0], b[1], b[2], b[3]]),
        I8 => (b[0] as i8 as f32, 127.0),
        U8 => (b[0] as f32, 255.0),
        I16 => (i16::from_le_bytes([b[0], b[1]]) as f32, 32767.0),
        U16 => (u16::from_le_bytes([b[0], b[1]]) as f32, 65535.0),
        U32 => (u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f32, u32::MAX as f32),
    };
    if normalized {
        (v / max).max(-1.0)
    } else {
        v
    }
}
