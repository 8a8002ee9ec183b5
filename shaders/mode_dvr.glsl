// Direct volume rendering: emission-absorption, composited front to back.
struct State { vec4 acc; };
void mode_init(inout State s) { s.acc = vec4(0.0); }
bool block_visible(ivec3 b, inout State s) { return block_tf_visible(b); }
bool mode_skip(inout State s) { return false; }
bool mode_sample(inout State s, float v, vec3 u, float t) {
    vec4 c = transfer(v);
    if (c.a <= 0.0) return false;
    float a = correct_alpha(c.a);
#ifdef SHADING
    c.rgb = shade(c.rgb, gradient_deformed(u, t), g_rd);
#endif
    s.acc.rgb += (1.0 - s.acc.a) * a * c.rgb;
    s.acc.a += (1.0 - s.acc.a) * a;
    return s.acc.a > 0.99;
}
vec4 mode_finish(State s) { return s.acc; }
