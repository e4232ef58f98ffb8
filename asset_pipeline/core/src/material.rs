//! glTF materials -> pack materials, and the images their texture slots read -> IR textures.

use crate::accessor::view_bytes;
use crate::ir::TextureIr;
use crate::label;
use crate::load::Source;
use crate::mips::Usage;
use crate::uri;
use gltf::json::extensions::texture::TextureTransform as TransformJson;
use gltf::material::AlphaMode;
use gltf::texture::{MagFilter, MinFilter, WrappingMode};
use pack::{Filter, TextureFormat, TextureTransform, Wrap};
use std::collections::{HashMap, HashSet};
use std::path::PathBuf;

/// What makes one pack texture: the image, how it is read (base colour and emission as sRGB
/// colour, metallic-roughness and occlusion as linear data, normal maps as vectors) and how it
/// is sampled (the sampler also decides which edges the mip filter wraps across).
type TextureKey = (usize, Usage, [u8; 5]);

fn texture_key(tex: &gltf::Texture, usage: Usage) -> TextureKey {
    let s = sampler(&tex.sampler());
    let filter = |f: Option<Filter>| f.map_or(0, |f| 1 + f as u8);
    (tex.source().index(), usage, [s.wrap_s as u8, s.wrap_t as u8, s.mag_filter as u8, s.min_filter as u8, filter(s.mipmap_filter)])
}

