#version 450
//! variant counted COUNT_FRAGMENTS
// The shading pass without a depth pre-pass: depth is tested and written here, so alpha-tested
// (MASK) materials discard here (or, multisampled, cover the samples their alpha says).
#include "mesh_shading.glsl"

layout(location = 0) out vec4 out_color;

void main() {
    vec4 a = albedo();
    if (alpha_tested_away(a)) {
        discard;
    }
    count_fragment();
    // Written on every path (an unwritten sample mask is undefined): all samples unless
    // alpha to coverage.
    gl_SampleMask[0] = ALPHA_TO_COVERAGE ? coverage_mask(coverage(a)) : -1;
    out_color = shade(a);
}
