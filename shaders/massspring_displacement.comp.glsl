#version 430 core
// Writes the mass-spring displacement texture (deform/elements/massspring_gpu.py): texel
// (i, j, k) = (position - rest position, stiffness), read from the block atlas; one
// invocation per block, one store per block element (massspring_pass.glsl, generated).
#include "massspring_config.glsl"
#include "massspring_atlas.glsl"

layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;

layout(rgba16f, binding = 0) writeonly uniform image2DArray u_displacement;  // layer = z
layout(rgba32f, binding = 1) readonly uniform image2D u_pos[MS_E];   // xyz position (mm), w stiffness
layout(rgba32f, binding = MS_REST_BINDING) readonly uniform image2D u_rest[MS_E];  // xyz rest (mm)

#define MS_DISPLACE(e, p, r) \
    if (all(lessThan(e, ivec3(NX, NY, NZ)))) imageStore(u_displacement, e, vec4((p).xyz - (r).xyz, (p).w))

void main() {
    ivec3 b = ivec3(gl_GlobalInvocationID);
    if (any(greaterThanEqual(b, ivec3(BX, BY, BZ)))) return;
    ivec2 t = ms_texel(b);
    ivec3 base = b * ivec3(SX, SY, SZ);
#include "massspring_pass.glsl"
}
