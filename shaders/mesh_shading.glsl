// What every mesh fragment shader shares: the draw's push constants and material constants
// (mesh_draw.glsl), the material's textures, the interpolated inputs, and the shading.
#include "frame.glsl"
#include "mesh_draw.glsl"

// Set 1: the material's textures, each with its own sampler; white where the slot is empty.
layout(set = 1, binding = 0) uniform sampler2D base_color_tex; // _SRGB format: sampled as linear
layout(set = 1, binding = 1) uniform sampler2D emissive_tex;   // _SRGB format: sampled as linear

// Set 2: the scene's baked light (engine/src/assets.rs). The lightmap pages as the layers of one
// array (one black layer without a bake), the probe grid, and the material constants.
layout(set = 2, binding = 0) uniform sampler2DArray lightmap; // B = H/pi in nits, half float
layout(std430, set = 2, binding = 1) readonly buffer Probes {
    vec4 origin;   // probe (i, j, k) at origin + (i, j, k) * spacing
    vec4 spacing;
    uvec4 counts;  // 0 when the pack has no probes
    float data[];  // per probe: 27 SH floats (9 x rgb, B = E/pi without the sun), sun visibility
} probes;

// The sun's shadow map (depth, 0 nearest the sun), sampled with a LESS_OR_EQUAL comparison and
// linear filtering: each lookup is a 2x2 PCF in hardware. Set 0 is the renderer's.
layout(set = 0, binding = 2) uniform sampler2DShadow sun_shadow_map;

layout(location = 0) in vec3 in_normal;
layout(location = 1) in vec2 in_base_color_uv;
layout(location = 2) in vec4 in_color;
layout(location = 3) in vec3 in_world;
layout(location = 4) in vec2 in_lightmap_uv;
layout(location = 5) in vec2 in_emissive_uv;
layout(location = 6) flat in float in_lightmap_layer;

// Set by the renderer's counting pipelines: each shaded fragment adds one to counters.fragments
// (helper invocations' atomics have no effect, so only real fragments count).
layout(constant_id = 0) const bool COUNT_FRAGMENTS = false;
// Set by the renderer for instances with a lightmap region (submeshes with a lightmap block):
// lit by the lightmap alone. A constant, not a push-constant branch, so each variant carries
// only its own lighting code (no branch, fewer registers): on lavapipe the demo flythrough's
// shading pass took about a third less time than with the branch (relative to the tone-map
// pass in the same frames).
layout(constant_id = 1) const bool LIGHTMAPPED = false;

void count_fragment() {
    if (COUNT_FRAGMENTS) {
        atomicAdd(counters.fragments, 1u);
    }
}

vec4 albedo() {
    return texture(base_color_tex, in_base_color_uv) * draw.base_color * in_color;
}

bool alpha_tested_away(vec4 a) {
    float cutoff = draw.material.x;
    return cutoff >= 0.0 && a.a < cutoff;
}

const float PI = 3.14159265;

// One probe's 28 floats start here.
uint probe_base(ivec3 c) {
    ivec3 n = ivec3(probes.counts.xyz);
    c = clamp(c, ivec3(0), n - 1);
    return uint(c.x + n.x * (c.y + n.y * c.z)) * 28u;
}

// Order-2 SH basis at unit n (cook_core::bake::probes: Y00, Y1-1, Y10, Y11, Y2-2, Y2-1, Y20, Y21, Y22).
float sh_basis(int i, vec3 n) {
    if (i == 0) return 0.2820948;
    if (i == 1) return 0.4886025 * n.y;
    if (i == 2) return 0.4886025 * n.z;
    if (i == 3) return 0.4886025 * n.x;
    if (i == 4) return 1.0925484 * n.x * n.y;
    if (i == 5) return 1.0925484 * n.y * n.z;
    if (i == 6) return 0.3153916 * (3.0 * n.z * n.z - 1.0);
    if (i == 7) return 1.0925484 * n.x * n.z;
    return 0.5462742 * (n.x * n.x - n.y * n.y);
}

