//! The crossing between Python's scene IR (`asset_pipeline/ir.py`) and `SceneIr`: JSON metadata
//! in which every array is replaced by an index into a list of raw arrays (numpy dtype string,
//! shape, little-endian bytes). See `to_wire` / `from_wire` in ir.py for the other side.

use crate::ir::{ChannelIr, ClipIr, LodIr, MeshIr, ProbesIr, ReflectionProbesIr, SceneIr, SkinIr, TextureIr};
use crate::mips::Usage;
use pack::{LightmapLayout, Material, Node, Sky, Spawn, TextureFormat};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// One numpy array as it crosses: `dtype` is numpy's `dtype.str` (e.g. "<f4", "|u1").
#[derive(Debug, Clone, PartialEq)]
pub struct RawArray {
    pub dtype: String,
    pub shape: Vec<usize>,
    pub bytes: Vec<u8>,
}

#[derive(Serialize, Deserialize)]
struct WireScene {
    name: String,
    source: String,
    meshes: Vec<WireMesh>,
    materials: Vec<Material>,
    textures: Vec<WireTexture>,
    nodes: Vec<WireNode>,
    #[serde(default)]
    lights: Vec<pack::Light>,
    #[serde(default)]
    spawns: Vec<Spawn>,
    #[serde(default)]
    pillars: Vec<pack::Pillar>,
    #[serde(default)]
    sky: Option<Sky>,
    #[serde(default)]
    lightmap: Option<LightmapLayout>,
    #[serde(default)]
    probes: Option<WireProbes>,
    #[serde(default)]
    reflection_probes: Option<WireReflectionProbes>,
    #[serde(default)]
    skins: Vec<WireSkin>,
    #[serde(default)]
    clips: Vec<WireClip>,
    #[serde(default)]
    warnings: Vec<String>,
}

/// A node with its animation binding (`pack::NodeBinding`) inline, as Python's `ir.Node`.
#[derive(Serialize, Deserialize)]
struct WireNode {
    name: String,
    parent: Option<u32>,
    local: [f32; 16],
    mesh: Option<u32>,
    #[serde(default)]
    skin: Option<u32>,
    #[serde(default)]
    weights: Option<Vec<f32>>,
    #[serde(rename = "static", default)]
    is_static: bool,
    #[serde(default)]
    lightmap: Option<pack::LightmapRegion>,
}

#[derive(Serialize, Deserialize)]
struct WireSkin {
    name: String,
    joints: Vec<u32>,
    /// float32 (n, 16), column-major matrices.
    inverse_bind: usize,
}

#[derive(Serialize, Deserialize)]
struct WireChannel {
    node: u32,
    path: pack::ChannelPath,
    interpolation: pack::Interpolation,
    /// float32 (k,).
    times: usize,
    /// float32 (k, c), or (3k, c) for cubic splines: in tangent, value, out tangent per key.
    values: usize,
}

#[derive(Serialize, Deserialize)]
struct WireClip {
    name: String,
    channels: Vec<WireChannel>,
}

#[derive(Serialize, Deserialize)]
struct WireReflectionProbes {
    face_size: u32,
    levels: u32,
    /// Rgba16Float (each cube a float16 (T, 4) array) or Bc6hUfloat (a uint8 array of blocks).
    #[serde(default = "half_float")]
    format: TextureFormat,
    probes: Vec<WireReflectionProbe>,
}

fn half_float() -> TextureFormat {
    TextureFormat::Rgba16Float
}

/// `pack::ReflectionProbe` with `data` the index of its cube array.
#[derive(Serialize, Deserialize)]
struct WireReflectionProbe {
    name: String,
    position: [f32; 3],
    box_min: [f32; 3],
    box_max: [f32; 3],
    blend_distance: f32,
    data: usize,
}

#[derive(Serialize, Deserialize)]
struct WireProbes {
    origin: [f32; 3],
    spacing: [f32; 3],
    counts: [u32; 3],
    /// float32 (n, 27): 9 SH coefficients x rgb per probe.
    sh: usize,
    /// float32 (n,).
    sun_visibility: usize,
}

