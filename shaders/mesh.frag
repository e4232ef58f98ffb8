#version 450
// The shading pass without a depth pre-pass: depth is tested and written here, so alpha-tested
// (MASK) materials discard here.
#include "mesh_shading.glsl"

layout(location = 0) out vec4 out_color;

void main() {
    vec4 a = albedo();
    if (alpha_tested_away(a)) {
        discard;
    }
    count_fragment();
    out_color = shade(a);
}
