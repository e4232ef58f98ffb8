#version 450
// Skinning and morph targets, once per frame; the output has the pack's 80-byte vertex layout,
// so every later pass binds it as its vertex buffer. Same maths as anim::skin_cpu (the tests
// compare the two): morph deltas first, then linear blend skinning; normals by the inverse
// transpose of the blended matrix, tangents by the matrix itself (w kept).

layout(local_size_x = 64) in;

// Vertices as five uvec4 of raw words each (80 bytes): a struct with vec3 members would get
// std430's 16-byte alignment and no longer match the packed layout, and whole-uvec4 loads and
// stores are several times faster than single words on lavapipe, which runs 8 vertices per
// SIMD lane group and turns each scalar access into a gather or scatter.
layout(std430, set = 0, binding = 0) readonly buffer BindVertices { uvec4 bind[]; };
layout(std430, set = 0, binding = 1) readonly buffer Joints { uvec2 joints[]; };  // 4 x u16 per vertex
layout(std430, set = 0, binding = 2) readonly buffer Weights { vec4 weights[]; };
layout(std430, set = 0, binding = 3) readonly buffer MorphPositions { float morph_positions[]; };  // [target][vertex][3]
layout(std430, set = 0, binding = 4) readonly buffer MorphNormals { float morph_normals[]; };
layout(std430, set = 0, binding = 5) readonly buffer MorphWeights { float morph_weights[]; };
layout(std430, set = 0, binding = 6) readonly buffer JointMatrices { mat4 joint_matrices[]; };
layout(std430, set = 0, binding = 7) writeonly buffer Skinned { uvec4 skinned[]; };

layout(push_constant) uniform Params {
    uint vertex_count;
    uint target_count;
    uint skinned;        // 0: every vertex follows joint matrix 0
    uint morph_normals;  // 1: morph_normals holds normal deltas
    uint joint_count;    // joint indices are clamped below it, so bad data cannot read past the buffer
} params;

uint joint(uvec2 words, uint k) {
    uint word = words[k / 2];
    return min((k % 2 == 0) ? (word & 0xffffu) : (word >> 16), params.joint_count - 1);
}

void main() {
    uint v = gl_GlobalInvocationID.x;
    if (v >= params.vertex_count) {
        return;
    }
    // The five words of a pack::Vertex: [position, normal.x] [normal.yz, tangent.xy]
    // [tangent.zw, uv0] [uv1, texcoord1] [colour, padding].
    uint base = v * 5u;
    vec4 w0 = uintBitsToFloat(bind[base]);
    vec4 w1 = uintBitsToFloat(bind[base + 1]);
    vec4 w2 = uintBitsToFloat(bind[base + 2]);
    vec3 p = w0.xyz;
    vec3 n = vec3(w0.w, w1.xy);
    vec4 t = vec4(w1.zw, w2.xy);
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
        uvec2 js = joints[v];
        m = mat4(0.0);
        for (uint k = 0; k < 4; k++) {
            if (w[k] != 0.0) {
                m += joint_matrices[joint(js, k)] * w[k];
            }
        }
    } else {
        m = joint_matrices[0];
    }
    mat3 m3 = mat3(m);
    // The inverse transpose up to a positive factor, which the normalize removes: the cofactor
    // matrix is det(m3) times it, so multiply by det's sign to keep mirrored joints' normals
    // pointing out. Cheaper than inverse() and defined for singular matrices.
    mat3 cofactor = mat3(cross(m3[1], m3[2]), cross(m3[2], m3[0]), cross(m3[0], m3[1]));
    float det = dot(m3[0], cofactor[0]);
    vec3 sn = (det < 0.0 ? -1.0 : 1.0) * (cofactor * n);
    vec3 st = m3 * t.xyz;
    vec3 sp = (m * vec4(p, 1.0)).xyz;
    sn = dot(sn, sn) > 0.0 ? normalize(sn) : vec3(0.0);
    st = dot(st, st) > 0.0 ? normalize(st) : vec3(0.0);
    skinned[base] = floatBitsToUint(vec4(sp, sn.x));
    skinned[base + 1] = floatBitsToUint(vec4(sn.yz, st.xy));
    skinned[base + 2] = floatBitsToUint(vec4(st.z, t.w, w2.zw));
    // uv1, texcoord1, colour and padding pass through unchanged.
    skinned[base + 3] = bind[base + 3];
    skinned[base + 4] = bind[base + 4];
}
