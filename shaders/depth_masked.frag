#version 450
// Depth pre-pass for alpha-tested (MASK) materials: no colour, only the discard.
#include "mesh_shading.glsl"

void main() {
    if (alpha_tested_away(albedo())) {
        discard;
    }
}
