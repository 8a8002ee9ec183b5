#version 430
// Per-voxel data gradient for shading (app/render/gradients.py): half the central
// difference along each texel axis, in data units per texel, the volume's edges
// replicated. Trilinear filtering of this texture at u equals the central differences
// of the trilinearly filtered volume at u +- 1 texel (filtering is linear in the
// voxel values), so one fetch replaces six.
layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;
layout(rgba16f, binding = 0) writeonly uniform image3D u_gradient;
#if defined(SLICE_PAIRS) || defined(SLICE_LAYERS)
uniform sampler2DArray u_volume;   // layer k holds slice k in r (SLICE_PAIRS: k + 1 in g)
#else
uniform sampler3D u_volume;
#endif
uniform ivec3 u_size;              // voxels per axis
uniform float u_scale;             // data value per texel value

float voxel(ivec3 i) {
    i = clamp(i, ivec3(0), u_size - 1);
    return texelFetch(u_volume, i, 0).r;
}

void main() {
    ivec3 i = ivec3(gl_GlobalInvocationID);
    if (any(greaterThanEqual(i, u_size))) return;
    vec3 g = vec3(voxel(i + ivec3(1, 0, 0)) - voxel(i - ivec3(1, 0, 0)),
                  voxel(i + ivec3(0, 1, 0)) - voxel(i - ivec3(0, 1, 0)),
                  voxel(i + ivec3(0, 0, 1)) - voxel(i - ivec3(0, 0, 1)));
    imageStore(u_gradient, i, vec4(0.5 * u_scale * g, 0.0));
}