#[derive(Serialize, Deserialize)]
struct WireMesh {
    name: String,
    lods: Vec<WireLod>,
    #[serde(default)]
    morph_weights: Vec<f32>,
    /// `[[lo_u, lo_v, hi_u, hi_v]; 3]` of uv0, uv1, texcoord1 (`MeshIr::uv_bounds`).
    #[serde(default)]
    uv_bounds: Option<pack::UvBounds>,
}

#[derive(Serialize, Deserialize)]
struct WireLod {
    attributes: BTreeMap<String, usize>,
    triangles: usize,
    materials: usize,
    #[serde(default)]
    lightmap_blocks: Option<usize>,
    #[serde(default)]
    error: f32,
    /// float32 (targets, n, 3).
    #[serde(default)]
    morph_positions: Option<usize>,
    #[serde(default)]
    morph_normals: Option<usize>,
}

#[derive(Serialize, Deserialize)]
struct WireTexture {
    name: String,
    width: u32,
    height: u32,
    format: TextureFormat,
    /// color | data | normal | hdr; absent: what the format implies.
    #[serde(default)]
    usage: Option<Usage>,
    mips: Vec<usize>,
    #[serde(default)]
    sampler: pack::Sampler,
}

/// A scalar type that can cross as a numpy dtype.
trait Elem: Copy + Default {
    const DTYPE: &'static str;
    const SIZE: usize;
    fn read(b: &[u8]) -> Self;
    fn write(self, out: &mut Vec<u8>);
}

macro_rules! elem {
    ($t:ty, $dtype:expr) => {
        impl Elem for $t {
            const DTYPE: &'static str = $dtype;
            const SIZE: usize = std::mem::size_of::<$t>();
            fn read(b: &[u8]) -> Self {
                <$t>::from_le_bytes(b.try_into().unwrap())
            }
            fn write(self, out: &mut Vec<u8>) {
                out.extend_from_slice(&self.to_le_bytes());
            }
        }
    };
}
elem!(f32, "<f4");
elem!(u32, "<u4");
elem!(u16, "<u2");
elem!(u8, "|u1");

struct Reader<'a> {
    arrays: &'a [RawArray],
}

impl Reader<'_> {
    fn get(&self, index: usize, what: &str) -> Result<&RawArray, String> {
        self.arrays.get(index).ok_or_else(|| format!("{what}: array {index} does not exist ({} arrays)", self.arrays.len()))
    }

    /// An (n, K) array of T as `Vec<[T; K]>`; (n,) arrays when K == 1 go through `scalars`.
    fn rows<T: Elem, const K: usize>(&self, index: usize, what: &str) -> Result<Vec<[T; K]>, String> {
        let a = self.get(index, what)?;
        if a.dtype != T::DTYPE || a.shape.len() != 2 || a.shape[1] != K || a.bytes.len() != a.shape[0] * K * T::SIZE {
            return Err(format!("{what}: expected a {}(n, {K}) array, got {}{:?} ({} bytes)", T::DTYPE, a.dtype, a.shape, a.bytes.len()));
        }
        Ok(a.bytes
            .chunks_exact(K * T::SIZE)
            .map(|row| {
                let mut out = [T::default(); K];
                for (k, o) in out.iter_mut().enumerate() {
                    *o = T::read(&row[k * T::SIZE..(k + 1) * T::SIZE]);
                }
                out
            })
            .collect())
    }

    /// A float32 (targets, n, 3) array of morph deltas as one list per target.
    fn morphs(&self, index: usize, n: usize, what: &str) -> Result<Vec<Vec<[f32; 3]>>, String> {
        let a = self.get(index, what)?;
        if a.dtype != "<f4" || a.shape.len() != 3 || a.shape[1] != n || a.shape[2] != 3 || a.bytes.len() != a.shape[0] * n * 12 {
            return Err(format!("{what}: expected a <f4(targets, {n}, 3) array, got {}{:?}", a.dtype, a.shape));
        }
        let flat = RawArray { dtype: a.dtype.clone(), shape: vec![a.shape[0] * n, 3], bytes: a.bytes.clone() };
        let rows = Reader { arrays: std::slice::from_ref(&flat) }.rows::<f32, 3>(0, what)?;
        Ok(if n == 0 { vec![Vec::new(); a.shape[0]] } else { rows.chunks(n).map(<[_]>::to_vec).collect() })
    }

    fn scalars<T: Elem>(&self, index: usize, what: &str) -> Result<Vec<T>, String> {
        let a = self.get(index, what)?;
        if a.dtype != T::DTYPE || a.shape.len() != 1 || a.bytes.len() != a.shape[0] * T::SIZE {
            return Err(format!("{what}: expected a {}(n,) array, got {}{:?}", T::DTYPE, a.dtype, a.shape));
        }
        Ok(a.bytes.chunks_exact(T::SIZE).map(T::read).collect())
    }
}

