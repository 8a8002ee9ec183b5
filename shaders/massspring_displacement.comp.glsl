#version 430 core
// Writes the mass-spring displacement texture (deform/massspring_gpu.py): texel
// (i, j, k) = (position - rest position, stiffness), read from the element atlas.
#include "massspring_config.glsl"
#include "massspring_atlas.glsl"

layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;

layout(rgba16f, binding = 0) writeonly uniform image3D u_displacement;
layout(rgba32f, binding = 1) readonly uniform image2D u_pos;   // xyz position (mm), w stiffness
layout(rgba32f, binding = 2) readonly uniform image2D u_rest;  // xyz rest position (mm)

void main() {
    ivec3 e = ivec3(gl_GlobalInvocationID);
    if (!ms_inside(e)) return;
    ivec2 t = ms_texel(e);
    vec4 p = imageLoad(u_pos, t);
    imageStore(u_displacement, e, vec4(p.xyz - imageLoad(u_rest, t).xyz, p.w));
}
