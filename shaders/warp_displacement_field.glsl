// Imported displacement field (deform/fields/displacement.py): the pull-back convention of
// ITK, ANTs and SimpleITK, warp(p) = p + u(p). u is trilinear between the nodes of the
// field's own grid (WARP_world_to_grid: world mm -> continuous node index), held in the
// RGBA16F 2D array texture WARP_displacement (layer k = z-slice k; xyz = u in RAS mm).
// Within half a node outside the grid the edge values hold (clamp to edge); farther out
// u = 0, as ITK's DisplacementFieldTransform.
uniform mat4 WARP_world_to_grid;
uniform vec3 WARP_shape;       // nodes per axis
uniform sampler2DArray WARP_displacement;

// u at continuous node index c (two bilinear fetches, a lerp along z), 0 far outside.
vec3 WARP_u_index(vec3 c) {
    vec3 in3 = step(vec3(-0.5), c) * step(c, WARP_shape - 0.5);
    vec2 tc = (c.xy + 0.5) / WARP_shape.xy;
    float z = clamp(c.z, 0.0, WARP_shape.z - 1.0);
    float layer = min(floor(z), WARP_shape.z - 2.0);
    vec3 u = mix(textureLod(WARP_displacement, vec3(tc, layer), 0.0).xyz,
                 textureLod(WARP_displacement, vec3(tc, layer + 1.0), 0.0).xyz, z - layer);
    return u * (in3.x * in3.y * in3.z);
}

// u and I + du/dp at p from the 8 nodes of its cell, fetched unfiltered: the trilinear
// value and the analytic gradient of the trilinear interpolant (the lower node's cell on
// cell faces, 0 along an axis clamped in the half-node border, as the CPU reference),
// carried to world by dc/dp (the linear part of WARP_world_to_grid).
void WARP_cell(vec3 p, out vec3 u, out mat3 J) {
    vec3 c = (WARP_world_to_grid * vec4(p, 1.0)).xyz;
    vec3 in3 = step(vec3(-0.5), c) * step(c, WARP_shape - 0.5);
    vec3 x = clamp(c, vec3(0.0), WARP_shape - 1.0);
    vec3 i0 = min(floor(x), WARP_shape - 2.0);
    vec3 f = x - i0;
    ivec3 i = ivec3(i0);
    vec3 u000 = texelFetch(WARP_displacement, i, 0).xyz;
    vec3 u100 = texelFetch(WARP_displacement, i + ivec3(1, 0, 0), 0).xyz;
    vec3 u010 = texelFetch(WARP_displacement, i + ivec3(0, 1, 0), 0).xyz;
    vec3 u110 = texelFetch(WARP_displacement, i + ivec3(1, 1, 0), 0).xyz;
    vec3 u001 = texelFetch(WARP_displacement, i + ivec3(0, 0, 1), 0).xyz;
    vec3 u101 = texelFetch(WARP_displacement, i + ivec3(1, 0, 1), 0).xyz;
    vec3 u011 = texelFetch(WARP_displacement, i + ivec3(0, 1, 1), 0).xyz;
    vec3 u111 = texelFetch(WARP_displacement, i + ivec3(1, 1, 1), 0).xyz;
    vec3 dx0 = mix(u100 - u000, u110 - u010, f.y), dx1 = mix(u101 - u001, u111 - u011, f.y);
    vec3 dy0 = mix(u010 - u000, u110 - u100, f.x), dy1 = mix(u011 - u001, u111 - u101, f.x);
    vec3 x00 = mix(u000, u100, f.x), x10 = mix(u010, u110, f.x);
    vec3 x01 = mix(u001, u101, f.x), x11 = mix(u011, u111, f.x);
    float inside = in3.x * in3.y * in3.z;
    // 0 along axes clamped in the half-node border, and everywhere far outside
    vec3 live = step(vec3(0.0), c) * step(c, WARP_shape - 1.0) * inside;
    mat3 g = mat3(mix(dx0, dx1, f.z) * live.x,
                  mix(dy0, dy1, f.z) * live.y,
                  (mix(x01, x11, f.y) - mix(x00, x10, f.y)) * live.z);
    J = mat3(1.0) + g * mat3(WARP_world_to_grid);
    u = mix(mix(x00, x10, f.y), mix(x01, x11, f.y), f.z) * inside;
}

// WARP_KEEP_JACOBIAN (shaded rays without the det J overlay): warp(p) reads u from its
// cell's 8 nodes and keeps the Jacobian at p, the point shading asks about (the same
// texels give both: no second read).
#if defined(SHADING) && !defined(DETJ_OVERLAY)
#define WARP_KEEP_JACOBIAN
mat3 WARP_kept_jacobian = mat3(1.0);
#endif

vec3 warp(vec3 p) {
#ifdef WARP_KEEP_JACOBIAN
    vec3 u;
    WARP_cell(p, u, WARP_kept_jacobian);
    return p + u;
#else
    return p + WARP_u_index((WARP_world_to_grid * vec4(p, 1.0)).xyz);
#endif
}

// I + du/dp at p (8 texel reads instead of the 24 of central differences). For shading
// normals and the det J overlay.
mat3 warp_jacobian(vec3 p) {
    vec3 u;
    mat3 J;
    WARP_cell(p, u, J);
    return J;
}

// The Jacobian at p given q = warp(p): kept by warp(p) where it keeps one.
mat3 warp_jacobian_at(vec3 p, vec3 q) {
#ifdef WARP_KEEP_JACOBIAN
    return WARP_kept_jacobian;
#else
    return warp_jacobian(p);
#endif
}