/// Decode the wire form into a `SceneIr`, checking every array's dtype and shape.
pub fn from_wire(json: &str, arrays: &[RawArray]) -> Result<SceneIr, String> {
    let w: WireScene = serde_json::from_str(json).map_err(|e| format!("scene metadata: {e}"))?;
    let r = Reader { arrays };
    let mut meshes = Vec::with_capacity(w.meshes.len());
    for (i, m) in w.meshes.iter().enumerate() {
        let mut lods = Vec::with_capacity(m.lods.len());
        for (l, wl) in m.lods.iter().enumerate() {
            let what = format!("mesh {i} '{}' LOD {l}", m.name);
            let attr = |name: &str| wl.attributes.get(name).copied();
            for name in wl.attributes.keys() {
                if !["position", "normal", "tangent", "uv0", "uv1", "texcoord1", "color", "joints", "weights"].contains(&name.as_str()) {
                    return Err(format!("{what}: unknown attribute '{name}'"));
                }
            }
            let pos = attr("position").ok_or_else(|| format!("{what}: no position attribute"))?;
            let opt3 = |n: &str| attr(n).map(|i| r.rows::<f32, 3>(i, &format!("{what} {n}"))).transpose();
            let opt4 = |n: &str| attr(n).map(|i| r.rows::<f32, 4>(i, &format!("{what} {n}"))).transpose();
            let opt2 = |n: &str| attr(n).map(|i| r.rows::<f32, 2>(i, &format!("{what} {n}"))).transpose();
            let lod = LodIr {
                positions: r.rows::<f32, 3>(pos, &format!("{what} position"))?,
                normals: opt3("normal")?,
                tangents: opt4("tangent")?,
                uv0: opt2("uv0")?,
                uv1: opt2("uv1")?,
                texcoord1: opt2("texcoord1")?,
                colors: attr("color").map(|i| r.rows::<u8, 4>(i, &format!("{what} color"))).transpose()?,
                joints: attr("joints").map(|i| r.rows::<u16, 4>(i, &format!("{what} joints"))).transpose()?,
                weights: opt4("weights")?,
                triangles: r.rows::<u32, 3>(wl.triangles, &format!("{what} triangles"))?,
                materials: r.scalars::<u32>(wl.materials, &format!("{what} materials"))?,
                lightmap_blocks: wl.lightmap_blocks.map(|i| r.scalars::<u32>(i, &format!("{what} lightmap_blocks"))).transpose()?,
                error: wl.error,
                morph_positions: Vec::new(),
                morph_normals: Vec::new(),
            };
            let n = lod.positions.len();
            let lod = LodIr {
                morph_positions: wl.morph_positions.map(|i| r.morphs(i, n, &format!("{what} morph_positions"))).transpose()?.unwrap_or_default(),
                morph_normals: wl.morph_normals.map(|i| r.morphs(i, n, &format!("{what} morph_normals"))).transpose()?.unwrap_or_default(),
                ..lod
            };
            lod.validate(&what)?;
            if !lod.morph_positions.is_empty() && lod.morph_positions.len() != m.morph_weights.len() {
                return Err(format!("{what}: {} morph targets but {} default morph weights", lod.morph_positions.len(), m.morph_weights.len()));
            }
            lods.push(lod);
        }
        meshes.push(MeshIr { name: m.name.clone(), lods, morph_weights: m.morph_weights.clone(), uv_bounds: m.uv_bounds });
    }
    let mut textures = Vec::with_capacity(w.textures.len());
    for (i, t) in w.textures.iter().enumerate() {
        let mut mips = Vec::with_capacity(t.mips.len());
        for (l, &index) in t.mips.iter().enumerate() {
            let a = r.get(index, &format!("texture {i} '{}' mip {l}", t.name))?;
            let want = t.format.level_bytes((t.width >> l).max(1), (t.height >> l).max(1)).unwrap_or(u64::MAX);
            if a.bytes.len() as u64 != want {
                return Err(format!("texture {i} '{}' mip {l}: {} bytes, expected {want}", t.name, a.bytes.len()));
            }
            mips.push(a.bytes.clone());
        }
        let usage = t.usage.unwrap_or(Usage::of_format(t.format));
        usage.check_format(t.format).map_err(|e| format!("texture {i} '{}': {e}", t.name))?;
        textures.push(TextureIr { name: t.name.clone(), width: t.width, height: t.height, format: t.format, usage, mips, sampler: t.sampler });
    }
    let probes = match &w.probes {
        None => None,
        Some(p) => {
            let (sh, sun_visibility) = (r.rows::<f32, 27>(p.sh, "probes sh")?, r.scalars::<f32>(p.sun_visibility, "probes sun_visibility")?);
            let n: u64 = p.counts.iter().map(|&c| c as u64).product();
            if sh.len() as u64 != n || sun_visibility.len() as u64 != n {
                return Err(format!("probes: {} SH rows and {} visibilities for a {:?} grid", sh.len(), sun_visibility.len(), p.counts));
            }
            Some(ProbesIr { origin: p.origin, spacing: p.spacing, counts: p.counts, sh, sun_visibility })
        }
    };
    let reflection_probes = match &w.reflection_probes {
        None => None,
        Some(rp) => {
            let mut probes = Vec::with_capacity(rp.probes.len());
            for (i, p) in rp.probes.iter().enumerate() {
                let what = format!("reflection probe {i} '{}'", p.name);
                let a = r.get(p.data, &what)?;
                let ok = match rp.format {
                    TextureFormat::Rgba16Float => a.dtype == "<f2" && a.shape.len() == 2 && a.shape[1] == 4 && a.bytes.len() == a.shape[0] * 8,
                    TextureFormat::Bc6hUfloat => a.dtype == "|u1" && a.shape.len() == 1,
                    f => return Err(format!("reflection probes: format {f:?} is not Rgba16Float or Bc6hUfloat")),
                };
                if !ok {
                    return Err(format!("{what}: expected a {} cube, got {}{:?}", if rp.format == TextureFormat::Rgba16Float { "<f2(n, 4)" } else { "|u1(n) BC6H" }, a.dtype, a.shape));
                }
                let probe = pack::ReflectionProbe { name: p.name.clone(), position: p.position, box_min: p.box_min, box_max: p.box_max, blend_distance: p.blend_distance, data: Default::default() };
                probes.push((probe, a.bytes.clone()));
            }
            Some(ReflectionProbesIr { face_size: rp.face_size, levels: rp.levels, format: rp.format, probes })
        }
    };
    let mut skins = Vec::with_capacity(w.skins.len());
    for (i, s) in w.skins.iter().enumerate() {
        let inverse_bind = r.rows::<f32, 16>(s.inverse_bind, &format!("skin {i} '{}' inverse_bind", s.name))?;
        skins.push(SkinIr { name: s.name.clone(), joints: s.joints.clone(), inverse_bind });
    }
    let mut clips = Vec::with_capacity(w.clips.len());
    for (c, clip) in w.clips.iter().enumerate() {
        let mut channels = Vec::with_capacity(clip.channels.len());
        for (k, ch) in clip.channels.iter().enumerate() {
            let what = format!("clip {c} '{}' channel {k} ({:?})", clip.name, ch.path);
            let times = r.scalars::<f32>(ch.times, &format!("{what} times"))?;
            let v = r.get(ch.values, &format!("{what} values"))?;
            if v.dtype != "<f4" || v.shape.len() != 2 || v.bytes.len() != v.shape[0] * v.shape[1] * 4 {
                return Err(format!("{what} values: expected a <f4(keys, components) array, got {}{:?}", v.dtype, v.shape));
            }
            let values = v.bytes.chunks_exact(4).map(f32::read).collect();
            let channel = ChannelIr { node: ch.node, path: ch.path, interpolation: ch.interpolation, components: v.shape[1] as u32, times, values };
            // Rotation keys are normalised here as on import, so both routes write the same pack.
            channels.push(crate::anim::validate_channel(channel).map_err(|e| format!("{what}: {e}"))?);
        }
        clips.push(ClipIr { name: clip.name.clone(), channels });
    }
    let bindings = w
        .nodes
        .iter()
        .enumerate()
        .filter(|(_, n)| n.skin.is_some() || n.weights.is_some())
        .map(|(i, n)| pack::NodeBinding { node: i as u32, skin: n.skin, weights: n.weights.clone() })
        .collect();
    let nodes = w.nodes.into_iter().map(|n| Node { name: n.name, parent: n.parent, local: n.local, mesh: n.mesh, is_static: n.is_static, lightmap: n.lightmap }).collect();
    let scene = SceneIr {
        name: w.name,
        source: w.source,
        meshes,
        materials: w.materials,
        textures,
        nodes,
        lights: w.lights,
        spawns: w.spawns,
        pillars: w.pillars,
        sky: w.sky,
        lightmap: w.lightmap,
        probes,
        reflection_probes,
        skins,
        clips,
        bindings,
        warnings: w.warnings,
    };
    scene.check_animation()?;
    Ok(scene)
}

