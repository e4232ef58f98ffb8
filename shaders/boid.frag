#version 450
#include "frame.glsl"

// Boids: a Lambertian bird in its material's base colour, lit by the sun, plus a constant sky
// fill standing in for the probes (the flock flies in the open, where the sky is most of the
// ambient). Double-sided: wings may be single triangles, so the normal is flipped to face the
// viewer.

layout(location = 0) in vec3 in_normal;
layout(location = 0) out vec4 out_color;

// The submesh's material base colour (linear RGBA).
layout(push_constant) uniform Push {
    vec4 base_color;
} push;

const float PI = 3.14159265;
// Sky fill as a fraction of the sun's illuminance (physical) or of the stand-in ambient.
const float SKY_FILL = 0.25;

void main() {
    vec3 ALBEDO = push.base_color.rgb;
    vec3 n = normalize(in_normal) * (gl_FrontFacing ? 1.0 : -1.0);
    float ndotl = max(dot(n, frame.sun_dir.xyz), 0.0);
    vec3 c;
    if (frame.exposure.y < 0.5) {
        c = ALBEDO * (frame.ambient.rgb + frame.sun_color.rgb * ndotl);
    } else {
        // Radiance of a Lambertian surface: albedo / pi * irradiance (sun in lux).
        c = ALBEDO / PI * frame.sun_color.rgb * (ndotl + SKY_FILL);
    }
    // Alpha 1: a surface, so the tone map treats it as radiance.
    out_color = vec4(c, 1.0);
}
