#version 450
// The shading pass without a depth pre-pass: depth is tested and written here, so alpha-tested
// (MASK) materials discard here (or, multisampled, give their coverage as alpha).
#include "mesh_shading.glsl"

layout(location = 0) out vec4 out_color;

void main() {
    vec4 a = albedo();
    if (alpha_tested_away(a)) {
        discard;
    }
    count_fragment();
    out_color = vec4(shade(a).rgb, ALPHA_TO_COVERAGE ? coverage(a) : 1.0);
}