struct Writer {
    arrays: Vec<RawArray>,
}

impl Writer {
    fn rows<T: Elem, const K: usize>(&mut self, rows: &[[T; K]]) -> usize {
        let mut bytes = Vec::with_capacity(rows.len() * K * T::SIZE);
        rows.iter().flatten().for_each(|v| v.write(&mut bytes));
        self.push(T::DTYPE, vec![rows.len(), K], bytes)
    }
    fn morphs(&mut self, m: &[Vec<[f32; 3]>]) -> usize {
        let n = m.first().map_or(0, Vec::len);
        let bytes = m.iter().flatten().flatten().flat_map(|x| x.to_le_bytes()).collect();
        self.push("<f4", vec![m.len(), n, 3], bytes)
    }
    fn scalars<T: Elem>(&mut self, v: &[T]) -> usize {
        let mut bytes = Vec::with_capacity(v.len() * T::SIZE);
        v.iter().for_each(|x| x.write(&mut bytes));
        self.push(T::DTYPE, vec![v.len()], bytes)
    }
    fn push(&mut self, dtype: &str, shape: Vec<usize>, bytes: Vec<u8>) -> usize {
        self.arrays.push(RawArray { dtype: dtype.into(), shape, bytes });
        self.arrays.len() - 1
    }
}

