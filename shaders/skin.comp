#version 450
// Skinning and morph targets, once per frame; the output has the pack's 64-byte vertex layout,
// so every later pass binds it as its vertex buffer. Same maths as anim::skin_cpu (the tests
// compare the two): morph deltas first, then linear blend skinning; normals by the inverse
// transpose of the blended matrix, tangents by the matrix itself (w kept).

layout(local_size_x = 64) in;

// Vertices as raw words (16 per vertex): a struct with vec3 members would get std430's
// 16-byte alignment and no longer match the packed layout.
layout(std430, set = 0, binding = 0) readonly buffer BindVertices { uint bind_words[]; };
layout(std430, set = 0, binding = 1) readonly buffer Joints { uint joints[]; };  // 4 x u16 per vertex
layout(std430, set = 0, binding = 2) readonly buffer Weights { vec4 weights[]; };
layout(std430, set = 0, binding = 3) readonly buffer MorphPositions { float morph_positions[]; };  // [target][vertex][3]
layout(std430, set = 0, binding = 4) readonly buffer MorphNormals { float morph_normals[]; };
layout(std430, set = 0, binding = 5) readonly buffer MorphWeights { float morph_weights[]; };
layout(std430, set = 0, binding = 6) readonly buffer JointMatrices { mat4 joint_matrices[]; };
layout(std430, set = 0, binding = 7) writeonly buffer Skinned { uint out_words[]; };

layout(push_constant) uniform Params {
    uint vertex_count;
    uint target_count;
    uint skinned;        // 0: every vertex follows joint matrix 0
    uint morph_normals;  // 1: morph_normals holds normal deltas
    uint joint_count;    // joint indices are clamped below it, so bad data cannot read past the buffer
} params;

vec3 word3(uint at) {
    return vec3(uintBitsToFloat(bind_words[at]), uintBitsToFloat(bind_words[at + 1]), uintBitsToFloat(bind_words[at + 2]));
}

void put3(uint at, vec3 v) {
    out_words[at] = floatBitsToUint(v.x);
    out_words[at + 1] = floatBitsToUint(v.y);
    out_words[at + 2] = floatBitsToUint(v.z);
}

uint joint(uint v, uint k) {
    uint word = joints[v * 2 + k / 2];
    return min((k % 2 == 0) ? (word & 0xffffu) : (word >> 16), params.joint_count - 1);
}

void main() {
    uint v = gl_GlobalInvocationID.x;
    if (v >= params.vertex_count) {
        return;
    }
    uint base = v * 16;
    vec3 p = word3(base);
    vec3 n = word3(base + 3);
    vec4 t = vec4(word3(base + 6), uintBitsToFloat(bind_words[base + 9]));
    for (uint k = 0; k < params.target_count; k++) {
        float w = morph_weights[k];
        if (w != 0.0) {
            uint at = (k * params.vertex_count + v) * 3;
            p += w * vec3(morph_positions[at], morph_positions[at + 1], morph_positions[at + 2]);
            if (params.morph_normals != 0) {
                n += w * vec3(morph_normals[at], morph_normals[at + 1], morph_normals[at + 2]);
            }
        }
    }
    mat4 m;
    if (params.skinned != 0) {
        vec4 w = weights[v];
        m = mat4(0.0);
        for (uint k = 0; k < 4; k++) {
            if (w[k] != 0.0) {
                m += joint_matrices[joint(v, k)] * w[k];
            }
        }
    } else {
        m = joint_matrices[0];
    }
    mat3 m3 = mat3(m);
    mat3 normal_matrix = transpose(inverse(m3));
    vec3 sn = normal_matrix * n;
    vec3 st = m3 * t.xyz;
    put3(base, (m * vec4(p, 1.0)).xyz);
    put3(base + 3, dot(sn, sn) > 0.0 ? normalize(sn) : vec3(0.0));
    put3(base + 6, dot(st, st) > 0.0 ? normalize(st) : vec3(0.0));
    out_words[base + 9] = floatBitsToUint(t.w);
    // uv0, uv1, colour and padding pass through unchanged.
    for (uint i = 10; i < 16; i++) {
        out_words[base + i] = bind_words[base + i];
    }
}
