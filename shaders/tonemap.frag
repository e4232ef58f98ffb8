#version 450
// The tone-map pass (engine/src/render/tonemap.rs): the shading pass's HDR radiance -> display. The one
// place where exposure and the tone-mapping operator are applied. The target is an _SRGB format,
// so the value written here is linear and the hardware does the sRGB encode.
//
// Operator: Reinhard's global operator on luminance, with the colour restored from the channel
// ratios (textures.md §5.7, ch.21 eqs. 21.3 / §5.5):
//   Ls = exposure * L;  Y = luminance(Ls);  Ld = Y / (1 + Y);  out_c = (Ls_c / Y)^s * Ld
// The notes recommend this sigmoid for real-time (ch.21 L13562), and on luminance rather than per
// channel: per-channel compression shifts hues towards white unevenly (each channel saturates on
// its own), while the ratio restore keeps the hue and `s` sets the saturation (s = 1 keeps the
// ratios exactly; s < 1 desaturates, which looks more natural for bright colours).

layout(set = 0, binding = 0) uniform sampler2D hdr; // R16G16B16A16_SFLOAT, linear radiance

// Mirrors `ToneMapPush` in engine/src/render/tonemap.rs.
layout(push_constant) uniform ToneMap {
    vec4 params; // x: exposure; y: 1 = tone map, 0 = pass through (display-referred input); z: s
} tm;

layout(location = 0) out vec4 out_color;

void main() {
    vec4 c = texelFetch(hdr, ivec2(gl_FragCoord.xy), 0);
    // Alpha 0 marks pixels no surface covered: the clear colour, display-referred, not radiance.
    if (tm.params.y < 0.5 || c.a == 0.0) {
        out_color = vec4(c.rgb, 1.0);
        return;
    }
    vec3 ls = max(c.rgb, 0.0) * tm.params.x;
    float y = dot(ls, vec3(0.2126, 0.7152, 0.0722));
    if (y <= 0.0) {
        out_color = vec4(0.0, 0.0, 0.0, 1.0);
        return;
    }
    float ld = y / (1.0 + y);
    out_color = vec4(clamp(pow(ls / y, vec3(tm.params.z)) * ld, 0.0, 1.0), 1.0);
}
