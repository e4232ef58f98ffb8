#version 450
// Depth pre-pass for alpha-tested (MASK) materials: no colour, only the discard; multisampled,
// the samples the alpha covers (gl_SampleMask), whose depth the shading pass then matches.
#include "mesh_shading.glsl"

void main() {
    vec4 a = albedo();
    if (alpha_tested_away(a)) {
        discard;
    }
    // Written on every path (an unwritten sample mask is undefined): all samples unless
    // alpha to coverage.
    gl_SampleMask[0] = ALPHA_TO_COVERAGE ? coverage_mask(coverage(a)) : -1;
}
