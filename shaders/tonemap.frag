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

// Mirrors `ToneMapPush` in engine/src/render/tonemap.rs (within 128 bytes, Vulkan's guaranteed
// push-constant size).
layout(push_constant) uniform ToneMap {
    vec4 params;        // x: exposure; y: 1 = tone map, 0 = pass through (display-referred input); z: s
    vec4 ray[3];        // the view ray through pixel (x, y): ray[0] + x ray[1] + y ray[2] (frame.rs SkyParams)
    vec4 sky;           // rgb: the sky's radiance (nits)
    vec4 sun;           // xyz: unit vector toward the sun; w: cos of its angular radius
    vec4 sun_disc;      // rgb: the disc's radiance (nits)
} tm;

layout(location = 0) out vec4 out_color;

// The pipeline's variant (tonemap.rs), a constant rather than a uniform branch, since a branch
// runs masked on lavapipe. Bit 0, SKY: the sky is behind what the frame drew (its code cost
// frames without a sky 3 ms at 720p). Bit 1, GAMMA2: the frame is drawn below the output's size
// and the upscaler (shaders/upscale.frag) reads this pass's output: it is written to a UNORM
// image as sqrt(colour), a perceptual encoding (gamma 2, as FSR 1 advises for its input) whose
// decode is one multiply.
layout(constant_id = 0) const int VARIANT = 1;
const bool SKY = (VARIANT & 1) != 0;
const bool GAMMA2 = (VARIANT & 2) != 0;

// The colour as the target stores it: linear for an _SRGB target (the hardware encodes), or
// gamma 2 for the upscaler's input, with the luma it finds edges by in alpha (computed once per
// texel here rather than for each of the 12 output pixels that read it).
vec4 encoded(vec3 c) {
    if (GAMMA2) {
        vec3 g = sqrt(c);
        return vec4(g, dot(g, vec3(0.25, 0.5, 0.25)));
    }
    return vec4(c, 1.0);
}

// The background's radiance along this pixel's view ray: the level's sky radiance in nits, as
// the baker lit the level with it, and the sun's disc (its illuminance spread over its solid
// angle, frame.rs `SkyParams`).
vec3 sky_radiance() {
    vec3 dir = normalize(tm.ray[0].xyz + gl_FragCoord.x * tm.ray[1].xyz + gl_FragCoord.y * tm.ray[2].xyz);
    return tm.sky.rgb + (dot(dir, tm.sun.xyz) >= tm.sun.w ? tm.sun_disc.rgb : vec3(0.0));
}

void main() {
    vec4 c = texelFetch(hdr, ivec2(gl_FragCoord.xy), 0);
    // With a sky, the frame was drawn over zero radiance and alpha 0, every pass compositing
    // premultiplied (surfaces alpha 1, glass and particles their coverage, MSAA's resolve the
    // average): what shows of the background is 1 - alpha of it. One pass over the pixels the
    // tone map visits anyway, instead of a sky pass of its own.
    if (SKY) {
        c = vec4(c.rgb + (1.0 - c.a) * sky_radiance(), 1.0);
    }
    // Alpha 0 marks pixels no surface covered: the clear colour, display-referred, not radiance.
    if (tm.params.y < 0.5 || c.a == 0.0) {
        out_color = encoded(c.rgb);
        return;
    }
    vec3 ls = max(c.rgb, 0.0) * tm.params.x;
    float y = dot(ls, vec3(0.2126, 0.7152, 0.0722));
    if (y <= 0.0) {
        out_color = encoded(vec3(0.0));
        return;
    }
    float ld = y / (1.0 + y);
    out_color = encoded(clamp(pow(ls / y, vec3(tm.params.z)) * ld, 0.0, 1.0));
}
