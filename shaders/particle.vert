#version 450
#include "frame.glsl"

// Camera-facing particle quads (engine/src/render/particles_draw.rs): one instance per billboard
// (`sim::particles::Billboard`), four vertices of a triangle strip made from gl_VertexIndex.

layout(location = 0) in vec4 in_pos_size; // xyz world centre, w edge length in metres
layout(location = 1) in vec4 in_color;    // linear rgb, alpha

// Mirrors `ParticlePush` in engine/src/render/particles_draw.rs: the camera's world right and up axes,
// so every quad faces the camera plane (no per-particle rotation on the GPU).
layout(push_constant) uniform Axes {
    vec4 right;
    vec4 up;
} axes;

layout(location = 0) out vec4 out_color;
layout(location = 1) out vec2 out_corner; // -1..1 across the quad, for the soft falloff

void main() {
    vec2 corner = vec2((gl_VertexIndex & 1) != 0 ? 1.0 : -1.0, (gl_VertexIndex & 2) != 0 ? 1.0 : -1.0);
    vec3 p = in_pos_size.xyz + (axes.right.xyz * corner.x + axes.up.xyz * corner.y) * (0.5 * in_pos_size.w);
    gl_Position = frame.view_proj * vec4(p, 1.0);
    // Particles are emissive: their colour is what they should look like on screen. Under
    // physical lighting the tone map multiplies by the exposure, so divide it out here.
    float scale = frame.exposure.y > 0.5 ? 1.0 / max(frame.exposure.x, 1e-8) : 1.0;
    out_color = vec4(in_color.rgb * scale, in_color.a);
    out_corner = corner;
}
