#version 430 core
// One integration step of the mass-spring model (deform/spring_model.py), one fragment
// per element of the atlas (massspring_atlas.glsl). Reads the state of the previous
// step, writes the new position (MRT 0) and velocity (MRT 1).
//
// massspring_config.glsl (generated per solver) defines NX, NY, NZ, TX, M and the
// compile-time spring tables MS_OFFSET[M] (ivec3) and MS_REST_LENGTH[M] (float).
// Inputs are read with imageLoad (unfiltered, like texelFetch, but about 1.5x cheaper
// on llvmpipe); neighbours outside the grid are clamped into it and weighted 0, so the
// unrolled spring loop has no branches.
#include "massspring_config.glsl"
#include "massspring_atlas.glsl"

layout(rgba32f, binding = 0) readonly uniform image2D u_pos;       // xyz position (mm), w stiffness
layout(rgba32f, binding = 1) readonly uniform image2D u_vel;       // xyz velocity (mm/s)
layout(rgba32f, binding = 2) readonly uniform image2D u_material;  // x damping (1/s), y mass
layout(rgba32f, binding = 3) readonly uniform image2D u_target;    // xyz target (mm), w pinned

uniform float u_spring_constant;
uniform float u_spring_damping;
uniform float u_dt;
uniform float u_max_step;     // displacement clamp (mm), 0 = off
uniform int u_semi_implicit;  // 0: explicit Euler, 1: symplectic Euler
uniform bool u_pin_only;      // no step: only move pinned elements to their targets

layout(location = 0) out vec4 out_pos;
layout(location = 1) out vec4 out_vel;

void main() {
    ivec2 t = ivec2(gl_FragCoord.xy);
    vec4 p = imageLoad(u_pos, t);
    vec4 target = imageLoad(u_target, t);
    if (target.w > 0.5) {  // pinned: at the target, at rest
        out_pos = vec4(target.xyz, p.w);
        out_vel = vec4(0.0);
        return;
    }
    if (u_pin_only) {
        out_pos = p;
        out_vel = imageLoad(u_vel, t);
        return;
    }
    ivec3 e = ms_element(t);
    vec3 x = p.xyz;
    vec3 v = imageLoad(u_vel, t).xyz;
    vec2 material = imageLoad(u_material, t).xy;
    float half_k = 0.5 * u_spring_constant;
    const ivec3 last = ivec3(NX - 1, NY - 1, NZ - 1);

    vec3 f = vec3(0.0);
    for (int s = 0; s < M; ++s) {
        ivec3 n = e + MS_OFFSET[s];
        ivec3 nc = clamp(n, ivec3(0), last);
        ivec2 tn = ms_texel(nc);
        vec4 pb = imageLoad(u_pos, tn);
        vec3 vb = imageLoad(u_vel, tn).xyz;
        vec3 d = pb.xyz - x;
        float len = length(d);
        // no spring to outside the grid; direction undefined (d^ = 0) below 1e-9
        bool spring = n == nc && len >= 1e-9;
        vec3 dh = spring ? d / len : vec3(0.0);
        float k = half_k * (p.w + pb.w);
        f += (k * (len - MS_REST_LENGTH[s]) + u_spring_damping * dot(vb - v, dh)) * dh;
    }
    f -= material.x * v;
    vec3 a = f / material.y;

    vec3 v_new = v + u_dt * a;
    vec3 step_x = u_dt * (u_semi_implicit != 0 ? v_new : v);
    if (u_max_step > 0.0) {
        float len = length(step_x);
        if (len > u_max_step) {
            float s = u_max_step / len;
            step_x *= s;
            v_new *= s;
        }
    }
    out_pos = vec4(x + step_x, p.w);
    out_vel = vec4(v_new, 0.0);
}
