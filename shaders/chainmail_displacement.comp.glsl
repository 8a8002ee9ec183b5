#version 430 core
// Writes the GPU ChainMail displacement texture (deform/elements/chainmail_gpu.py) over the box
// [u_lo, u_hi) of elements: texel (i, j) of layer k = (position - rest, 0), read from
// the z-slice atlas; one invocation per element.
#include "chainmail_config.glsl"
#include "massspring_atlas.glsl"

layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;

layout(rgba16f, binding = 0) writeonly uniform image2DArray u_displacement;  // layer = z
layout(rgba32f, binding = 1) readonly uniform image2D u_pos;   // position - origin (mm)
layout(rgba32f, binding = 2) readonly uniform image2D u_rest;  // rest - origin (mm)

uniform ivec3 u_lo;
uniform ivec3 u_hi;  // exclusive

void main() {
    ivec3 e = u_lo + ivec3(gl_GlobalInvocationID);
    if (any(greaterThanEqual(e, u_hi))) return;
    ivec2 t = ms_texel(e);
    imageStore(u_displacement, e, vec4(imageLoad(u_pos, t).xyz - imageLoad(u_rest, t).xyz, 0.0));
}
