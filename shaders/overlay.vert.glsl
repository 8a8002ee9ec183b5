#version 430
// Editing handles drawn over a rendered frame (voxwarp.render.overlay): points (round discs with
// an outline ring) and 1-px line segments, placed by the raycaster's camera.
// * No near/far clipping: z is set to 0, so a handle outside the camera's scene sphere
//   stays visible; perspective geometry behind the eye (w < 0) is still clipped.
// * Colours arrive straight (unnormalised RGBA8 -> [0, 1]); the fragment stage writes
//   them premultiplied, like the raycaster.

in vec3 in_position;    // world mm
in vec4 in_color;       // straight RGBA

uniform mat4 u_view_proj;       // world -> clip
uniform float u_sprite_size;    // point sprite diameter in pixels (disc + outline ring)

out vec4 v_color;

void main() {
    vec4 clip = u_view_proj * vec4(in_position, 1.0);
    clip.z = 0.0;
    gl_Position = clip;
    gl_PointSize = u_sprite_size;
    v_color = in_color;
}
