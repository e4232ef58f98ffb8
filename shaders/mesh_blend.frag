#version 450
// The transparent phase (glTF BLEND, engine/src/render/passes/transparent.rs): lit like an
// opaque surface, written premultiplied, (alpha L, alpha), for the "over" blend ONE,
// ONE_MINUS_SRC_ALPHA into the HDR target (alpha is coverage: it scales the specular and the
// emission too). Depth tested against the opaque depth, never written.
#include "mesh_shading.glsl"

layout(location = 0) out vec4 out_color;

void main() {
    vec4 a = albedo();
    count_fragment();
    vec4 l = shade(a);
    out_color = vec4(l.rgb * a.a, a.a);
}
