#version 430 core
// One half-sweep of the GPU ChainMail relaxation (deform/elements/chainmail_gpu.py): the
// rule of relax_sweep in deform/elements/chainmail_cpu.py. One fragment per element of
// the z-slice atlas, drawn only over the half-sweep's box (chainmail_box.vert.glsl);
// reads the previous state with imageLoad, writes the other framebuffer of the
// ping-pong pair.
//
// A free element (w 0) of colour u_colour ((i + j + k) % 2) moves, per coordinate, to
// rest + mean(x_n - rest_n) of its linked neighbours, clamped into the interval its
// links allow with the neighbours where they are (left alone in a coordinate whose
// interval is empty). Elements of the other colour, held and fixed ones are copied;
// u_colour -1 copies every element (to make both buffers agree again).
#include "chainmail_config.glsl"
#include "massspring_atlas.glsl"

// position - origin (x, y, z mm); w: 0 free, 1 fixed, 2 held
layout(rgba32f, binding = 0) readonly uniform image2D u_pos;
// the packed link limits of chainmail_pass.frag.glsl (absent link: min -CM_BIG)
layout(rgba32f, binding = 1) readonly uniform image2D u_link[5];
// rest - origin (x, y, z mm)
layout(rgba32f, binding = 6) readonly uniform image2D u_rest;
uniform int u_colour;

#include "chainmail_links.glsl"

layout(location = 0) out vec4 cm_out;

// 1 when the link with this min distance is present (absent links store -1e30)
float present(float min_dist) {
    return float(min_dist > -1e29);
}

void main() {
    ivec2 t = ivec2(gl_FragCoord.xy);
    vec4 p = imageLoad(u_pos, t);
    ivec3 e = ms_block(t);
    cm_out = p;
    if (p.w != 0.0 || ((e.x + e.y + e.z) & 1) != u_colour) {
        return;
    }
    vec3 x = p.xyz;
    ivec2 n[6];
    vec4 l[5];
    vec3 xn[6];
    vec3 lo, hi;
    cm_neighbours(t, e, n);
    cm_load(t, n, l, xn);
    cm_interval(l, xn, lo, hi);
    // the mean displacement of the linked neighbours (their links' mins: fx, bx, fy,
    // by, fz, bz)
    float w[6] = float[6](present(l[0].x), present(l[0].w), present(l[1].z),
                          present(l[2].y), present(l[3].x), present(l[3].w));
    float cnt = w[0] + w[1] + w[2] + w[3] + w[4] + w[5];
    if (cnt == 0.0) {
        return;
    }
    vec3 u[6];  // the neighbours' displacements
    for (int k = 0; k < 6; ++k) u[k] = xn[k] - imageLoad(u_rest, n[k]).xyz;
    vec3 su = w[0] * u[0] + w[1] * u[1];  // summed per axis, as before the shared include
    su += w[2] * u[2] + w[3] * u[3];
    su += w[4] * u[4] + w[5] * u[5];
    vec3 target = imageLoad(u_rest, t).xyz + su / cnt;
    vec3 y = min(max(target, lo), hi);
    // an empty interval (conflicting neighbours): stay
    cm_out = vec4(mix(y, x, greaterThan(lo, hi)), p.w);
}
