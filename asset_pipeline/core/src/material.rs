//! glTF materials -> pack materials, and the images they use as base colour -> IR textures.

use crate::load::{read_uri, Source};
use crate::{accessor::view_bytes, label};
use gltf::material::AlphaMode;
use crate::ir::TextureIr;
use crate::mips::Usage;
use pack::TextureFormat;
use std::collections::HashMap;

/// Cook every material, in glTF order (so material indices carry over). Each image used as a
/// base colour becomes one pack texture, however many glTF textures or materials refer to it;
/// `on_image` is told before each decode (for progress).
pub(crate) fn cook_materials(src: &Source, textures: &mut Vec<TextureIr>, on_image: &mut dyn FnMut(&str)) -> Result<Vec<pack::Material>, String> {
    let mut by_image: HashMap<usize, u32> = HashMap::new();
    let mut out = Vec::new();
    for (i, m) in src.document.materials().enumerate() {
        let pbr = m.pbr_metallic_roughness();
        let base_color_texture = match pbr.base_color_texture() {
            None => None,
            Some(info) => {
                let image = info.texture().source();
                match by_image.get(&image.index()) {
                    Some(&t) => Some(t),
                    None => {
                        let what = label("image", image.index(), image.name());
                        on_image(&what);
                        let tex = decode(&image, src).map_err(|e| {
                            format!("{what} (base colour of {}): {e}", label("material", i, m.name()))
                        })?;
                        textures.push(tex);
                        let index = (textures.len() - 1) as u32;
                        by_image.insert(image.index(), index);
                        Some(index)
                    }
                }
            }
        };
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
        });
    }
    Ok(out)
}

/// Decode an image to an RGBA8 sRGB texture with one mip level.
fn decode(image: &gltf::Image, src: &Source) -> Result<TextureIr, String> {
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
    let rgba = image::load_from_memory(&bytes).map_err(|e| format!("cannot decode: {e}"))?.to_rgba8();
    let name = image.name().map(str::to_string).or(name).unwrap_or_else(|| format!("image{}", image.index()));
    let (width, height) = rgba.dimensions();
    Ok(TextureIr { name, width, height, format: TextureFormat::Rgba8Srgb, usage: Usage::Color, mips: vec![rgba.into_raw()] })
}
