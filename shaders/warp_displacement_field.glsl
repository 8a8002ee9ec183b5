// Imported displacement field (deform/displacement_field.py): the pull-back convention of
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

vec3 warp(vec3 p) {
    return p + WARP_u_index((WARP_world_to_grid * vec4(p, 1.0)).xyz);
}

// I + du/dp, du/dc by central differences at +-0.5 node along each grid axis, carried to
// world by dc/dp (the linear part of WARP_world_to_grid). For shading normals only.
mat3 warp_jacobian(vec3 p) {
    vec3 c = (WARP_world_to_grid * vec4(p, 1.0)).xyz;
    mat3 g;
    g[0] = WARP_u_index(c + vec3(0.5, 0.0, 0.0)) - WARP_u_index(c - vec3(0.5, 0.0, 0.0));
    g[1] = WARP_u_index(c + vec3(0.0, 0.5, 0.0)) - WARP_u_index(c - vec3(0.0, 0.5, 0.0));
    g[2] = WARP_u_index(c + vec3(0.0, 0.0, 0.5)) - WARP_u_index(c - vec3(0.0, 0.0, 0.5));
    return mat3(1.0) + g * mat3(WARP_world_to_grid);
}
