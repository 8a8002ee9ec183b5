// Maximum intensity projection, shown through the window (grey values).
struct State { float m; };
void mode_init(inout State s) { s.m = -3.0e38; }
// a block can only matter if its maximum beats both the current maximum and the window low
bool block_visible(vec2 range, inout State s) {
    return range.y > max(s.m, u_window.x);
}
bool mode_skip(inout State s, float t_clear) { return false; }
bool mode_sample(inout State s, float v, vec3 u, float t) {
    s.m = max(s.m, v);
    return s.m >= min(u_window.y, u_value_limits.y);   // cannot get brighter
}
vec4 mode_finish(State s) { return g_inside ? vec4(vec3(window_gray(s.m)), 1.0) : vec4(0.0); }
