#version 430 core
// Mass-spring step: the used tiles of the element atlas as triangles in NDC (one
// fragment per element; see deform/massspring_gpu.py).
in vec2 in_ndc;
void main() {
    gl_Position = vec4(in_ndc, 0.0, 1.0);
}
