#version 430 core
// One constraint pass of the GPU ChainMail (deform/elements/chainmail_gpu.py): one fragment per
// element of the z-slice atlas (massspring_atlas.glsl with one element per cell), drawn
// only over the pass's box (chainmail_box.vert.glsl). Reads the previous state with
// imageLoad and writes the new position into the other framebuffer of a ping-pong pair.
//
// Each link gives the element an interval per coordinate, relative to the linked
// neighbour's position; lo/hi are the intersection of the 6 links' intervals. Per
// coordinate c the pass either only lowers (u_lower[c]: x > hi -> hi) or only raises
// (u_raise[c]: x < lo -> lo) -- the two monotone phases of the module doc. Held and
// fixed elements (w != 0) never move. Changed elements record the bounding box of the
// changes and one bit per changed coordinate in a tiny SSBO (read back per pass);
// elements left violating a link in a coordinate's last phase record their box too.
//
// With CM_PIN_PASS defined the same file is the pin pass instead: held elements go to
// their targets (w 2), released ones become free (w 0), fixed ones (w 1) stay.
#include "chainmail_config.glsl"
#include "massspring_atlas.glsl"

// position - origin (x, y, z mm); w: 0 free, 1 fixed, 2 held
layout(rgba32f, binding = 0) readonly uniform image2D u_pos;
#ifdef CM_PIN_PASS
// target - origin (x, y, z mm); w: 1 when held
layout(rgba32f, binding = 1) readonly uniform image2D u_target;
#else
// per element, the limits (min, max, shear; mm) of its links: forward (to e + e_i) and
// backward (from e - e_i), packed (fx fy fz: forward x y z, bx by bz: backward):
// 0 (fx.min, fx.max, fx.sh, bx.min)  1 (bx.max, bx.sh, fy.min, fy.max)
// 2 (fy.sh, by.min, by.max, by.sh)   3 (fz.min, fz.max, fz.sh, bz.min)  4 (bz.max, bz.sh)
// An absent link (cut, or past a face) has min -CM_BIG, max +CM_BIG, shear +CM_BIG.
layout(rgba32f, binding = 1) readonly uniform image2D u_link[5];
layout(std430, binding = 0) buffer CmChanges {
    int cm_lo[3];     // bounding box of the elements changed by this pass (inclusive)
    int cm_hi[3];
    uint cm_flags;    // bit c: coordinate c changed somewhere
    uint cm_pad;
    int cm_vlo[3];    // bounding box of the elements reported as violating
    int cm_vhi[3];
};
uniform ivec3 u_lower;  // per coordinate: 1 in the lowering phase
uniform ivec3 u_raise;  // per coordinate: 1 in the raising phase
uniform ivec3 u_report_below;  // per coordinate: report x < lo (left by a last lowering)
uniform ivec3 u_report_above;  // per coordinate: report x > hi (left by a last raising)
uniform float u_tol;    // move only when off by more than this (mm): float round-off
uniform int u_report_pinned;  // 1: report held and fixed elements too (the check pass)
#endif

#ifndef CM_PIN_PASS
#include "chainmail_links.glsl"
#endif

layout(location = 0) out vec4 cm_out;

void main() {
    ivec2 t = ivec2(gl_FragCoord.xy);
    vec4 p = imageLoad(u_pos, t);
#ifdef CM_PIN_PASS
    vec4 tg = imageLoad(u_target, t);
    cm_out = p.w == 1.0 ? p : (tg.w > 0.0 ? vec4(tg.xyz, 2.0) : vec4(p.xyz, 0.0));
#else
    ivec3 e = ms_block(t);
    vec3 x = p.xyz;
    ivec2 n[6];
    vec4 l[5];
    vec3 xn[6];
    vec3 lo, hi;
    cm_neighbours(t, e, n);
    cm_load(t, n, l, xn);
    cm_interval(l, xn, lo, hi);
    ivec3 free_ = ivec3(p.w == 0.0);
    ivec3 above = ivec3(greaterThan(x, hi + u_tol)) * free_;
    ivec3 below = ivec3(lessThan(x, lo - u_tol)) * free_;
    ivec3 down = above * u_lower;
    ivec3 up = below * u_raise;
    vec3 y = mix(mix(x, hi, bvec3(down)), lo, bvec3(up));
    cm_out = vec4(y, p.w);
    ivec3 moved = down + up;
    if (moved != ivec3(0)) {
        atomicOr(cm_flags, uint(moved.x | (moved.y << 1) | (moved.z << 2)));
        atomicMin(cm_lo[0], e.x);
        atomicMin(cm_lo[1], e.y);
        atomicMin(cm_lo[2], e.z);
        atomicMax(cm_hi[0], e.x);
        atomicMax(cm_hi[1], e.y);
        atomicMax(cm_hi[2], e.z);
    }
    ivec3 any_ = ivec3(u_report_pinned != 0);
    ivec3 report_below = below + (1 - free_) * any_ * ivec3(lessThan(x, lo - u_tol));
    ivec3 report_above = above + (1 - free_) * any_ * ivec3(greaterThan(x, hi + u_tol));
    if (report_below * u_report_below + report_above * u_report_above != ivec3(0)) {
        atomicMin(cm_vlo[0], e.x);
        atomicMin(cm_vlo[1], e.y);
        atomicMin(cm_vlo[2], e.z);
        atomicMax(cm_vhi[0], e.x);
        atomicMax(cm_vhi[1], e.y);
        atomicMax(cm_vhi[2], e.z);
    }
#endif
}
