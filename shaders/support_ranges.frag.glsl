#version 430
// Writes the ray parameter t at which the pixel's ray (built exactly as
// shaders/raycast.frag.glsl builds it) crosses this support face, into r and a: the
// target blends r by MIN and a by MAX, so each pixel ends with the first and the last
// face its ray crosses, the range in which its samples may need the chain.
uniform mat4 u_inv_view_proj;   // clip -> deformed world (mm)
uniform vec4 u_viewport;        // x, y, width, height in pixels (of the raycast draw)
in vec3 v_world;
out vec4 f_range;

void main() {
    vec2 ndc = (gl_FragCoord.xy - u_viewport.xy) / u_viewport.zw * 2.0 - 1.0;
    vec4 a = u_inv_view_proj * vec4(ndc, -1.0, 1.0);
    vec4 b = u_inv_view_proj * vec4(ndc, 1.0, 1.0);
    vec3 ro = a.xyz / a.w;
    vec3 d = b.xyz / b.w - ro;
    vec3 rd = d / length(d);
    float t = dot(v_world - ro, rd);
    f_range = vec4(t, 0.0, 0.0, t);
}
