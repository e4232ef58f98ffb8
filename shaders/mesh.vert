#version 450
#include "frame.glsl"

layout(location = 0) in vec3 in_position;
layout(location = 1) in vec3 in_normal;
layout(location = 3) in vec2 in_uv0;
layout(location = 4) in vec2 in_uv1;
layout(location = 5) in vec4 in_color;
// Location 2 (tangent) exists in the vertex format but is not read yet.

// Per instance (binding 1, the renderer's instance stream; `InstanceData` in batches.rs): the
// model matrix and its normal matrix, the inverse-transpose of the 3x3 (non-uniform and mirrored
// scale).
layout(location = 6) in mat4 in_model;
layout(location = 10) in mat3 in_normal_matrix;

layout(location = 0) out vec3 out_normal;
// The depth pre-pass and the shading pass run this same shader, and the shading pass's EQUAL
// test must pass exactly the pre-pass's winners: `precise` forbids the compiler to fuse or
// reorder the position's arithmetic differently in the two pipelines. (`invariant gl_Position`
// says the same but glslang puts it on a member of the gl_PerVertex block, which the validation
// layer's SPIR-V checker flags with a warning on every pipeline.)
precise gl_Position;
layout(location = 1) out vec2 out_uv0;
layout(location = 2) out vec4 out_color;
layout(location = 3) out vec3 out_world;
layout(location = 4) out vec2 out_uv1;

void main() {
    vec4 world = in_model * vec4(in_position, 1.0);
    out_normal = in_normal_matrix * in_normal;
    out_uv0 = in_uv0;
    out_color = in_color;
    out_world = world.xyz;
    out_uv1 = in_uv1;
    gl_Position = frame.view_proj * world;
}
