#version 450
// The spatial upscaler (engine/src/render/passes/upscale.rs): the tone-mapped frame drawn at the
// render scale -> the output. An implementation of the published algorithm of AMD FidelityFX
// Super Resolution 1's edge-adaptive spatial upsampler (EASU): per output pixel, the 12 input
// texels around it (the 4 nearest and their 8 edge neighbours) weighted by a Lanczos-2-like
// kernel stretched along the local edge and shortened across it, so an edge is resampled along
// its own direction (no stair steps, no blur across it), then clamped to the 4 nearest texels'
// range (no ringing).
//
// On CPU devices (lavapipe) the same 12 texels are weighted by the separable Catmull-Rom cubic
// instead (CUBIC, passes/upscale.rs): a sharp cubic (its negative lobes restore contrast the
// resampling takes), not edge-adaptive; measured there at 0.62x EASU's cost for the same SSIM
// against the full-size frame to within 0.003 (README, "Frame budget").
//
// Input: `low`, a UNORM image of the output's size whose top-left `in_size` texels hold the
// frame as sqrt(colour) (gamma 2, shaders/tonemap.frag GAMMA2) and its luma in alpha: the kernel
// works on perceptual values, as FSR 1 asks, and the decode is one multiply. Output: linear colour for the _SRGB
// target (the hardware encodes).

layout(set = 0, binding = 0) uniform sampler2D low;

layout(push_constant) uniform Upscale {
    // xy: input texels per output pixel (in_size / out_size); zw: the input's valid size in texels.
    vec4 scale;
} up;

layout(location = 0) out vec4 out_color;

layout(constant_id = 0) const bool CUBIC = false;

// The texel at integer `p`, clamped into the drawn region (the image is larger: texels past it
// hold nothing of this frame): gamma-2 colour, and its luma in alpha (the tone map's).
vec4 tap(ivec2 p) {
    ivec2 hi = ivec2(up.scale.zw) - 1;
    return texelFetch(low, clamp(p, ivec2(0), hi), 0);
}

// One of the four nearest texels' votes for the edge direction and its length (how much it looks
// like an edge rather than a gradient or noise), weighted by its bilinear weight `w`. `a` above,
// `b` left, `c` the texel, `d` right, `e` below.
void edge_vote(inout vec2 dir, inout float len, float w, float a, float b, float c, float d, float e) {
    // Horizontal: the gradient across the texel, and how one-sided it is.
    float dc = d - c;
    float cb = c - b;
    float lx = max(abs(dc), abs(cb));
    float dx = d - b;
    dir.x += dx * w;
    lx = clamp(abs(dx) / max(lx, 1e-5), 0.0, 1.0);
    len += lx * lx * w;
    // Vertical, likewise.
    float ec = e - c;
    float ca = c - a;
    float ly = max(abs(ec), abs(ca));
    float dy = e - a;
    dir.y += dy * w;
    ly = clamp(abs(dy) / max(ly, 1e-5), 0.0, 1.0);
    len += ly * ly * w;
}

// One tap's weight: the texel at `off` from the sample point (texels), in the kernel's frame
// (rotated onto the edge direction `dir`, scaled by `len2`), through the kernel with negative lobe
// `lob`: (25/16 (2/5 x^2 - 1)^2 - (25/16 - 1)) (lob x^2 - 1)^2, an approximation of Lanczos 2
// without trigonometry, its window clipped at x^2 = `clip`.
void accumulate(inout vec3 acc, inout float wsum, vec2 off, vec2 dir, vec2 len2, float lob, float clip, vec3 c) {
    vec2 v = vec2(off.x * dir.x + off.y * dir.y, off.x * -dir.y + off.y * dir.x) * len2;
    float d2 = min(dot(v, v), clip);
    float wb = 0.4 * d2 - 1.0;
    float wa = lob * d2 - 1.0;
    wb *= wb;
    wa *= wa;
    wb = 1.5625 * wb - 0.5625;
    float w = wb * wa;
    acc += c * w;
    wsum += w;
}

