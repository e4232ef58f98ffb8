// The octahedral unit vectors of the pack's vertices (engine/pack/src/vertex.rs is the same code
// on the CPU; its tests bound the error): a direction folded onto [-1, 1]², two snorm16.

vec3 oct_decode(vec2 e) {
    vec3 v = vec3(e, 1.0 - abs(e.x) - abs(e.y));
    float t = max(-v.z, 0.0);
    v.xy += vec2(v.x >= 0.0 ? -t : t, v.y >= 0.0 ? -t : t);
    return normalize(v);
}

vec2 oct_encode(vec3 n) {
    float l1 = abs(n.x) + abs(n.y) + abs(n.z);
    if (!(l1 > 0.0)) {
        return vec2(0.0);
    }
    vec2 e = n.xy / l1;
    if (n.z < 0.0) {
        e = (1.0 - abs(e.yx)) * vec2(e.x >= 0.0 ? 1.0 : -1.0, e.y >= 0.0 ? 1.0 : -1.0);
    }
    return e;
}

// A tangent's code (two i16): octahedral x as snorm16; y as c in 1..32767 with
// y = (c - 16384) / 16383, negated for a negative bitangent sign (w).
vec4 tangent_decode(ivec2 c) {
    float x = max(float(c.x) / 32767.0, -1.0);
    float y = (float(abs(c.y)) - 16384.0) / 16383.0;
    return vec4(oct_decode(vec2(x, y)), c.y < 0 ? -1.0 : 1.0);
}

ivec2 tangent_encode(vec4 t) {
    vec2 e = oct_encode(t.xyz);
    int c = int(round(clamp(e.y, -1.0, 1.0) * 16383.0)) + 16384;
    return ivec2(int(round(clamp(e.x, -1.0, 1.0) * 32767.0)), t.w < 0.0 ? -c : c);
}

// Two i16 in one word (x low), as the vertex input reads R16G16_SINT.
ivec2 unpack_i16x2(uint w) {
    return ivec2(int(w << 16) >> 16, int(w) >> 16);
}

uint pack_i16x2(ivec2 c) {
    return (uint(c.x) & 0xffffu) | (uint(c.y) << 16);
}
