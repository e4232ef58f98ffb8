#version 450
#include "frame.glsl"

// Instanced boid meshes (engine/src/render/boids_draw.rs): the flock's mesh from the scene's vertex
// buffer, one model matrix per instance, from the boid's position and `boid_rotation` (heading
// plus banking roll).

layout(location = 0) in vec3 in_position;
layout(location = 1) in vec3 in_normal;
layout(location = 2) in vec4 in_model0;
layout(location = 3) in vec4 in_model1;
layout(location = 4) in vec4 in_model2;
layout(location = 5) in vec4 in_model3;

layout(location = 0) out vec3 out_normal;

void main() {
    mat4 model = mat4(in_model0, in_model1, in_model2, in_model3);
    // Rotation and translation only: the model matrix transforms normals correctly.
    out_normal = mat3(model) * in_normal;
    gl_Position = frame.view_proj * model * vec4(in_position, 1.0);
}
