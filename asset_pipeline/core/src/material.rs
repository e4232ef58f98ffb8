//! glTF materials -> pack materials, and the images they use as base colour -> IR textures.

use crate::load::{read_uri, Source};
use crate::{accessor::view_bytes, label};
use gltf::material::AlphaMode;
use crate::ir::TextureIr;
use crate::mips::Usage;
use pack::TextureFormat;
use std::collections::HashMap;

/// Cook every material, in glTF order (so material indices carry over). Each image becomes one
/// pack texture per way it is read (base colour and emission as sRGB colour, metallic-roughness
/// and occlusion as linear data, normal maps as vectors), however many glTF textures or
/// materials refer to it; `on_image` is told before each decode (for progress).
pub(crate) fn cook_materials(src: &Source, textures: &mut Vec<TextureIr>, on_image: &mut dyn FnMut(&str)) -> Result<Vec<pack::Material>, String> {
    let mut by_image: HashMap<(usize, Usage), u32> = HashMap::new();
    let mut out = Vec::new();
    for (i, m) in src.document.materials().enumerate() {
        let mut texture = |tex: Option<gltf::texture::Texture>, usage: Usage, slot: &str| -> Result<Option<u32>, String> {
            let Some(tex) = tex else { return Ok(None) };
            let image = tex.source();
            if let Some(&t) = by_image.get(&(image.index(), usage)) {
                return Ok(Some(t));
            }
            let what = label("image", image.index(), image.name());
            on_image(&what);
            let decoded = decode(&image, src, usage).map_err(|e| format!("{what} ({slot} of {}): {e}", label("material", i, m.name())))?;
            textures.push(decoded);
            let index = (textures.len() - 1) as u32;
            by_image.insert((image.index(), usage), index);
            Ok(Some(index))
        };
        let pbr = m.pbr_metallic_roughness();
        let base_color_texture = texture(pbr.base_color_texture().map(|t| t.texture()), Usage::Color, "base colour")?;
        let metallic_roughness_texture = texture(pbr.metallic_roughness_texture().map(|t| t.texture()), Usage::Data, "metallic-roughness")?;
        let normal = m.normal_texture();
        let normal_texture = texture(normal.as_ref().map(|t| t.texture()), Usage::Normal, "normal map")?;
        let occlusion = m.occlusion_texture();
        let occlusion_texture = texture(occlusion.as_ref().map(|t| t.texture()), Usage::Data, "occlusion")?;
        let emissive_texture = texture(m.emissive_texture().map(|t| t.texture()), Usage::Color, "emissive")?;
        let strength = m.emissive_strength().unwrap_or(1.0);
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
            normal_scale: normal.as_ref().map_or(1.0, |n| n.scale()),
            metallic_roughness_texture,
            occlusion_texture,
            occlusion_strength: occlusion.as_ref().map_or(1.0, |o| o.strength()),
            emissive_texture,
        });
    }
    Ok(out)
}

/// Decode an image to a texture with one mip level, in the format its usage reads: RGBA8
/// (sRGB for colour), and 16-bit for normal maps authored with 16 bits, which keep them.
fn decode(image: &gltf::Image, src: &Source, usage: Usage) -> Result<TextureIr, String> {
    // Read the JSON rather than `image.source()`, which unwraps a missing uri or mimeType.
    let json = src.document.as_json().images.get(image.index()).ok_or("does not exist")?;
    let (bytes, name) = match (&json.buffer_view, &json.uri) {
        (Some(v), _) => {
            let view = src.document.views().nth(v.value()).ok_or("its buffer view does not exist")?;
            (view_bytes(&view, &src.buffers)?.to_vec(), None)
        }
        (None, Some(uri)) => {
            let name = (!uri.starts_with("data:")).then(|| uri.rsplit('/').next().unwrap_or(uri).to_string());
            (read_uri(&src.base, uri)?, name)
        }
        (None, None) => return Err("has neither a uri nor a bufferView".into()),
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
    Ok(TextureIr { name, width, height, format, usage, mips: vec![texels] })
}
