#version 450
// One triangle that covers the whole viewport (vertices at NDC (-1,-1), (3,-1), (-1,3)); no
// vertex buffer. Used by full-screen passes such as the tone map.

void main() {
    vec2 p = vec2((gl_VertexIndex << 1) & 2, gl_VertexIndex & 2);
    gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);
}