/// The texture of each material slot with the usage it is read with, in the pack's slot order
/// (`pack::Material::texture_slots`: base colour, normal, metallic-roughness, occlusion, emissive).
fn slot_textures<'a>(m: &gltf::Material<'a>) -> [Option<(gltf::Texture<'a>, Usage)>; 5] {
    let pbr = m.pbr_metallic_roughness();
    [
        pbr.base_color_texture().map(|t| (t.texture(), Usage::Color)),
        m.normal_texture().map(|t| (t.texture(), Usage::Normal)),
        pbr.metallic_roughness_texture().map(|t| (t.texture(), Usage::Data)),
        m.occlusion_texture().map(|t| (t.texture(), Usage::Data)),
        m.emissive_texture().map(|t| (t.texture(), Usage::Color)),
    ]
}

/// How many pack textures the materials make (for progress).
pub(crate) fn texture_count(doc: &gltf::Document) -> usize {
    let keys: HashSet<TextureKey> = doc.materials().flat_map(|m| slot_textures(&m)).flatten().map(|(t, u)| texture_key(&t, u)).collect();
    keys.len()
}

/// Cook every material, in glTF order (so material indices carry over). Each image becomes one
/// pack texture per (usage, sampler) it is read with, however many glTF textures or materials
/// refer to it; `on_image` is told before each decode (for progress), and each image file read
/// is added to `files` (once).
pub(crate) fn cook_materials(src: &Source, textures: &mut Vec<TextureIr>, files: &mut Vec<PathBuf>, on_image: &mut dyn FnMut(&str)) -> Result<Vec<pack::Material>, String> {
    let mut made: HashMap<TextureKey, u32> = HashMap::new();
    let mut out = Vec::new();
    let json = &src.document.as_json().materials;
    for (i, m) in src.document.materials().enumerate() {
        let material = label("material", i, m.name());
        let [base_color, normal, metallic_roughness, occlusion, emissive] = slot_textures(&m);
        // texCoord and KHR_texture_transform of each slot, from the JSON: the crate reads the
        // extension on textureInfo slots; `load` kept it for normal and occlusion textures.
        let mj = &json[i];
        let pbr = &mj.pbr_metallic_roughness;
        let info = |t: &Option<gltf::json::texture::Info>| t.as_ref().map(|t| (t.tex_coord, t.extensions.as_ref().and_then(|e| e.texture_transform.clone())));
        let raw = |k: usize, tex_coord: u32| -> Result<(u32, Option<TransformJson>), String> {
            let t = src.normal_occlusion_transforms.get(i).and_then(|t| t[k].clone());
            let t = t.map(serde_json::from_value).transpose().map_err(|e| format!("{material} {}: KHR_texture_transform: {e}", ["normal map", "occlusion"][k]))?;
            Ok((tex_coord, t))
        };
        let uvs = [
            info(&pbr.base_color_texture),
            mj.normal_texture.as_ref().map(|t| raw(0, t.tex_coord)).transpose()?,
            info(&pbr.metallic_roughness_texture),
            mj.occlusion_texture.as_ref().map(|t| raw(1, t.tex_coord)).transpose()?,
            info(&mj.emissive_texture),
        ];
        let mut slot_uv = [TextureTransform::default(); 5];
        for (k, uv) in uvs.into_iter().enumerate() {
            if let Some((tex_coord, transform)) = uv {
                slot_uv[k] = uv_transform(tex_coord, transform.as_ref()).map_err(|e| format!("{material} {}: {e}", SLOTS[k]))?;
            }
        }

        let mut texture = |slot: Option<(gltf::Texture, Usage)>, k: usize| -> Result<Option<u32>, String> {
            let Some((tex, usage)) = slot else { return Ok(None) };
            let key = texture_key(&tex, usage);
            if let Some(&t) = made.get(&key) {
                return Ok(Some(t));
            }
            let image = tex.source();
            let what = label("image", image.index(), image.name());
            on_image(&what);
            let mut decoded = decode(&image, src, usage, files).map_err(|e| format!("{what} ({} of {material}): {e}", SLOTS[k]))?;
            decoded.sampler = sampler(&tex.sampler());
            textures.push(decoded);
            let index = (textures.len() - 1) as u32;
            made.insert(key, index);
            Ok(Some(index))
        };
        // Decoded in this order, which fixes the pack's texture order.
        let base_color_texture = texture(base_color, 0)?;
        let metallic_roughness_texture = texture(metallic_roughness, 2)?;
        let normal_texture = texture(normal, 1)?;
        let occlusion_texture = texture(occlusion, 3)?;
        let emissive_texture = texture(emissive, 4)?;
        let pbr = m.pbr_metallic_roughness();
        let strength = m.emissive_strength().unwrap_or(1.0);
        let [base_color_uv, normal_uv, metallic_roughness_uv, occlusion_uv, emissive_uv] = slot_uv;
        out.push(pack::Material {
            name: m.name().map_or_else(|| format!("material{i}"), str::to_string),
            base_color: pbr.base_color_factor(),
            base_color_texture,
            metallic: pbr.metallic_factor(),
            roughness: pbr.roughness_factor(),
            emissive: m.emissive_factor().map(|c| c * strength),
            alpha_mode: match m.alpha_mode() {
                AlphaMode::Opaque => pack::AlphaMode::Opaque,
                AlphaMode::Mask => pack::AlphaMode::Mask,
                AlphaMode::Blend => pack::AlphaMode::Blend,
            },
            alpha_cutoff: m.alpha_cutoff().unwrap_or(0.5),
            double_sided: m.double_sided(),
            normal_texture,
            normal_scale: m.normal_texture().map_or(1.0, |n| n.scale()),
            metallic_roughness_texture,
            occlusion_texture,
            occlusion_strength: m.occlusion_texture().map_or(1.0, |o| o.strength()),
            emissive_texture,
            base_color_uv,
            normal_uv,
            metallic_roughness_uv,
            occlusion_uv,
            emissive_uv,
        });
    }
    Ok(out)
}

/// Slot names in messages, in `slot_textures` order.
const SLOTS: [&str; 5] = ["base colour", "normal map", "metallic-roughness", "occlusion", "emissive"];

/// A slot's `texCoord` and KHR_texture_transform (whose `texCoord`, when given, overrides the
/// slot's) as the pack's transform. Vertices carry two UV sets, so only 0 and 1 can be read.
fn uv_transform(tex_coord: u32, t: Option<&TransformJson>) -> Result<TextureTransform, String> {
    let tex_coord = t.and_then(|t| t.tex_coord).unwrap_or(tex_coord);
    if tex_coord > 1 {
        return Err(format!("texCoord {tex_coord} is not supported (vertices carry TEXCOORD_0 and TEXCOORD_1)"));
    }
    let Some(t) = t else { return Ok(TextureTransform { tex_coord, ..Default::default() }) };
    let out = TextureTransform { tex_coord, offset: t.offset.0, rotation: t.rotation.0, scale: t.scale.0 };
    let numbers = [out.offset[0], out.offset[1], out.rotation, out.scale[0], out.scale[1]];
    if !numbers.iter().all(|x| x.is_finite()) {
        return Err(format!("KHR_texture_transform has a number that is not finite (offset {:?}, rotation {}, scale {:?})", out.offset, out.rotation, out.scale));
    }
    Ok(out)
}

/// A glTF sampler as the pack's. glTF leaves absent filters to the implementation: linear, with
/// linear blending between mip levels (trilinear), as the runtime samples by default.
fn sampler(s: &gltf::texture::Sampler) -> pack::Sampler {
    let wrap = |w| match w {
        WrappingMode::Repeat => Wrap::Repeat,
        WrappingMode::ClampToEdge => Wrap::Clamp,
        WrappingMode::MirroredRepeat => Wrap::Mirror,
    };
    let (min_filter, mipmap_filter) = match s.min_filter() {
        None | Some(MinFilter::LinearMipmapLinear) => (Filter::Linear, Some(Filter::Linear)),
        Some(MinFilter::Nearest) => (Filter::Nearest, None),
        Some(MinFilter::Linear) => (Filter::Linear, None),
        Some(MinFilter::NearestMipmapNearest) => (Filter::Nearest, Some(Filter::Nearest)),
        Some(MinFilter::LinearMipmapNearest) => (Filter::Linear, Some(Filter::Nearest)),
        Some(MinFilter::NearestMipmapLinear) => (Filter::Nearest, Some(Filter::Linear)),
    };
    pack::Sampler {
        wrap_s: wrap(s.wrap_s()),
        wrap_t: wrap(s.wrap_t()),
        mag_filter: match s.mag_filter() {
            Some(MagFilter::Nearest) => Filter::Nearest,
            None | Some(MagFilter::Linear) => Filter::Linear,
        },
        min_filter,
        mipmap_filter,
    }
}

/// Decode an image to a texture with one mip level, in the format its usage reads: RGBA8
/// (sRGB for colour), and 16-bit for normal maps authored with 16 bits, which keep them.
/// A file it reads is added to `files` (once).
fn decode(image: &gltf::Image, src: &Source, usage: Usage, files: &mut Vec<PathBuf>) -> Result<TextureIr, String> {
    // Read the JSON rather than `image.source()`, which unwraps a missing uri or mimeType.
    let json = src.document.as_json().images.get(image.index()).ok_or("does not exist")?;
    let (bytes, name) = match (&json.buffer_view, &json.uri, src.image_files.get(image.index()).cloned().flatten()) {
        (Some(v), _, _) => {
            let view = src.document.views().nth(v.value()).ok_or("its buffer view does not exist")?;
            (view_bytes(&view, &src.buffers)?.to_vec(), None)
        }
        (None, Some(u), Some(path)) => {
            let name = u.rsplit('/').next().unwrap_or(u).to_string();
            let bytes = uri::read_file(&path);
            if !files.contains(&path) {
                files.push(path);
            }
            (bytes?, Some(name))
        }
        (None, Some(u), None) => (uri::decode_data(u)?, None),
        (None, None, _) => return Err("has neither a uri nor a bufferView".into()),
    };
    // The format comes from the bytes, not the declared MIME type, which exporters get wrong.
    let decoded = crate::decode_texture(&bytes)?;
    let name = image.name().map(str::to_string).or(name).unwrap_or_else(|| format!("image{}", image.index()));
    let (width, height) = (decoded.width(), decoded.height());
    let sixteen_bit = matches!(decoded.color(), image::ColorType::L16 | image::ColorType::La16 | image::ColorType::Rgb16 | image::ColorType::Rgba16);
    let (format, texels) = match usage {
        Usage::Normal if sixteen_bit => (TextureFormat::Rgba16Unorm, decoded.to_rgba16().into_raw().iter().flat_map(|v| v.to_le_bytes()).collect()),
        Usage::Color => (TextureFormat::Rgba8Srgb, decoded.to_rgba8().into_raw()),
        Usage::Data | Usage::Normal | Usage::Hdr => (TextureFormat::Rgba8Unorm, decoded.to_rgba8().into_raw()),
    };
    Ok(TextureIr { name, width, height, format, usage, mips: vec![texels], sampler: pack::Sampler::default() })
}
