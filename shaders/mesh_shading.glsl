// What every mesh fragment shader shares: the draw's push constants and material constants
// (mesh_draw.glsl), the material's textures, the interpolated inputs, and the shading.
#include "frame.glsl"
#include "mesh_draw.glsl"

// Set 1: the material's textures, each with its own sampler; white where the slot is empty.
layout(set = 1, binding = 0) uniform sampler2D base_color_tex; // _SRGB format: sampled as linear
layout(set = 1, binding = 1) uniform sampler2D emissive_tex;   // _SRGB format: sampled as linear
layout(set = 1, binding = 2) uniform sampler2D normal_tex;     // xy: n.xy * 0.5 + 0.5 (white: no map, scale 0)
layout(set = 1, binding = 3) uniform sampler2D metallic_roughness_tex; // g: roughness, b: metallic
layout(set = 1, binding = 4) uniform sampler2D occlusion_tex;  // r

// Set 2: the scene's baked light (engine/src/assets.rs). The lightmap pages as the layers of one
// array (one black layer without a bake), the probe grid, and the material constants.
layout(set = 2, binding = 0) uniform sampler2DArray lightmap; // B = H/pi in nits, half float or BC6H
layout(std430, set = 2, binding = 1) readonly buffer Probes {
    vec4 origin;   // probe (i, j, k) at origin + (i, j, k) * spacing
    vec4 spacing;
    uvec4 counts;  // 0 when the pack has no probes
    float data[];  // per probe: 27 SH floats (9 x rgb, B = E/pi without the sun), sun visibility
} probes;
// The specular lobe's directional albedo split by Schlick, (A, B) over (n.v, roughness): a lobe
// of reflectance f0 returns f0 A + B of a uniform environment (engine/shading, `DfgLut`).
layout(set = 2, binding = 3) uniform sampler2D dfg_lut;
// Directional lightmaps (DIRECTIONAL): per page the luminance's L1 direction t, stored as
// (128 + 127 t) / 255 in rgb and the sun's visibility in a ("MonoSH", shading.md §4.2; RGBA8
// or BC7); `lightmap` then holds b0 (rgb).
layout(set = 2, binding = 4) uniform sampler2DArray lightmap_direction;
// Reflection probes (REFLECTIONS; shading.md §3): per probe a cube of radiance prefiltered for
// GGX, level k holding roughness k / (levels - 1), as layers of one cube-map array; and the
// probes, smallest box first (engine/src/assets.rs `reflection_probe_bytes`).
layout(set = 2, binding = 5) uniform samplerCubeArray reflection_cubes;
struct ReflectionProbe {
    vec4 box_min;   // xyz: the box (world, axis-aligned); w: blend distance (m)
    vec4 box_max;   // xyz; w: the probe's cube in reflection_cubes
    vec4 position;  // xyz: where the cube was captured
};
layout(std430, set = 2, binding = 6) readonly buffer ReflectionProbes {
    uvec4 info;     // x: probes, y: levels
    ReflectionProbe probe[];
} reflections;

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
layout(location = 7) in vec4 in_tangent;
layout(location = 8) in vec2 in_normal_uv;
layout(location = 9) in vec2 in_metallic_roughness_uv;
layout(location = 10) in vec2 in_occlusion_uv;

