// Per-frame uniforms shared by every pass. Mirrors `FrameUniforms` in engine/src/renderer.rs.
layout(set = 0, binding = 0) uniform Frame {
    mat4 view_proj;
    vec4 camera_pos;   // xyz world position
    vec4 sun_dir;      // xyz unit vector towards the sun
    vec4 sun_color;    // rgb linear irradiance scale
    vec4 ambient;      // rgb linear ambient (stand-in until probes and lightmaps land)
} frame;
