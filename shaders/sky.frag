#version 450
// The sky pass (engine/src/render/passes/sky.rs): where no surface was drawn (depth still at the
// far plane, tested EQUAL), the level's sky radiance in nits, as the baker lit the level with
// it, and the sun's disc: its illuminance spread over its solid angle. Alpha 1: radiance, for
// the tone map like any surface.

// Mirrors `SkyPush` in sky.rs.
layout(push_constant) uniform Sky {
    mat4 inv_view_proj;
    vec4 sky;      // rgb: radiance (nits)
    vec4 sun;      // xyz: unit vector toward the sun; w: cos of its angular radius
    vec4 sun_disc; // rgb: the disc's radiance (nits)
    vec4 viewport; // xy: size in pixels
} s;

layout(location = 0) out vec4 out_color;

// Largest finite half float (the HDR target).
const float HALF_MAX = 65504.0;

void main() {
    vec2 ndc = gl_FragCoord.xy / s.viewport.xy * 2.0 - 1.0;
    // Two points along the pixel's ray (reverse Z: 1 is the near plane, 0.5 twice as far).
    vec4 a = s.inv_view_proj * vec4(ndc, 1.0, 1.0);
    vec4 b = s.inv_view_proj * vec4(ndc, 0.5, 1.0);
    vec3 dir = normalize(b.xyz / b.w - a.xyz / a.w);
    vec3 l = s.sky.rgb;
    if (dot(dir, s.sun.xyz) >= s.sun.w) {
        l += s.sun_disc.rgb;
    }
    out_color = vec4(min(l, HALF_MAX), 1.0);
}
