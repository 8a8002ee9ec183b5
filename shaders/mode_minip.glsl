// Minimum intensity projection, shown through the window (grey values).
struct State { float m; };
void mode_init(inout State s) { s.m = 3.0e38; }
bool block_visible(vec2 range, inout State s) {
    return range.x < min(s.m, u_window.y);
}
bool mode_skip(inout State s, float t_clear) { return false; }
bool mode_sample(inout State s, float v, vec3 u, float t) {
    s.m = min(s.m, v);
    return s.m <= max(u_window.x, u_value_limits.x);   // cannot get darker
}
vec4 mode_finish(State s) { return g_inside ? vec4(vec3(window_gray(s.m)), 1.0) : vec4(0.0); }