void main() {
    // The output pixel's centre in input texel space, relative to the texel whose centre is the
    // nearest up and to the left.
    vec2 pp = gl_FragCoord.xy * up.scale.xy - 0.5;
    vec2 fp = floor(pp);
    pp -= fp;
    ivec2 p = ivec2(fp);
    //    b c
    //  e f g h
    //  i j k l
    //    n o
    vec4 b = tap(p + ivec2(0, -1)), c = tap(p + ivec2(1, -1));
    vec4 e = tap(p + ivec2(-1, 0)), f = tap(p), g = tap(p + ivec2(1, 0)), h = tap(p + ivec2(2, 0));
    vec4 i = tap(p + ivec2(-1, 1)), j = tap(p + ivec2(0, 1)), k = tap(p + ivec2(1, 1)), l = tap(p + ivec2(2, 1));
    vec4 n = tap(p + ivec2(0, 2)), o = tap(p + ivec2(1, 2));
    float lb = b.a, lc = c.a, le = e.a, lf = f.a, lg = g.a, lh = h.a;
    float li = i.a, lj = j.a, lk = k.a, ll = l.a, ln = n.a, lo = o.a;

    if (CUBIC) {
        // Catmull-Rom weights per axis at the fraction pp; the 4x4's corners (a few percent of
        // the weight) left out, as EASU leaves them, and the rest renormalised.
        vec2 w0 = pp * (-0.5 + pp * (1.0 - 0.5 * pp));
        vec2 w1 = 1.0 + pp * pp * (-2.5 + 1.5 * pp);
        vec2 w2 = pp * (0.5 + pp * (2.0 - 1.5 * pp));
        vec2 w3 = pp * pp * (-0.5 + 0.5 * pp);
        vec3 acc = b.rgb * (w1.x * w0.y) + c.rgb * (w2.x * w0.y)
            + e.rgb * (w0.x * w1.y) + f.rgb * (w1.x * w1.y) + g.rgb * (w2.x * w1.y) + h.rgb * (w3.x * w1.y)
            + i.rgb * (w0.x * w2.y) + j.rgb * (w1.x * w2.y) + k.rgb * (w2.x * w2.y) + l.rgb * (w3.x * w2.y)
            + n.rgb * (w1.x * w3.y) + o.rgb * (w2.x * w3.y);
        float wsum = (w1.x + w2.x) * (w0.y + w3.y) + (w0.x + w1.x + w2.x + w3.x) * (w1.y + w2.y);
        // The cubic's overshoot clamped to the 4 nearest texels' range, as EASU's.
        vec3 lo4 = min(min(f.rgb, g.rgb), min(j.rgb, k.rgb));
        vec3 hi4 = max(max(f.rgb, g.rgb), max(j.rgb, k.rgb));
        vec3 cc = clamp(acc / wsum, lo4, hi4);
        out_color = vec4(cc * cc, 1.0);
        return;
    }
    // The edge direction and length: the four nearest texels' votes, bilinearly weighted.
    vec2 dir = vec2(0.0);
    float len = 0.0;
    edge_vote(dir, len, (1.0 - pp.x) * (1.0 - pp.y), lb, le, lf, lg, lj);
    edge_vote(dir, len, pp.x * (1.0 - pp.y), lc, lf, lg, lh, lk);
    edge_vote(dir, len, (1.0 - pp.x) * pp.y, lf, li, lj, lk, ln);
    edge_vote(dir, len, pp.x * pp.y, lg, lj, lk, ll, lo);
    float d2 = dot(dir, dir);
    bool flat_area = d2 < 1.0 / 32768.0;
    dir = flat_area ? vec2(1.0, 0.0) : dir * inversesqrt(d2);
    // len in [0, 1]: 0 a flat or noisy area (round kernel, soft lobe), 1 a clean edge
    // (kernel stretched along it up to sqrt(2) on diagonals, narrowed across it, sharper lobe).
    len = len * 0.5;
    len *= len;
    float stretch = 1.0 / max(abs(dir.x), abs(dir.y));
    vec2 len2 = vec2(1.0 + (stretch - 1.0) * len, 1.0 - 0.5 * len);
    float lob = 0.5 + (0.21 - 0.5) * len;
    float clip = 1.0 / lob;

    vec3 acc = vec3(0.0);
    float wsum = 0.0;
    accumulate(acc, wsum, vec2(0.0, -1.0) - pp, dir, len2, lob, clip, b.rgb);
    accumulate(acc, wsum, vec2(1.0, -1.0) - pp, dir, len2, lob, clip, c.rgb);
    accumulate(acc, wsum, vec2(-1.0, 1.0) - pp, dir, len2, lob, clip, i.rgb);
    accumulate(acc, wsum, vec2(0.0, 1.0) - pp, dir, len2, lob, clip, j.rgb);
    accumulate(acc, wsum, vec2(0.0, 0.0) - pp, dir, len2, lob, clip, f.rgb);
    accumulate(acc, wsum, vec2(-1.0, 0.0) - pp, dir, len2, lob, clip, e.rgb);
    accumulate(acc, wsum, vec2(1.0, 1.0) - pp, dir, len2, lob, clip, k.rgb);
    accumulate(acc, wsum, vec2(2.0, 1.0) - pp, dir, len2, lob, clip, l.rgb);
    accumulate(acc, wsum, vec2(2.0, 0.0) - pp, dir, len2, lob, clip, h.rgb);
    accumulate(acc, wsum, vec2(1.0, 0.0) - pp, dir, len2, lob, clip, g.rgb);
    accumulate(acc, wsum, vec2(1.0, 2.0) - pp, dir, len2, lob, clip, o.rgb);
    accumulate(acc, wsum, vec2(0.0, 2.0) - pp, dir, len2, lob, clip, n.rgb);
    // No ringing: within the four nearest texels' range.
    vec3 lo4 = min(min(f.rgb, g.rgb), min(j.rgb, k.rgb));
    vec3 hi4 = max(max(f.rgb, g.rgb), max(j.rgb, k.rgb));
    vec3 c2 = clamp(acc / wsum, lo4, hi4);
    out_color = vec4(c2 * c2, 1.0);
}
