#version 430 core
// One integration step of the mass-spring model (deform/elements/spring_model.py): one fragment
// per block of MS_E elements of the atlas (massspring_atlas.glsl). Reads the state of
// the previous step, writes the new position and velocity of each block element into
// the MS_STATE colour attachments (p0 v0 p1 v1 ...) of the other framebuffer.
//
// massspring_config.glsl (generated per solver) defines the grid, block and atlas
// constants; massspring_pass.glsl (generated) is main(): the springs of the block's
// elements unrolled, each distinct neighbour texel loaded once with imageLoad (about
// 1.5x cheaper than texelFetch on llvmpipe), neighbours outside the grid clamped into
// it and weighted 0 (no branches). With MS_PIN_PASS defined the same file is the pin
// pass instead (deform/elements/massspring_gpu.py: set_constraints).
#include "massspring_config.glsl"
#include "massspring_atlas.glsl"

// position (x, y, z mm; w stiffness) and velocity (x, y, z mm/s; w inverse mass, 0 when
// pinned) of block element e at image units 2e and 2e + 1
layout(rgba32f, binding = 0) readonly uniform image2D u_state[MS_STATE];
#ifdef MS_PIN_PASS
// per block element: target (x, y, z mm; w -1 when pinned, else the inverse mass)
layout(rgba32f, binding = MS_STATE) readonly uniform image2D u_target[MS_E];
#else
// damping (1/s) of block element e in channel e
layout(rgba32f, binding = MS_STATE) readonly uniform image2D u_damping;
#endif

uniform float u_half_k;          // spring_constant / 2
uniform float u_spring_damping;
uniform float u_dt;
uniform float u_max_step;        // displacement clamp (mm), 0 = off
uniform int u_semi_implicit;     // 0: explicit Euler, 1: symplectic Euler

layout(location = 0) out vec4 ms_out[MS_STATE];

// force of the spring from a to b on a (0 if b is outside the grid or |d| < MS_MIN_LENGTH)
vec3 ms_spring(vec4 pa, vec4 va, vec4 pb, vec4 vb, float rest_length, bool inside) {
    vec3 d = pb.xyz - pa.xyz;
    float len = length(d);
    vec3 dh = (inside && len >= MS_MIN_LENGTH) ? d / len : vec3(0.0);
    float k = u_half_k * (pa.w + pb.w);
    return (k * (len - rest_length) + u_spring_damping * dot(vb.xyz - va.xyz, dh)) * dh;
}

// one step of an element from its spring force f; pinned elements (inverse mass 0, at
// rest at their target) stay where they are
void ms_integrate(vec4 p, vec4 v, vec3 f, float damping, out vec4 out_pos, out vec4 out_vel) {
    vec3 a = (f - damping * v.xyz) * v.w;
    vec3 v_new = v.xyz + u_dt * a;
    vec3 step_x = u_dt * (u_semi_implicit != 0 ? v_new : v.xyz);
    if (u_max_step > 0.0) {
        float len = length(step_x);
        if (len > u_max_step) {
            float s = u_max_step / len;
            step_x *= s;
            v_new *= s;
        }
    }
    out_pos = vec4(p.xyz + step_x, p.w);
    out_vel = vec4(v_new, v.w);
}

// pin pass: pinned elements to their target, at rest; inverse masses from the target
void ms_pin(vec4 p, vec4 v, vec4 target, out vec4 out_pos, out vec4 out_vel) {
    bool pinned = target.w < 0.0;
    out_pos = pinned ? vec4(target.xyz, p.w) : p;
    out_vel = vec4(pinned ? vec3(0.0) : v.xyz, max(target.w, 0.0));
}

#include "massspring_pass.glsl"
