#version 430
// Overlay handles (voxwarp.render.overlay). Points: a disc of the vertex colour inside a ring
// u_outline_width pixels wide of u_outline (its alpha scaled by the point's), so a
// handle reads on bright and dark volumes alike; outside the disc the sprite discards.
// Lines: the vertex colour. Output is premultiplied RGBA ("over" blending).

in vec4 v_color;

uniform int u_points;           // 1: points (round discs), 0: lines
uniform float u_sprite_size;    // point sprite diameter in pixels (as gl_PointSize)
uniform float u_outline_width;  // ring width in pixels
uniform vec4 u_outline;         // ring colour, straight RGBA

out vec4 f_color;

void main() {
    vec4 c = v_color;
    if (u_points == 1) {
        float radius = 0.5 * u_sprite_size;
        float r = length(gl_PointCoord - vec2(0.5)) * u_sprite_size;  // pixels from centre
        if (r > radius) discard;
        if (r > radius - u_outline_width) c = vec4(u_outline.rgb, u_outline.a * v_color.a);
    }
    f_color = vec4(c.rgb * c.a, c.a);
}
