#version 450

// Soft round particles: alpha falls off as 1 - r^2 from the quad's centre (r = 1 at the edge's
// midpoint), so a sprite has no hard square outline and needs no texture. The blend state
// (alpha or additive) is the pipeline's; both use src alpha as the weight.

layout(location = 0) in vec4 in_color;
layout(location = 1) in vec2 in_corner;

layout(location = 0) out vec4 out_color;

void main() {
    float falloff = clamp(1.0 - dot(in_corner, in_corner), 0.0, 1.0);
    if (falloff <= 0.0) {
        discard;
    }
    out_color = vec4(in_color.rgb, in_color.a * falloff);
}
