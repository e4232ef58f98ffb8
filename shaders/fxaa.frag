#version 450
// Post-process anti-aliasing (engine/src/render/passes/fxaa.rs): Lottes' FXAA in its compact
// form. Luma from the four diagonal neighbours gives the edge's direction; two bilinear taps
// along it (at +-1/6 of the span) and two more (at +-1/2) are averaged, and the wider average is
// kept only if its luma stays within the neighbourhood's range (else it crossed another edge).
// Input: the tone-mapped frame (display colour, sampled as linear from an _SRGB image); luma
// is taken of the encoded value (perceptual, as FXAA wants), approximated by sqrt.

layout(set = 0, binding = 0) uniform sampler2D frame;

// Mirrors `FxaaPush` in fxaa.rs.
layout(push_constant) uniform Fxaa {
    vec4 params; // xy: 1 / the image's size in pixels; zw (GAMMA2): the drawn region's far corner in uv
} fx;

layout(location = 0) out vec4 out_color;

// Below the output's size (the render scale) FXAA runs before the upscaler, on its input: gamma
// 2 already (luma is taken of it as it is), in an image larger than the drawn region (taps are
// clamped into it, `params.zw`), and the upscaler wants the result's luma in alpha.
layout(constant_id = 0) const bool GAMMA2 = false;

const float REDUCE_MIN = 1.0 / 128.0;
const float REDUCE_MUL = 1.0 / 8.0;
const float SPAN_MAX = 8.0;

float luma(vec3 c) {
    return GAMMA2 ? dot(c, vec3(0.299, 0.587, 0.114)) : sqrt(dot(c, vec3(0.299, 0.587, 0.114)));
}

// The colour at `uv` (bilinear), within the drawn region.
vec3 at(vec2 uv) {
    if (GAMMA2) {
        uv = clamp(uv, 0.5 * fx.params.xy, fx.params.zw - 0.5 * fx.params.xy);
    }
    return texture(frame, uv).rgb;
}

void main() {
    vec2 px = fx.params.xy;
    vec2 uv = gl_FragCoord.xy * px;
    vec3 m = at(uv);
    float l_nw = luma(at(uv + vec2(-1.0, -1.0) * px));
    float l_ne = luma(at(uv + vec2(1.0, -1.0) * px));
    float l_sw = luma(at(uv + vec2(-1.0, 1.0) * px));
    float l_se = luma(at(uv + vec2(1.0, 1.0) * px));
    float l_m = luma(m);
    float l_min = min(l_m, min(min(l_nw, l_ne), min(l_sw, l_se)));
    float l_max = max(l_m, max(max(l_nw, l_ne), max(l_sw, l_se)));
    // Across the edge: the gradient of the diagonal lumas, turned along it.
    vec2 dir = vec2(-((l_nw + l_ne) - (l_sw + l_se)), (l_nw + l_sw) - (l_ne + l_se));
    float reduce = max((l_nw + l_ne + l_sw + l_se) * 0.25 * REDUCE_MUL, REDUCE_MIN);
    float scale = 1.0 / (min(abs(dir.x), abs(dir.y)) + reduce);
    dir = clamp(dir * scale, vec2(-SPAN_MAX), vec2(SPAN_MAX)) * px;
    vec3 a = 0.5 * (at(uv + dir * (1.0 / 3.0 - 0.5)) + at(uv + dir * (2.0 / 3.0 - 0.5)));
    vec3 b = a * 0.5 + 0.25 * (at(uv - dir * 0.5) + at(uv + dir * 0.5));
    float l_b = luma(b);
    vec3 c = (l_b < l_min || l_b > l_max) ? a : b;
    out_color = vec4(c, GAMMA2 ? dot(c, vec3(0.25, 0.5, 0.25)) : 1.0);
}
