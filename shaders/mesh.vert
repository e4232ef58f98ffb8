#version 450
#include "frame.glsl"

layout(location = 0) in vec3 in_position;
layout(location = 1) in vec3 in_normal;
layout(location = 3) in vec2 in_uv0;
layout(location = 4) in vec2 in_uv1;
layout(location = 5) in vec4 in_color;
// Location 2 (tangent) exists in the vertex format but is not read yet.

// 128 bytes: the minimum every device guarantees. Mirrors `DrawPush` in renderer.rs.
layout(push_constant) uniform Draw {
    mat4 model;
    vec4 normal_cols[3]; // inverse-transpose of model's 3x3 (handles non-uniform and mirrored scale)
    vec4 base_color;
} draw;

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
    vec4 world = draw.model * vec4(in_position, 1.0);
    mat3 normal_matrix = mat3(draw.normal_cols[0].xyz, draw.normal_cols[1].xyz, draw.normal_cols[2].xyz);
    out_normal = normal_matrix * in_normal;
    out_uv0 = in_uv0;
    out_color = in_color;
    out_world = world.xyz;
    out_uv1 = in_uv1;
    gl_Position = frame.view_proj * world;
}
