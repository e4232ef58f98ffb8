#version 450
//! variant counted COUNT_FRAGMENTS
// The shading pass after the depth pre-pass (compare EQUAL, no depth writes): only the visible
// fragment of each pixel passes, so it is tested before shading (early_fragment_tests: every
// invocation is one shaded pixel, as the pre-pass promises). Alpha testing already happened in
// the pre-pass: a discarded texel left the depth of what is behind it, which this surface's
// fragment does not match.
layout(early_fragment_tests) in;
#include "mesh_shading.glsl"

layout(location = 0) out vec4 out_color;

void main() {
    count_fragment();
    out_color = shade(albedo());
}
