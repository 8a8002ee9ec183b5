// Isosurface at u_iso: first crossing from below, refined by bisection between the
// two samples around it, Blinn-Phong shaded from the (warped) gradient.
uniform float u_iso;
uniform vec3 u_iso_color;
struct State { float prev; float prev_t; bool hit; vec4 color; };
void mode_init(inout State s) { s.prev = -3.0e38; s.prev_t = 0.0; s.hit = false; s.color = vec4(0.0); }
bool block_visible(vec2 range, inout State s) { return range.y >= u_iso; }
// everything up to t_clear lies below the isovalue: bisection may start there
// (t_clear < 0: the ray was outside the volume, no known value to start from)
bool mode_skip(inout State s, float t_clear) {
    s.prev = t_clear < 0.0 ? -3.0e38 : u_iso - 1.0;
    s.prev_t = t_clear;
    return false;
}
bool mode_sample(inout State s, float v, vec3 u, float t) {
    if (v < u_iso) {
        s.prev = v;
        s.prev_t = t;
        return false;
    }
    float th = t;
    if (s.prev > -1.0e38) {
        float ta = s.prev_t;
        float tb = t;
        for (int i = 0; i < 6; ++i) {
            float tm = 0.5 * (ta + tb);
            if (scene_value(texel_at(tm), tm) >= u_iso) tb = tm; else ta = tm;
        }
        th = tb;
    }
    vec3 rgb = detj_tint(u_iso_color, 1.0, th);
#ifdef SHADING
    rgb = shade(rgb, 1.0, gradient_deformed(texel_at(th), th), g_rd);
#endif
    s.color = vec4(rgb, 1.0);
    s.hit = true;
    return true;
}
vec4 mode_finish(State s) { return s.color; }
