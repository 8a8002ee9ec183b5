// X-ray (a radiograph, like a digitally reconstructed radiograph): the line integral of
// the windowed value through the object, scaled by a FIXED length, shown through the
// window (bright = more material along the ray).
//
//   attenuation  a(v) = max(v - w_lo, 0)         the window's low end is zero attenuation
//                                                  (air in a CT window: dark, adds nothing)
//   line integral I   = sum over samples a(v) * u_step      (value x mm, deformed space)
//   grey              = clamp(I / L / (w_hi - w_lo), 0, 1)
//
// L = u_xray_length, the longest edge of the volume box in mm (the same for every ray,
// camera, warp and clip box; set by app/render/raycaster.py). So a ray crossing L mm of
// material of value v shows as window_gray(v), a slab twice as thick is twice as bright
// (until white), and rays that cross the box near its faces show only the material
// they cross (no caps). The sum over the sample lattice (one sample in the middle of
// each step) covers the path within u_step / 2 at either end.
// Values above the window's top still add (dense bone attenuates more); only the
// result is clamped. Compare mode_average.glsl, the thesis's mean along the ray (Knoche
// 2008, section 2.3.2): it divides by the samples inside the box, so it does not grow
// with thickness and short paths near the box faces give bright caps.
uniform float u_xray_length;   // reference length L in mm
struct State { float sum; };
void mode_init(inout State s) { s.sum = 0.0; }
// a block adds nothing unless some value in it lies above the window's low end (used
// by warped rays; straight rays march without skip checks, app/render/skipping/cache.py)
bool block_visible(vec2 range, inout State s) { return range.y > u_window.x; }
bool mode_skip(inout State s, float t_clear) { return false; }
bool mode_sample(inout State s, float v, vec3 u, float t) {
    s.sum += max(v - u_window.x, 0.0);
    // no early exit at white: the test per sample costs ~15 % on a CPU rasteriser,
    // and only a window too narrow for the data saturates
    return false;
}
vec4 mode_finish(State s) {
    float gray = s.sum * u_step / (u_xray_length * (u_window.y - u_window.x));
    return g_inside ? vec4(vec3(clamp(gray, 0.0, 1.0)), 1.0) : vec4(0.0);
}
