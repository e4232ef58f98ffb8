// What every mesh fragment shader shares: the draw's push constants (mirrors `DrawPush` in
// engine/src/renderer.rs), the base colour texture, the interpolated inputs, and the shading.
#include "frame.glsl"

layout(set = 1, binding = 0) uniform sampler2D base_color_tex; // _SRGB format: sampled as linear

layout(push_constant) uniform Draw {
    mat4 model;
    vec4 normal_cols[3]; // column 0's w: alpha-test cutoff, or -1 for none
    vec4 base_color;
} draw;

layout(location = 0) in vec3 in_normal;
layout(location = 1) in vec2 in_uv0;
layout(location = 2) in vec4 in_color;

// Set by the renderer's counting pipelines: each shaded fragment adds one to counters.fragments
// (helper invocations' atomics have no effect, so only real fragments count).
layout(constant_id = 0) const bool COUNT_FRAGMENTS = false;

void count_fragment() {
    if (COUNT_FRAGMENTS) {
        atomicAdd(counters.fragments, 1u);
    }
}

vec4 albedo() {
    return texture(base_color_tex, in_uv0) * draw.base_color * in_color;
}

bool alpha_tested_away(vec4 a) {
    float cutoff = draw.normal_cols[0].w;
    return cutoff >= 0.0 && a.a < cutoff;
}

vec4 shade(vec4 a) {
    // Double-sided faces seen from behind shade with the flipped normal.
    vec3 n = normalize(gl_FrontFacing ? in_normal : -in_normal);
    float ndotl = max(dot(n, frame.sun_dir.xyz), 0.0);
    vec3 lit = a.rgb * (frame.ambient.rgb + frame.sun_color.rgb * ndotl);
    // Linear out; the _SRGB attachment encodes.
    return vec4(lit, a.a);
}
