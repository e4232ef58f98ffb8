// What a mesh draw gives both its vertex and its fragment shaders: the push constants (mirrors
// `DrawPush` in engine/src/render/mesh_draw.rs) and every material's constants (set 2 binding 2;
// `MaterialConstants` in engine/src/assets.rs).

layout(push_constant) uniform Draw {
    vec4 material; // x: alpha-test cutoff (or -1), y: material index, z: the submesh's lightmap block
    vec4 base_color;
    // The LOD's 16-bit texture coordinates' maps (pack::UvRanges): uv = q * xy + zw for uv0,
    // uv1 (lightmap) and texcoord1.
    vec4 uv_ranges[3];
} draw;

struct MaterialConstants {
    vec4 emission; // rgb: emitted radiance factor, times the emissive texture
    // x: metallic, y: roughness (factors, times the metallic-roughness texture's b and g),
    // z: normalTexture.scale, w: occlusion strength.
    vec4 pbr;
    // A texture slot's UV transform (glTF texCoord and KHR_texture_transform) as two rows
    // (a, b, c, tex_coord) and (d, e, f, has): uv' = (a u + b v + c, d u + e v + f) of uv0
    // (tex_coord 0) or texcoord1 (1); has = 1 when the slot has a texture (else the shader
    // skips the sample: the factor alone).
    vec4 base_color_uv[2];
    vec4 emissive_uv[2];
    vec4 normal_uv[2];
    vec4 metallic_roughness_uv[2];
    vec4 occlusion_uv[2];
};
layout(std430, set = 2, binding = 2) readonly buffer MaterialBlock {
    MaterialConstants materials[];
};
