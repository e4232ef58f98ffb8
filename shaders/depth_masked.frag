#version 450
// Depth pre-pass for alpha-tested (MASK) materials: no colour, only the discard; multisampled,
// alpha-to-coverage reads output 0's alpha (there is no colour attachment to write).
#include "mesh_shading.glsl"

layout(location = 0) out vec4 out_coverage;

void main() {
    vec4 a = albedo();
    if (alpha_tested_away(a)) {
        discard;
    }
    out_coverage = vec4(0.0, 0.0, 0.0, coverage(a));
}
