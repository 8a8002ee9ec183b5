// Direct volume rendering: emission-absorption, composited front to back with
// premultiplied, sample-distance-corrected colours from the transfer function table.
struct State { vec4 acc; };
void mode_init(inout State s) { s.acc = vec4(0.0); }
// the transfer function's visibility is in the static skip map
bool block_visible(vec2 range, inout State s) { return true; }
bool mode_skip(inout State s, float t_clear) { return false; }
bool mode_sample(inout State s, float v, vec3 u, float t) {
    vec4 c = transfer(v);
    if (c.a <= 0.0) return false;
    c.rgb = detj_tint(c.rgb, c.a, t);
#ifdef SHADING
    c.rgb = shade(c.rgb, c.a, gradient_deformed(u, t), g_rd);
#endif
    s.acc += (1.0 - s.acc.a) * c;
    return s.acc.a > 0.99;
}
vec4 mode_finish(State s) { return s.acc; }
