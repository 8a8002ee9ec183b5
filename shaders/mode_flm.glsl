// First local maximum (Knoche 2008): the first maximum along the ray above the
// threshold u_threshold, coloured by the transfer function (opaque). Shading uses the
// gradient where the ray crossed the threshold on its way up to that maximum (at the
// maximum itself the gradient is perpendicular to the ray and would leave it unlit).
uniform float u_threshold;
struct State {
    float prev; vec3 prev_u; float prev_t;   // previous sample
    vec3 cross_u; float cross_t;             // where the current rise crossed the threshold
    bool hit; vec4 color;
};
void mode_init(inout State s) { s.prev = -3.0e38; s.hit = false; s.color = vec4(0.0); }
bool flm_emit(inout State s) {
    vec3 rgb = transfer_straight(s.prev).rgb;
#ifdef SHADING
    rgb = shade(rgb, 1.0, gradient_deformed_anew(s.cross_u, s.cross_t), g_rd);
#endif
    s.color = vec4(rgb, 1.0);
    s.hit = true;
    return true;
}
bool block_visible(vec2 range, inout State s) { return range.y >= u_threshold; }
// a skipped region lies below the threshold: a maximum pending above it is final
bool mode_skip(inout State s, float t_clear) {
    if (s.prev >= u_threshold) return flm_emit(s);
    s.prev = -3.0e38;
    return false;
}
bool mode_sample(inout State s, float v, vec3 u, float t) {
    if (s.prev >= u_threshold && v < s.prev) return flm_emit(s);
    if (v >= u_threshold && s.prev < u_threshold) {
        s.cross_u = u;
        s.cross_t = t;
    }
    s.prev = v;
    s.prev_u = u;
    s.prev_t = t;
    return false;
}
vec4 mode_finish(State s) {
    if (!s.hit && s.prev >= u_threshold) {
        flm_emit(s);   // ray left the volume while still rising
    }
    return s.color;
}
