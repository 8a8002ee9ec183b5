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
    ivec2 tpx = t + ivec2(int(e.x < NX - 1), 0);
    ivec2 tmx = t - ivec2(int(e.x > 0), 0);
    ivec2 tpy = t + ivec2(0, int(e.y < NY - 1));
    ivec2 tmy = t - ivec2(0, int(e.y > 0));
    ivec2 tpz = ms_texel(ivec3(e.xy, min(e.z + 1, NZ - 1)));
    ivec2 tmz = ms_texel(ivec3(e.xy, max(e.z - 1, 0)));
    vec3 xpx = imageLoad(u_pos, tpx).xyz;
    vec3 xmx = imageLoad(u_pos, tmx).xyz;
    vec3 xpy = imageLoad(u_pos, tpy).xyz;
    vec3 xmy = imageLoad(u_pos, tmy).xyz;
    vec3 xpz = imageLoad(u_pos, tpz).xyz;
    vec3 xmz = imageLoad(u_pos, tmz).xyz;
    vec4 l0 = imageLoad(u_link[0], t);
    vec4 l1 = imageLoad(u_link[1], t);
    vec4 l2 = imageLoad(u_link[2], t);
    vec4 l3 = imageLoad(u_link[3], t);
    vec4 l4 = imageLoad(u_link[4], t);
    // the constraint interval, as in chainmail_pass.frag.glsl
    vec3 lo = max(xpx - vec3(l0.y, l0.z, l0.z), xmx + vec3(l0.w, -l1.y, -l1.y));
    vec3 hi = min(xpx + vec3(-l0.x, l0.z, l0.z), xmx + vec3(l1.x, l1.y, l1.y));
    lo = max(lo, max(xpy - vec3(l2.x, l1.w, l2.x), xmy + vec3(-l2.w, l2.y, -l2.w)));
    hi = min(hi, min(xpy + vec3(l2.x, -l1.z, l2.x), xmy + vec3(l2.w, l2.z, l2.w)));
    lo = max(lo, max(xpz - vec3(l3.z, l3.z, l3.y), xmz + vec3(-l4.y, -l4.y, l3.w)));
    hi = min(hi, min(xpz + vec3(l3.z, l3.z, -l3.x), xmz + vec3(l4.y, l4.y, l4.x)));
    // the mean displacement of the linked neighbours (fx, bx, fy, by, fz, bz mins)
    float wpx = present(l0.x), wmx = present(l0.w), wpy = present(l1.z);
    float wmy = present(l2.y), wpz = present(l3.x), wmz = present(l3.w);
    float cnt = wpx + wmx + wpy + wmy + wpz + wmz;
    if (cnt == 0.0) {
        return;
    }
    vec3 su = wpx * (xpx - imageLoad(u_rest, tpx).xyz) + wmx * (xmx - imageLoad(u_rest, tmx).xyz);
    su += wpy * (xpy - imageLoad(u_rest, tpy).xyz) + wmy * (xmy - imageLoad(u_rest, tmy).xyz);
    su += wpz * (xpz - imageLoad(u_rest, tpz).xyz) + wmz * (xmz - imageLoad(u_rest, tmz).xyz);
    vec3 target = imageLoad(u_rest, t).xyz + su / cnt;
    vec3 y = min(max(target, lo), hi);
    // an empty interval (conflicting neighbours): stay
    cm_out = vec4(mix(y, x, greaterThan(lo, hi)), p.w);
}
