#version 430 core
// Mass-spring step and pin pass: the used tiles of the block atlas as triangles in NDC
// (one fragment per block of elements; see deform/elements/massspring_gpu.py).
in vec2 in_ndc;
void main() {
    gl_Position = vec4(in_ndc, 0.0, 1.0);
}
