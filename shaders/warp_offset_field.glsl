// Offset-field warp (deform/offset_field.py). Grid nodes ("elements") rest at
// X = lo + (i, j, k) * spacing and are displaced by u (mm), stored per node in the RGBA16F
// 3D texture WARP_displacement (xyz = u, a = material); u is trilinear between nodes and
// 0 outside the grid box [lo, lo + size]. The material point X is seen at X + u(X), so
// the warp solves q + u(q) = p by the fixed point q <- p - u(q), starting from q = p,
// WARP_iterations times (1 = the thesis' approximation q = p - u(p)).
uniform vec3 WARP_lo;          // grid box corner (node 0, 0, 0), mm
uniform vec3 WARP_size;        // hi - lo, mm
uniform vec3 WARP_shape;       // nodes per axis (n_x, n_y, n_z)
uniform int WARP_iterations;   // fixed-point steps, 1..64
uniform sampler3D WARP_displacement;

// u(q): hardware trilinear filtering at node-centred texture coordinates (node i at the
// centre of texel i), times a branch-free mask that is 0 outside the grid box.
vec3 WARP_offset(vec3 q) {
    vec3 s = (q - WARP_lo) / WARP_size;   // [0, 1] inside the grid box
    vec3 tc = (s * (WARP_shape - 1.0) + 0.5) / WARP_shape;
    vec3 inside = step(vec3(0.0), s) * step(s, vec3(1.0));
    return textureLod(WARP_displacement, tc, 0.0).xyz * (inside.x * inside.y * inside.z);
}

vec3 warp(vec3 p) {
    vec3 q = p;
    for (int i = 0; i < WARP_iterations; ++i) {
        q = p - WARP_offset(q);
    }
    return q;
}

// d warp / d p = (I + grad u(q))^-1 at q = warp(p); grad u by central differences of
// the interpolated field at +-0.5 node spacing (exact inside one trilinear cell, the
// mean slope of the two cells across a cell face). For shading normals only; a folded
// field (singular I + grad u) gives the identity.
mat3 warp_jacobian(vec3 p) {
    vec3 q = warp(p);
    vec3 h = 0.5 * WARP_size / (WARP_shape - 1.0);
    mat3 g;
    g[0] = (WARP_offset(q + vec3(h.x, 0.0, 0.0)) - WARP_offset(q - vec3(h.x, 0.0, 0.0))) / (2.0 * h.x);
    g[1] = (WARP_offset(q + vec3(0.0, h.y, 0.0)) - WARP_offset(q - vec3(0.0, h.y, 0.0))) / (2.0 * h.y);
    g[2] = (WARP_offset(q + vec3(0.0, 0.0, h.z)) - WARP_offset(q - vec3(0.0, 0.0, h.z))) / (2.0 * h.z);
    mat3 a = mat3(1.0) + g;
    return abs(determinant(a)) > 1e-6 ? inverse(a) : mat3(1.0);
}
