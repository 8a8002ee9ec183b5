// Maximum intensity projection, shown through the window (grey values).
struct State { float m; float t; };
void mode_init(inout State s) { s.m = -3.0e38; s.t = 0.0; }
// a block can only matter if its maximum beats both the current maximum and the window low
bool block_visible(vec2 range, inout State s) {
    return range.y > max(s.m, u_window.x);
}
bool mode_skip(inout State s, float t_clear) { return false; }
bool mode_sample(inout State s, float v, vec3 u, float t) {
    if (v > s.m) {
        s.m = v;
        s.t = t;   // where the extreme lies: the det J overlay's sample
    }
    return s.m >= min(u_window.y, u_value_limits.y);   // cannot get brighter
}
vec4 mode_finish(State s) {
    if (!g_inside) return vec4(0.0);
    vec3 g = vec3(window_gray(s.m));
    return vec4(s.m < 3.0e38 && s.m > -3.0e38 ? detj_tint(g, 1.0, s.t) : g, 1.0);
}