// Defined in the counting variants (`//! variant counted` in mesh.frag and mesh_equal.frag):
// each shaded fragment adds one to counters.fragments (helper invocations' atomics have no
// effect, so only real fragments count). A module of its own, not a specialisation constant:
// lavapipe takes any atomic in the SPIR-V, even under a constant that is false, for a write to
// the buffer, and then finishes all rendering before every draw that binds it (measured: about 60 us
// a draw, a third of the flythrough's shading pass).
// Set by the renderer for instances with a lightmap region (submeshes with a lightmap block):
// lit by the lightmap alone. A constant, not a push-constant branch, so each variant carries
// only its own lighting code (no branch, fewer registers): on lavapipe the demo flythrough's
// shading pass took about a third less time than with the branch (relative to the tone-map
// pass in the same frames).
layout(constant_id = 1) const bool LIGHTMAPPED = false;
// Samples per pixel of the target (1, or 4 with MSAA). Multisampled, an alpha-tested (MASK)
// fragment covers as many of its pixel's samples as its alpha says (alpha to coverage, done
// here with gl_SampleMask: the target's alpha stays 1, which the tone map's sky needs, and the
// depth-only pre-pass needs no colour output for it) instead of discarding.
layout(constant_id = 2) const int SAMPLES = 1;
const bool ALPHA_TO_COVERAGE = SAMPLES > 1;
// The material's texture slots a pipeline samples (`TextureSlots` in engine/src/scene/mod.rs:
// 1 base colour, 2 emissive, 4 normal, 8 metallic-roughness, 16 a separate occlusion texture).
// The renderer draws each material with a pipeline made for its slots, so no fragment samples
// the white stand-in of an empty slot: on lavapipe a branch is executed masked and the lookup
// costs the same taken or not (the emissive and occlusion lookups of materials without them
// were 10 of the 1280x720 flythrough's 43 shading ms). Every slot (31) leaves it to the material
// constants' flags at run time.
layout(constant_id = 3) const int SLOTS = 31;
const bool HAS_BASE_COLOR = (SLOTS & 1) != 0;
const bool HAS_EMISSIVE = (SLOTS & 2) != 0;
const bool HAS_NORMAL = (SLOTS & 4) != 0;
const bool HAS_METALLIC_ROUGHNESS = (SLOTS & 8) != 0;
const bool HAS_OCCLUSION = (SLOTS & 16) != 0;
// Set by the renderer for a LIGHTMAPPED variant when the scene's lightmaps are directional:
// B(n) = b0 (1 + 2 t.n), clamped at 0, for the shading normal n (its normal map shows under
// baked light), and the sun lit here through the full BRDF, times the baked visibility.
layout(constant_id = 4) const bool DIRECTIONAL = false;
// Set by the renderer (`Renderer::bicubic_lightmaps`) for LIGHTMAPPED variants: lightmaps are
// read through a cubic B-spline instead of bilinearly.
layout(constant_id = 5) const bool BICUBIC = false;
// Set by the renderer when the scene has reflection probes (`Renderer::reflections`): the
// specular environment is theirs, box-projected and blended, over the fallback.
layout(constant_id = 6) const bool REFLECTIONS = false;

// The material textures' mip bias: log2 of the render scale (0 at the output's size; -1 at half
// of it), so a frame drawn small and upscaled keeps the texture detail of the output's size, as
// upscalers ask (FSR 1: the bias makes the low-resolution frame sharper, EASU then resamples it).
#define MIP_BIAS frame.features.y

void count_fragment() {
#ifdef COUNT_FRAGMENTS
    atomicAdd(counters.fragments, 1u);
#endif
}

vec4 albedo() {
    vec4 t = HAS_BASE_COLOR && materials[uint(draw.material.y)].base_color_uv[1].w > 0.5 ? texture(base_color_tex, in_base_color_uv, MIP_BIAS) : vec4(1.0);
    return t * draw.base_color * in_color;
}

// Alpha at texture coordinate `uv` with vertex colour `color`, at this pixel's mip level.
float alpha_at(vec2 uv, vec4 color) {
    float t = HAS_BASE_COLOR && materials[uint(draw.material.y)].base_color_uv[1].w > 0.5 ? textureGrad(base_color_tex, uv, dFdx(in_base_color_uv), dFdy(in_base_color_uv)).a : 1.0;
    return t * draw.base_color.a * color.a;
}

