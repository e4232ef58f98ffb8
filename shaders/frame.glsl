// Per-frame uniforms shared by every pass. Mirrors `FrameUniforms` in engine/src/render/renderer.rs.
layout(set = 0, binding = 0) uniform Frame {
    mat4 view_proj;
    // World -> the sun's shadow map: xy * 0.5 + 0.5 is the texture coordinate, z the depth
    // (0 nearest the sun). engine/src/render/shadow.rs.
    mat4 sun_view_proj;
    vec4 camera_pos;   // xyz world position
    vec4 sun_dir;      // xyz unit vector towards the sun
    vec4 sun_color;    // rgb linear irradiance scale
    vec4 ambient;      // rgb linear ambient (stand-in lighting only)
    vec4 exposure;     // x: exposure (the tone-map pass's); y: 1 = physical lighting (lightmaps, probes, sun in lux), tone-mapped
    vec4 shadow;       // x: 1 when the shadow map holds this frame's casters; y: one map texel in metres; z: 1 / map size
    vec4 features;     // x: 1 = specular (the material-maps switch picks pipelines: SLOTS, mesh_shading.glsl); y: the material textures' mip bias (log2 of the render scale)
} frame;

// Counted fragments (the renderer's fragment counter; written only by pipelines made with the
// COUNT_FRAGMENTS variants of mesh.frag and mesh_equal.frag). Mirrors `Renderer::fragment_count`.
layout(set = 0, binding = 1) buffer Counters {
    uint fragments;
} counters;