/// Encode a `SceneIr` for Python. Texture mips cross as (h, w, 4) uint8 arrays (or float16 for
/// HDR formats).
pub fn to_wire(scene: &SceneIr) -> (String, Vec<RawArray>) {
    let mut w = Writer { arrays: Vec::new() };
    let meshes = scene
        .meshes
        .iter()
        .map(|m| WireMesh {
            name: m.name.clone(),
            uv_bounds: m.uv_bounds,
            lods: m
                .lods
                .iter()
                .map(|l| {
                    let mut attributes = BTreeMap::new();
                    attributes.insert("position".to_string(), w.rows(&l.positions));
                    if let Some(v) = &l.normals {
                        attributes.insert("normal".into(), w.rows(v));
                    }
                    if let Some(v) = &l.tangents {
                        attributes.insert("tangent".into(), w.rows(v));
                    }
                    if let Some(v) = &l.uv0 {
                        attributes.insert("uv0".into(), w.rows(v));
                    }
                    if let Some(v) = &l.uv1 {
                        attributes.insert("uv1".into(), w.rows(v));
                    }
                    if let Some(v) = &l.texcoord1 {
                        attributes.insert("texcoord1".into(), w.rows(v));
                    }
                    if let Some(v) = &l.colors {
                        attributes.insert("color".into(), w.rows(v));
                    }
                    if let Some(v) = &l.joints {
                        attributes.insert("joints".into(), w.rows(v));
                    }
                    if let Some(v) = &l.weights {
                        attributes.insert("weights".into(), w.rows(v));
                    }
                    WireLod {
                        attributes,
                        triangles: w.rows(&l.triangles),
                        materials: w.scalars(&l.materials),
                        lightmap_blocks: l.lightmap_blocks.as_ref().map(|p| w.scalars(p)),
                        error: l.error,
                        morph_positions: (!l.morph_positions.is_empty()).then(|| w.morphs(&l.morph_positions)),
                        morph_normals: (!l.morph_normals.is_empty()).then(|| w.morphs(&l.morph_normals)),
                    }
                })
                .collect(),
            morph_weights: m.morph_weights.clone(),
        })
        .collect();
    let textures = scene
        .textures
        .iter()
        .map(|t| {
            let (dtype, channel_bytes) = match t.format {
                TextureFormat::Rgba16Float => ("<f2", 2),
                TextureFormat::Rgba16Unorm => ("<u2", 2),
                TextureFormat::Rgba8Srgb | TextureFormat::Rgba8Unorm => ("|u1", 1),
                // Compressed levels cross as their blocks' bytes (one dimension).
                TextureFormat::Bc7Srgb | TextureFormat::Bc7Unorm | TextureFormat::Bc5Unorm | TextureFormat::Bc4Unorm | TextureFormat::Bc6hUfloat => ("|u1", 1),
            };
            let mips = (0..t.mips.len())
                .map(|l| {
                    if t.format.is_compressed() {
                        return w.push(dtype, vec![t.mips[l].len()], t.mips[l].clone());
                    }
                    let shape = vec![(t.height >> l).max(1) as usize, (t.width >> l).max(1) as usize, 4];
                    debug_assert_eq!(shape.iter().product::<usize>() * channel_bytes, t.mips[l].len());
                    w.push(dtype, shape, t.mips[l].clone())
                })
                .collect();
            WireTexture { name: t.name.clone(), width: t.width, height: t.height, format: t.format, usage: Some(t.usage), mips, sampler: t.sampler }
        })
        .collect();
    let probes = scene.probes.as_ref().map(|p| WireProbes {
        origin: p.origin,
        spacing: p.spacing,
        counts: p.counts,
        sh: w.rows(&p.sh),
        sun_visibility: w.scalars(&p.sun_visibility),
    });
    let reflection_probes = scene.reflection_probes.as_ref().map(|rp| WireReflectionProbes {
        face_size: rp.face_size,
        levels: rp.levels,
        format: rp.format,
        probes: rp
            .probes
            .iter()
            .map(|(p, bytes)| WireReflectionProbe {
                name: p.name.clone(),
                position: p.position,
                box_min: p.box_min,
                box_max: p.box_max,
                blend_distance: p.blend_distance,
                data: match rp.format {
                    TextureFormat::Bc6hUfloat => w.push("|u1", vec![bytes.len()], bytes.clone()),
                    _ => w.push("<f2", vec![bytes.len() / 8, 4], bytes.clone()),
                },
            })
            .collect(),
    });
    let doc = WireScene {
        name: scene.name.clone(),
        source: scene.source.clone(),
        meshes,
        materials: scene.materials.clone(),
        textures,
        nodes: scene
            .nodes
            .iter()
            .enumerate()
            .map(|(i, n)| {
                let b = scene.bindings.iter().find(|b| b.node as usize == i);
                WireNode {
                    name: n.name.clone(),
                    parent: n.parent,
                    local: n.local,
                    mesh: n.mesh,
                    skin: b.and_then(|b| b.skin),
                    weights: b.and_then(|b| b.weights.clone()),
                    is_static: n.is_static,
                    lightmap: n.lightmap,
                }
            })
            .collect(),
        lights: scene.lights.clone(),
        spawns: scene.spawns.clone(),
        pillars: scene.pillars.clone(),
        sky: scene.sky,
        lightmap: scene.lightmap.clone(),
        probes,
        reflection_probes,
        skins: scene.skins.iter().map(|s| WireSkin { name: s.name.clone(), joints: s.joints.clone(), inverse_bind: w.rows(&s.inverse_bind) }).collect(),
        clips: scene
            .clips
            .iter()
            .map(|c| WireClip {
                name: c.name.clone(),
                channels: c
                    .channels
                    .iter()
                    .map(|ch| {
                        let k = ch.components.max(1) as usize;
                        let rows = ch.values.len() / k;
                        let bytes = ch.values.iter().flat_map(|x| x.to_le_bytes()).collect();
                        WireChannel { node: ch.node, path: ch.path, interpolation: ch.interpolation, times: w.scalars(&ch.times), values: w.push("<f4", vec![rows, k], bytes) }
                    })
                    .collect(),
            })
            .collect(),
        warnings: scene.warnings.clone(),
    };
    (serde_json::to_string(&doc).expect("the IR always serialises"), w.arrays)
}