// The share of the pixel's samples an alpha-tested fragment covers: the cutoff's edge
// sharpened to one pixel's width, so a MASK edge ramps over one pixel like a geometric edge
// instead of blurring over the texture's texels or stepping at the cutoff. 1 for opaque
// materials. Alpha's change over a pixel comes from sampling one pixel over in x and in y (the
// inputs' derivatives), not from fwidth(alpha): on lavapipe the helper invocations of a quad a
// triangle edge crosses give the texture's alpha wrongly, and fwidth(alpha) there reads a
// whole unit, which spread a triangle's diagonal as a line of half-covered pixels.
float coverage(vec4 a) {
    float cutoff = draw.material.x;
    if (cutoff < 0.0) {
        return 1.0;
    }
    vec2 uv = in_base_color_uv;
    float ax = alpha_at(uv + dFdx(uv), in_color + dFdx(in_color)) - a.a;
    float ay = alpha_at(uv + dFdy(uv), in_color + dFdy(in_color)) - a.a;
    return clamp((a.a - cutoff) / max(abs(ax) + abs(ay), 1e-4) + 0.5, 0.0, 1.0);
}

// The first round(coverage x SAMPLES) samples: a fixed pattern, so a ramp of coverage over an
// edge covers one more sample a step (the samples sit at different places in the pixel).
int coverage_mask(float c) {
    int n = int(c * float(SAMPLES) + 0.5);
    return (1 << n) - 1;
}

// Alpha tested against the material's cutoff. With ALPHA_TO_COVERAGE only a fragment that
// covers no sample is discarded; the rest are kept with their coverage (`coverage`).
bool alpha_tested_away(vec4 a) {
    float cutoff = draw.material.x;
    if (ALPHA_TO_COVERAGE) {
        return coverage(a) <= 0.0;
    }
    return cutoff >= 0.0 && a.a < cutoff;
}


const float PI = 3.14159265;

// A lightmap array's texel at `at` (uv, layer): bilinear; with BICUBIC the uniform cubic
// B-spline over the 4x4 texels around it, as four bilinear taps placed so the hardware's
// weights make the spline's (Sigg and Hadwiger, GPU Gems 2 ch. 20). Its weights are never
// negative (no ringing below 0 next to a shadow) and its slope is continuous across texels,
// where bilinear's kinks at every texel draw a baked shadow's edge as visible steps.
vec4 lightmap_at(sampler2DArray map, vec3 at) {
    if (!BICUBIC) {
        return texture(map, at);
    }
    vec2 size = vec2(textureSize(map, 0).xy);
    vec2 p = at.xy * size - 0.5;
    vec2 i = floor(p);
    vec2 f = p - i;
    vec2 f2 = f * f;
    vec2 f3 = f2 * f;
    vec2 w0 = (1.0 - 3.0 * f + 3.0 * f2 - f3) / 6.0;
    vec2 w1 = (4.0 - 6.0 * f2 + 3.0 * f3) / 6.0;
    vec2 w2 = (1.0 + 3.0 * f + 3.0 * f2 - 3.0 * f3) / 6.0;
    vec2 w3 = f3 / 6.0;
    vec2 g0 = w0 + w1;
    vec2 g1 = w2 + w3;
    // Tap positions (texel centres at i + 0.5): between texels i-1 and i, and i+1 and i+2.
    vec2 t0 = (i - 0.5 + w1 / g0) / size;
    vec2 t1 = (i + 1.5 + w3 / g1) / size;
    return g0.y * (g0.x * texture(map, vec3(t0.x, t0.y, at.z)) + g1.x * texture(map, vec3(t1.x, t0.y, at.z)))
         + g1.y * (g0.x * texture(map, vec3(t0.x, t1.y, at.z)) + g1.x * texture(map, vec3(t1.x, t1.y, at.z)));
}

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

