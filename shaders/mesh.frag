#version 450
#include "frame.glsl"

layout(set = 1, binding = 0) uniform sampler2D base_color_tex; // _SRGB format: sampled as linear

layout(push_constant) uniform Draw {
    mat4 model;
    vec4 normal_cols[3];
    vec4 base_color;
} draw;

layout(location = 0) in vec3 in_normal;
layout(location = 1) in vec2 in_uv0;
layout(location = 2) in vec4 in_color;

layout(location = 0) out vec4 out_color;

void main() {
    vec4 albedo = texture(base_color_tex, in_uv0) * draw.base_color * in_color;
    // Alpha-tested (MASK) materials carry their cutoff here; others carry -1.
    float cutoff = draw.normal_cols[0].w;
    if (cutoff >= 0.0 && albedo.a < cutoff) {
        discard;
    }
    // Double-sided faces seen from behind shade with the flipped normal.
    vec3 n = normalize(gl_FrontFacing ? in_normal : -in_normal);
    float ndotl = max(dot(n, frame.sun_dir.xyz), 0.0);
    vec3 lit = albedo.rgb * (frame.ambient.rgb + frame.sun_color.rgb * ndotl);
    // Linear out; the _SRGB attachment encodes.
    out_color = vec4(lit, albedo.a);
}
