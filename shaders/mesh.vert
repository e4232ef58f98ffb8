#version 450
//! variant depth DEPTH_ONLY
#include "frame.glsl"
#include "mesh_draw.glsl"
#include "octahedral.glsl"

// The pack's quantised vertex (engine/pack/src/vertex.rs): the position as stored, normal and
// tangent octahedral (the tangent's code carries the bitangent's sign), the texture
// coordinates unorm16 over the LOD's ranges (`draw.uv_ranges`), the colour unorm8.
layout(location = 0) in vec3 in_position;
layout(location = 1) in vec2 in_normal_oct;
layout(location = 2) in ivec2 in_tangent_code;
layout(location = 3) in vec2 in_uv0_q;
layout(location = 4) in vec2 in_uv1_q;
layout(location = 5) in vec4 in_color;
layout(location = 13) in vec2 in_texcoord1_q;

// Per instance (binding 1, the renderer's instance stream; `InstanceData` in batches.rs): the
// model matrix, the columns of its normal matrix (the inverse-transpose of the 3x3: non-uniform
// and mirrored scale), the w of the first being the page of the instance's lightmap region, and
// the region's transform of uv1 (xy scale, zw offset; zero without a region).
layout(location = 6) in mat4 in_model;
layout(location = 10) in vec4 in_normal0;
layout(location = 11) in vec3 in_normal1;
layout(location = 12) in vec3 in_normal2;
layout(location = 14) in vec4 in_lightmap;

// The depth pre-pass and the shading pass compute the position with this same code, and the
// shading pass's EQUAL test must pass exactly the pre-pass's winners: `precise` forbids the
// compiler to fuse or reorder the position's arithmetic differently in the two pipelines.
// (`invariant gl_Position` says the same but glslang puts it on a member of the gl_PerVertex
// block, which the validation layer's SPIR-V checker flags with a warning on every pipeline.)
precise gl_Position;

// The world position, and gl_Position from it: the one place both modules compute them.
vec4 place_vertex() {
    vec4 world = in_model * vec4(in_position, 1.0);
    gl_Position = frame.view_proj * world;
    return world;
}

#ifdef DEPTH_ONLY
// The depth-only pipelines' module (mesh_depth.vert, `//! variant depth`): the position alone.
// Lavapipe runs vertex shaders on one thread and a pipeline without a fragment shader still
// computed every output below (the material's five UV transforms read from a storage buffer).
void main() {
    place_vertex();
}
#else
layout(location = 0) out vec3 out_normal;
layout(location = 1) out vec2 out_base_color_uv;
layout(location = 2) out vec4 out_color;
layout(location = 3) out vec3 out_world;
layout(location = 4) out vec2 out_lightmap_uv;
layout(location = 5) out vec2 out_emissive_uv;
// The lightmap array's layer: the region's page plus the submesh's block.
layout(location = 6) flat out float out_lightmap_layer;
layout(location = 7) out vec4 out_tangent;
layout(location = 8) out vec2 out_normal_uv;
layout(location = 9) out vec2 out_metallic_roughness_uv;
layout(location = 10) out vec2 out_occlusion_uv;

// A texture slot's coordinates (`MaterialConstants` rows). Per vertex rather than per fragment:
// the transform is affine, so interpolating its result is the same as transforming the
// interpolated coordinates.
vec2 slot_uv(vec4 row0, vec4 row1, vec2 uv0, vec2 texcoord1) {
    vec3 uv = vec3(row0.w > 0.5 ? texcoord1 : uv0, 1.0);
    return vec2(dot(row0.xyz, uv), dot(row1.xyz, uv));
}

void main() {
    vec4 world = place_vertex();
    out_normal = mat3(in_normal0.xyz, in_normal1, in_normal2) * oct_decode(in_normal_oct);
    vec4 in_tangent = tangent_decode(in_tangent_code);
    vec2 uv0 = in_uv0_q * draw.uv_ranges[0].xy + draw.uv_ranges[0].zw;
    vec2 uv1 = in_uv1_q * draw.uv_ranges[1].xy + draw.uv_ranges[1].zw;
    vec2 texcoord1 = in_texcoord1_q * draw.uv_ranges[2].xy + draw.uv_ranges[2].zw;
    uint m = uint(draw.material.y);
    out_base_color_uv = slot_uv(materials[m].base_color_uv[0], materials[m].base_color_uv[1], uv0, texcoord1);
    out_emissive_uv = slot_uv(materials[m].emissive_uv[0], materials[m].emissive_uv[1], uv0, texcoord1);
    out_normal_uv = slot_uv(materials[m].normal_uv[0], materials[m].normal_uv[1], uv0, texcoord1);
    out_metallic_roughness_uv = slot_uv(materials[m].metallic_roughness_uv[0], materials[m].metallic_roughness_uv[1], uv0, texcoord1);
    out_occlusion_uv = slot_uv(materials[m].occlusion_uv[0], materials[m].occlusion_uv[1], uv0, texcoord1);
    // A tangent is a direction in the surface: it moves with the model matrix itself. A
    // mirroring instance (negative determinant) flips the frame's handedness.
    mat3 model3 = mat3(in_model);
    out_tangent = vec4(model3 * in_tangent.xyz, determinant(model3) < 0.0 ? -in_tangent.w : in_tangent.w);
    out_color = in_color;
    out_world = world.xyz;
    out_lightmap_uv = uv1 * in_lightmap.xy + in_lightmap.zw;
    out_lightmap_layer = in_normal0.w + draw.material.z;
}
#endif