// B(n) at p from the probe grid, trilinear over the 8 probes around p, with (w) the
// interpolated sun visibility; and in `at_r` the same B in the direction r (the rough
// environment the specular lobe reflects until reflection probes exist). (0, 0, 0, 1) and 0
// without probes.
vec4 probe_light(vec3 p, vec3 n, vec3 r, out vec3 at_r) {
    at_r = vec3(0.0);
    if (probes.counts.x == 0u) {
        return vec4(0.0, 0.0, 0.0, 1.0);
    }
    vec3 g = (p - probes.origin.xyz) / probes.spacing.xyz;
    ivec3 c0 = ivec3(floor(g));
    vec3 f = clamp(g - vec3(c0), 0.0, 1.0);
    float y[9];
    float yr[9];
    for (int i = 0; i < 9; i++) {
        y[i] = sh_basis(i, n);
        yr[i] = sh_basis(i, r);
    }
    vec4 acc = vec4(0.0);
    vec3 acc_r = vec3(0.0);
    for (int k = 0; k < 8; k++) {
        ivec3 o = ivec3(k & 1, (k >> 1) & 1, (k >> 2) & 1);
        vec3 w3 = mix(1.0 - f, f, vec3(o));
        float w = w3.x * w3.y * w3.z;
        uint b = probe_base(c0 + o);
        vec3 e = vec3(0.0);
        vec3 e_r = vec3(0.0);
        for (int i = 0; i < 9; i++) {
            vec3 c = vec3(probes.data[b + 3u * uint(i)], probes.data[b + 3u * uint(i) + 1u], probes.data[b + 3u * uint(i) + 2u]);
            e += y[i] * c;
            e_r += yr[i] * c;
        }
        acc += w * vec4(e, probes.data[b + 27u]);
        acc_r += w * e_r;
    }
    // L2 SH rings below zero next to strong lobes: clamp.
    at_r = max(acc_r, 0.0);
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

// The shading normal: the interpolated normal tilted by the normal map in the frame of the
// interpolated tangent (Gram-Schmidt against the normal; B = cross(N, T) * w, glTF), the map's
// xy scaled by normalTexture.scale (0 without a map: the white texel then leaves N as it is).
// Double-sided faces seen from behind shade with the whole frame flipped.
vec3 shading_normal(float scale) {
    vec3 n = normalize(in_normal);
    vec3 t = in_tangent.xyz - n * dot(n, in_tangent.xyz);
    float tl = dot(t, t);
    if (HAS_NORMAL && scale != 0.0 && tl > 1e-12) {
        // x and y only, z rebuilt (the map is unit length, z >= 0 in tangent space): BC5 keeps
        // two channels, and every normal format reads the same way.
        vec2 xy = texture(normal_tex, in_normal_uv, MIP_BIAS).xy * 2.0 - 1.0;
        vec3 ts = vec3(xy * scale, sqrt(max(1.0 - dot(xy, xy), 0.0)));
        t *= inversesqrt(tl);
        vec3 b = cross(n, t) * (in_tangent.w < 0.0 ? -1.0 : 1.0);
        n = normalize(ts.x * t + ts.y * b + ts.z * n);
    }
    return gl_FrontFacing ? n : -n;
}

// Filament's fp16-safe floor on roughness (alpha >= 0.002).
const float MIN_ROUGHNESS = 0.045;

// GGX / Trowbridge-Reitz.
float d_ggx(float nh, float a) {
    float a2 = a * a;
    float d = nh * nh * (a2 - 1.0) + 1.0;
    return a2 / (PI * d * d);
}

// Height-correlated Smith visibility G / (4 n.l n.v).
float vis_smith(float nl, float nv, float a) {
    float a2 = a * a;
    float gv = nl * sqrt(a2 + (1.0 - a2) * nv * nv);
    float gl = nv * sqrt(a2 + (1.0 - a2) * nl * nl);
    return 0.5 / max(gv + gl, 1e-12);
}

// The sun's light that a surface (normal n, toward the eye v) reflects toward the eye, times the
// fraction of the sun it sees: [(1 - m)(1 - F_d) base / pi + F D Vis] E n.l; without specular,
// the diffuse term alone (kd / pi).
vec3 sun_reflected(vec3 n, vec3 v, vec3 kd, vec3 f0, float alpha, float nv, bool specular, float visibility) {
    vec3 sun_l = frame.sun_dir.xyz;
    float nl = dot(n, sun_l);
    if (nl <= 0.0) {
        return vec3(0.0);
    }
    if (!specular) {
        return kd / PI * frame.sun_color.rgb * nl * visibility;
    }
    vec3 h = normalize(v + sun_l);
    float vh = max(dot(v, h), 0.0);
    float w = pow(1.0 - vh, 5.0);
    vec3 f = f0 + (1.0 - f0) * w;
    float fd = 0.04 + 0.96 * w;
    vec3 brdf = kd * (1.0 - fd) / PI + f * (d_ggx(max(dot(n, h), 0.0), alpha) * vis_smith(nl, nv, alpha));
    return brdf * frame.sun_color.rgb * nl * visibility;
}

// The prefiltered radiance toward r (the split sum's first term, shading.md §3) at p for
// perceptual roughness `rough`: each probe takes its weight's share of what the smaller probes
// before it left, `fallback` the rest (§3.6). The weight is 1 in the probe's box, faces
// included, and fades to 0 over its blend distance outside them: a room's box is the room, and
// its floor and walls, which lie on the box's faces, are what it must light (fading inside the
// faces, as §3.6 has it, left them to the fallback). The direction is box-projected: where the
// ray from p (clamped into the box) leaves the box, seen from the capture point (§3.5; exact
// for mirrors).
vec3 probe_reflection(vec3 p, vec3 r, float rough, vec3 fallback) {
    float lod = rough * float(reflections.info.y - 1u);
    vec3 c = vec3(0.0);
    float rest = 1.0;
    for (uint i = 0u; i < reflections.info.x && rest > 0.0; ++i) {
        vec3 lo = reflections.probe[i].box_min.xyz;
        vec3 hi = reflections.probe[i].box_max.xyz;
        vec3 q = clamp(p, lo, hi);
        float outside = distance(p, q);
        // At least a centimetre of fade: a floor on the box's face is not outside by rounding.
        float blend = max(reflections.probe[i].box_min.w, 0.01);
        float w = max(1.0 - outside / blend, 0.0);
        if (w <= 0.0) {
            continue;
        }
        // The ray's exit: the nearest of the far slab planes (r's zero components give +inf).
        vec3 far = max((hi - q) / r, (lo - q) / r);
        float t = min(far.x, min(far.y, far.z));
        vec3 dir = q + t * r - reflections.probe[i].position.xyz;
        c += rest * w * textureLod(reflection_cubes, vec4(dir, reflections.probe[i].box_max.w), lod).rgb;
        rest *= 1.0 - w;
    }
    return c + rest * fallback;
}

// The fragment's linear radiance for the HDR target; alpha 1 marks it covered (the tone-map pass
// leaves alpha-0 pixels, the clear colour, as they are). glTF metallic-roughness
// (engine/shading is the same model on the CPU, ../shared/notes/shading.md 2.2 and 5):
//   sun:      [(1 - m)(1 - F_d) base / pi + F D Vis] E n.l visibility   (dynamic objects)
//   indirect: (1 - m) base w_d B ao + env (f0 A + B) ao,  w_d = 1 - (0.04 A + B)
// B is the lightmap (static; directional ones leave the sun to the sun term, which then draws
// its highlight too) or the probes (dynamic); env is the reflection probes' prefiltered
// radiance (REFLECTIONS), over a rough stand-in where they do not reach: the irradiance probes'
// B in the reflected direction, or the lightmap's B on lightmapped surfaces.
vec4 shade(vec4 a) {
    // Read member by member: copying the whole block costs every field's load on lavapipe.
    uint m = uint(draw.material.y);
    vec4 pbr = materials[m].pbr;
    // The renderer's specular switch (uniform: every invocation takes the same branch). Its
    // material-maps switch picks pipelines whose SLOTS hold the base colour alone.
    bool specular = frame.features.x > 0.5;
    vec3 n = shading_normal(pbr.z);
    if (frame.exposure.y < 0.5) {
        // Stand-in lighting, display-referred already. Linear out; the _SRGB attachment encodes.
        float ndotl = max(dot(n, frame.sun_dir.xyz), 0.0);
        return vec4(a.rgb * (frame.ambient.rgb + frame.sun_color.rgb * ndotl), 1.0);
    }
    vec4 mr = HAS_METALLIC_ROUGHNESS && materials[m].metallic_roughness_uv[1].w > 0.5 ? texture(metallic_roughness_tex, in_metallic_roughness_uv, MIP_BIAS) : vec4(1.0);
    float metallic = clamp(pbr.x * mr.b, 0.0, 1.0);
    float rough = clamp(pbr.y * mr.g, MIN_ROUGHNESS, 1.0);
    float alpha = rough * rough;
    // Occlusion's flag is 2 when it is the metallic-roughness texture's red at the same
    // coordinates (a packed ORM texture): one sample serves both.
    float occlusion_flag = materials[m].occlusion_uv[1].w;
    float ao = 1.0;
    if (HAS_OCCLUSION && occlusion_flag > 0.5 && occlusion_flag < 1.5) {
        ao = 1.0 + pbr.w * (texture(occlusion_tex, in_occlusion_uv, MIP_BIAS).r - 1.0);
    } else if (HAS_METALLIC_ROUGHNESS && occlusion_flag > 1.5) {
        ao = 1.0 + pbr.w * (mr.r - 1.0);
    }
    vec3 v = normalize(frame.camera_pos.xyz - in_world);
    float nv = max(dot(n, v), 1e-4);
    vec3 f0 = mix(vec3(0.04), a.rgb, metallic);
    // Without specular the table's (A, B) are 0: w_d = 1 and no environment reflection.
    // The table's first and last texels are the ends of both ranges (shading::DfgLut).
    vec2 lut_size = vec2(textureSize(dfg_lut, 0));
    vec2 dfg = specular ? texture(dfg_lut, (vec2(nv, rough) * (lut_size - 1.0) + 0.5) / lut_size).xy : vec2(0.0);
    vec3 kd = a.rgb * (1.0 - metallic);
    // Rough lobes lean toward the normal (Frostbite's dominant direction).
    vec3 r = reflect(-v, n);
    float s = 1.0 - alpha;
    vec3 r_dom = normalize(mix(n, r, s * (sqrt(s) + alpha)));

    vec3 b;
    vec3 env;
    vec3 l = vec3(0.0);
    if (LIGHTMAPPED && DIRECTIONAL) {
        vec3 at = vec3(in_lightmap_uv, in_lightmap_layer);
        vec3 b0 = lightmap_at(lightmap, at).rgb;
        vec4 dir = lightmap_at(lightmap_direction, at);
        vec3 t = (dir.xyz * 255.0 - 128.0) / 127.0;
        b = b0 * max(1.0 + 2.0 * dot(t, n), 0.0);
        // The rough environment: the same light toward the lobe's dominant direction.
        env = b0 * max(1.0 + 2.0 * dot(t, r_dom), 0.0);
        l += sun_reflected(n, v, kd, f0, alpha, nv, specular, dir.a);
    } else if (LIGHTMAPPED) {
        b = lightmap_at(lightmap, vec3(in_lightmap_uv, in_lightmap_layer)).rgb;
        // The lightmap's B stands for the environment too (no probe code in this variant: it
        // is most of the screen).
        env = b;
    } else {
        vec4 pl = probe_light(in_world, n, r_dom, env);
        b = pl.rgb;
        l += sun_reflected(n, v, kd, f0, alpha, nv, specular, sun_visibility(in_world, n, pl.w));
    }
    if (REFLECTIONS && specular) {
        // The roughness as authored picks the level: a mirror (0) reads the capture itself,
        // not the blur MIN_ROUGHNESS (a guard for the sun's peak) would mix in.
        env = probe_reflection(in_world, r_dom, clamp(pbr.y * mr.g, 0.0, 1.0), env);
    }
    float wd = 1.0 - (0.04 * dfg.x + dfg.y);
    l += (kd * wd * b + env * (f0 * dfg.x + dfg.y)) * ao;
    // Emission adds radiance on top of the reflected light, before exposure and tone mapping
    // (both in the tone-map pass).
    vec3 emission = materials[m].emission.rgb;
    if (HAS_EMISSIVE && materials[m].emissive_uv[1].w > 0.5) {
        emission *= texture(emissive_tex, in_emissive_uv, MIP_BIAS).rgb;
    }
    l += emission;
    return vec4(min(l, HALF_MAX), 1.0);
}
