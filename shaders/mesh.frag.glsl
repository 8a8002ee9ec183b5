#version 430
// Blinn-Phong with a headlight (the light sits at the eye, so the half vector is the
// view direction), lit from both sides (open meshes such as tiles show their back).
// Output is premultiplied RGBA, like the raycaster's.

in vec3 v_world;
in vec3 v_normal;

uniform vec4 u_color;   // straight RGBA
uniform vec4 u_eye;     // perspective: eye position, w = 1; orthographic: towards the eye, w = 0
uniform vec4 u_light;   // ambient, diffuse, specular, shininess

out vec4 f_color;

void main() {
    vec3 v = u_eye.w > 0.5 ? normalize(u_eye.xyz - v_world) : normalize(u_eye.xyz);
    float len = length(v_normal);
    vec3 n = len > 1e-30 ? v_normal / len : v;   // (NaN fails the test too)
    float ndv = abs(dot(n, v));                   // two-sided
    float spec = pow(ndv, u_light.w);
    vec3 rgb = min(u_color.rgb * (u_light.x + u_light.y * ndv) + u_light.z * spec, vec3(1.0));
    f_color = vec4(rgb * u_color.a, u_color.a);
}