// B(n) at p from the probe grid, trilinear over the 8 probes around p; and (w) the interpolated
// sun visibility. (0, 0, 0, 1) without probes.
vec4 probe_light(vec3 p, vec3 n) {
    if (probes.counts.x == 0u) {
        return vec4(0.0, 0.0, 0.0, 1.0);
    }
    vec3 g = (p - probes.origin.xyz) / probes.spacing.xyz;
    ivec3 c0 = ivec3(floor(g));
    vec3 f = clamp(g - vec3(c0), 0.0, 1.0);
    float y[9];
    for (int i = 0; i < 9; i++) {
        y[i] = sh_basis(i, n);
    }
    vec4 acc = vec4(0.0);
    for (int k = 0; k < 8; k++) {
        ivec3 o = ivec3(k & 1, (k >> 1) & 1, (k >> 2) & 1);
        vec3 w3 = mix(1.0 - f, f, vec3(o));
        float w = w3.x * w3.y * w3.z;
        uint b = probe_base(c0 + o);
        vec3 e = vec3(0.0);
        for (int i = 0; i < 9; i++) {
            e += y[i] * vec3(probes.data[b + 3u * uint(i)], probes.data[b + 3u * uint(i) + 1u], probes.data[b + 3u * uint(i) + 2u]);
        }
        acc += w * vec4(e, probes.data[b + 27u]);
    }
    // L2 SH rings below zero next to strong lobes: clamp.
    return vec4(max(acc.rgb, 0.0), acc.w);
}

// Fraction of the sun that reaches p (normal n) on a dynamic object: the shadow map with a 3x3
// PCF of 2x2-filtered taps when the renderer drew it this frame, else the probes' baked view of
// the sun (`probe_vis`), the stand-in.
float sun_visibility(vec3 p, vec3 n, float probe_vis) {
    if (frame.shadow.x < 0.5) {
        return probe_vis;
    }
    // Normal offset: look up a point 1.5 texels off the surface, so that the surface does not
    // shadow itself where its depth varies across a texel (acne); the rasteriser's slope-scaled
    // bias in the shadow pass covers the rest.
    vec4 c = frame.sun_view_proj * vec4(p + n * (1.5 * frame.shadow.y), 1.0);
    vec3 s = c.xyz / c.w;
    vec2 uv = s.xy * 0.5 + 0.5;
    float depth = min(s.z, 1.0);
    float lit = 0.0;
    for (int dy = -1; dy <= 1; dy++) {
        for (int dx = -1; dx <= 1; dx++) {
            lit += texture(sun_shadow_map, vec3(uv + vec2(dx, dy) * frame.shadow.z, depth));
        }
    }
    return lit / 9.0;
}

// Largest finite half float: the HDR target would store inf above it (and the tone map would
// turn that into NaN).
const float HALF_MAX = 65504.0;

// The fragment's linear radiance for the HDR target; alpha 1 marks it covered (the tone-map pass
// leaves alpha-0 pixels, the clear colour, as they are).
vec4 shade(vec4 a) {
    // Double-sided faces seen from behind shade with the flipped normal.
    vec3 n = normalize(gl_FrontFacing ? in_normal : -in_normal);
    float ndotl = max(dot(n, frame.sun_dir.xyz), 0.0);
    if (frame.exposure.y < 0.5) {
        // Stand-in lighting, display-referred already. Linear out; the _SRGB attachment encodes.
        return vec4(a.rgb * (frame.ambient.rgb + frame.sun_color.rgb * ndotl), 1.0);
    }
    // Physical: B = H/pi from the lightmap (baked static instances: it holds the sun too) or
    // from the probes plus the sun where the shadow map sees it (dynamic objects).
    vec3 b;
    if (LIGHTMAPPED) {
        b = texture(lightmap, vec3(in_lightmap_uv, in_lightmap_layer)).rgb;
    } else {
        vec4 pl = probe_light(in_world, n);
        b = pl.rgb + frame.sun_color.rgb * ndotl * sun_visibility(in_world, n, pl.w) / PI;
    }
    // Emission adds radiance on top of the reflected light, before exposure and tone mapping
    // (both in the tone-map pass).
    vec3 emission = materials[uint(draw.material.y)].emission.rgb * texture(emissive_tex, in_emissive_uv).rgb;
    vec3 l = a.rgb * b + emission;
    return vec4(min(l, HALF_MAX), 1.0);
}
