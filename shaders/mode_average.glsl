// Average intensity along the ray (X-ray like), shown through the window.
struct State { float sum; float count; };
void mode_init(inout State s) { s.sum = 0.0; s.count = 0.0; }
bool block_visible(vec2 range, inout State s) { return true; }
bool mode_skip(inout State s, float t_clear) { return false; }
bool mode_sample(inout State s, float v, vec3 u, float t) {
    s.sum += v;
    s.count += 1.0;
    return false;
}
vec4 mode_finish(State s) {
    return s.count > 0.0 ? vec4(vec3(window_gray(s.sum / s.count)), 1.0) : vec4(0.0);
}
