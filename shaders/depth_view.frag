#version 450
// The depth view (engine/src/render/passes/depth_view.rs), a debug pass: the camera's depth
// buffer as grey. With reversed-Z and an infinite far plane the stored depth is znear / z (z the
// distance along the view axis), so the grey is exactly that: white at the near plane, halving
// with each doubling of distance, black at infinity (where nothing was drawn).

layout(set = 0, binding = 0) uniform sampler2D depth;

// Mirrors `DepthViewPush` in depth_view.rs.
layout(push_constant) uniform DepthView {
    vec4 params; // x: gain (1: the raw znear / z)
} dv;

layout(location = 0) out vec4 color;

void main() {
    float d = texelFetch(depth, ivec2(gl_FragCoord.xy), 0).r;
    color = vec4(vec3(clamp(d * dv.params.x, 0.0, 1.0)), 1.0);
}
