#version 430 core
// Bilinear upscaling of a low-resolution frame (premultiplied RGBA, copied as is).
uniform sampler2D u_frame;
in vec2 v_uv;
out vec4 f_color;

void main() {
    f_color = texture(u_frame, v_uv);
}
