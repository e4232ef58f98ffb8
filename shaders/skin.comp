#version 450
// Skinning and morph targets, once per frame; the output has the pack's 36-byte quantised vertex
// layout (engine/pack/src/vertex.rs), so every later pass binds it as its vertex buffer and
// pushes the LOD's texture-coordinate ranges, which the copied codes still refer to. Same maths as anim::skin_cpu (the tests
// compare the two): morph deltas first, then linear blend skinning; normals by the inverse
// transpose of the blended matrix, tangents by the matrix itself (w kept).

layout(local_size_x = 64) in;

#include "octahedral.glsl"

// Vertices as nine raw words each (36 bytes): a struct with vec3 members would get std430's
// 16-byte alignment and no longer match the packed layout.
const uint WORDS = 9u;
layout(std430, set = 0, binding = 0) readonly buffer BindVertices { uint bind[]; };
layout(std430, set = 0, binding = 1) readonly buffer Joints { uvec2 joints[]; };  // 4 x u16 per vertex
layout(std430, set = 0, binding = 2) readonly buffer Weights { vec4 weights[]; };
layout(std430, set = 0, binding = 3) readonly buffer MorphPositions { float morph_positions[]; };  // per job [target][vertex][3]
layout(std430, set = 0, binding = 4) readonly buffer MorphNormals { float morph_normals[]; };
layout(std430, set = 0, binding = 5) readonly buffer MorphWeights { float morph_weights[]; };
layout(std430, set = 0, binding = 6) readonly buffer JointMatrices { mat4 joint_matrices[]; };
layout(std430, set = 0, binding = 7) writeonly buffer Skinned { uint skinned[]; };

// One dispatch skins every (instance, LOD) the frame draws (anim::skin_gpu::SkinBatch): lavapipe
// wakes its compute threads and waits for them at every dispatch, which cost more than the
// skinning itself at one dispatch per character. Each workgroup belongs to one job; a job's
// inputs, parameters and output are ranges of the shared buffers.
struct Job {
    uint vertex_count;
    uint bind_base;          // first vertex in bind, joints, weights
    uint morph_base;         // first float of the job's deltas in morph_positions
    uint target_count;
    uint morph_normal_base;  // in morph_normals, or ~0u: no normal deltas
    uint weight_base;        // first of the owner's morph weights
    uint joint_base;         // first of the owner's joint matrices
    uint joint_count;        // joint indices are clamped below it, so bad data cannot read another's
    uint skinned;            // 0: every vertex follows joint matrix joint_base
    uint out_base;           // first vertex of the job's output
    uint first_group;        // the job's first workgroup (with group_offset)
    uint pad;
};
layout(std430, set = 0, binding = 8) readonly buffer Jobs { Job jobs[]; };
layout(std430, set = 0, binding = 9) readonly buffer GroupJobs { uint group_job[]; };

layout(push_constant) uniform Params {
    // Added to gl_WorkGroupID.x: a batch of more groups than a dispatch may have is several.
    uint group_offset;
} params;

uint joint(Job job, uvec2 words, uint k) {
    uint word = words[k / 2];
    return job.joint_base + min((k % 2 == 0) ? (word & 0xffffu) : (word >> 16), job.joint_count - 1);
}

void main() {
    uint group = gl_WorkGroupID.x + params.group_offset;
    Job job = jobs[group_job[group]];
    uint v = (group - job.first_group) * gl_WorkGroupSize.x + gl_LocalInvocationID.x;
    if (v >= job.vertex_count) {
        return;
    }
    // The words of a stored vertex: position (3), normal, tangent, uv0, uv1, texcoord1, colour.
    uint iv = job.bind_base + v;
    uint base = iv * WORDS;
    vec3 p = uintBitsToFloat(uvec3(bind[base], bind[base + 1], bind[base + 2]));
    vec3 n = oct_decode(unpackSnorm2x16(bind[base + 3]));
    vec4 t = tangent_decode(unpack_i16x2(bind[base + 4]));
    for (uint k = 0; k < job.target_count; k++) {
        float w = morph_weights[job.weight_base + k];
        if (w != 0.0) {
            uint at = (k * job.vertex_count + v) * 3;
            p += w * vec3(morph_positions[job.morph_base + at], morph_positions[job.morph_base + at + 1], morph_positions[job.morph_base + at + 2]);
            if (job.morph_normal_base != ~0u) {
                uint an = job.morph_normal_base + at;
                n += w * vec3(morph_normals[an], morph_normals[an + 1], morph_normals[an + 2]);
            }
        }
    }
    mat4 m;
    if (job.skinned != 0) {
        vec4 w = weights[iv];
        uvec2 js = joints[iv];
        m = mat4(0.0);
        for (uint k = 0; k < 4; k++) {
            if (w[k] != 0.0) {
                m += joint_matrices[joint(job, js, k)] * w[k];
            }
        }
    } else {
        m = joint_matrices[job.joint_base];
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
    uint out_at = (job.out_base + v) * WORDS;
    uvec3 ps = floatBitsToUint(sp);
    skinned[out_at] = ps.x;
    skinned[out_at + 1] = ps.y;
    skinned[out_at + 2] = ps.z;
    skinned[out_at + 3] = packSnorm2x16(oct_encode(sn));
    skinned[out_at + 4] = pack_i16x2(tangent_encode(vec4(st, t.w)));
    // The texture coordinates and the colour pass through unchanged.
    for (uint k = 5u; k < WORDS; k++) {
        skinned[out_at + k] = bind[base + k];
    }
}
