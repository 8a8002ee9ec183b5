// Offset-field warp (deform/offset_field.py). Grid nodes ("elements") rest at
// X = lo + (i, j, k) * spacing and are displaced by u (mm), stored per node in the RGBA16F
// 2D array texture WARP_displacement (layer k = z-slice k; xyz = u, a = material); u is
// trilinear between nodes and 0 outside the grid box [lo, lo + size]. The material
// point X is seen at X + u(X), so the warp solves q + u(q) = p by the fixed point
// q <- p - u(q), WARP_ITERATIONS times, starting from q = p (1 step = the thesis'
// approximation q = p - u(p)) or, when WARP_SEEDED, from q = p - v(p), v the inverse
// offsets baked on a finer node grid over the same box (WARP_inverse, same layout;
// shaders/offset_field_bake.comp.glsl).
// WARP_ITERATIONS and WARP_SEEDED are compile-time constants prepended by the warp
// (Warp.glsl_constants), so the iteration unrolls.
uniform vec3 WARP_lo;          // grid box corner (node 0, 0, 0), mm
uniform vec3 WARP_size;        // hi - lo, mm
uniform vec3 WARP_shape;       // nodes per axis (n_x, n_y, n_z)
uniform sampler2DArray WARP_displacement;
uniform sampler2DArray WARP_inverse;   // baked inverse offsets (WARP_SEEDED only)
uniform vec3 WARP_inverse_shape;       // its nodes per axis (finer than WARP_shape)

// Trilinear value of a node grid stored as z-slice layers, at s in [0, 1]³ of the grid
// box (clamped to the box): two bilinear fetches (layers k, k + 1) and a lerp along z.
vec3 WARP_trilinear(sampler2DArray field, vec3 shape, vec3 s) {
    vec3 g = clamp(s, 0.0, 1.0) * (shape - 1.0);   // node coordinates
    vec2 tc = (g.xy + 0.5) / shape.xy;
    float layer = min(floor(g.z), shape.z - 2.0);
    vec3 a = textureLod(field, vec3(tc, layer), 0.0).xyz;
    vec3 b = textureLod(field, vec3(tc, layer + 1.0), 0.0).xyz;
    return mix(a, b, g.z - layer);
}

// 1 inside the grid box, 0 outside (branch-free).
float WARP_inside(vec3 s) {
    vec3 in3 = step(vec3(0.0), s) * step(s, vec3(1.0));
    return in3.x * in3.y * in3.z;
}

// u(q), 0 outside the grid box.
vec3 WARP_offset(vec3 q) {
    vec3 s = (q - WARP_lo) / WARP_size;
    return WARP_trilinear(WARP_displacement, WARP_shape, s) * WARP_inside(s);
}

vec3 warp(vec3 p) {
    vec3 q = p;
    if (WARP_SEEDED) {  // a constant: the compiler keeps one branch
        vec3 s = (p - WARP_lo) / WARP_size;
        q = p - WARP_trilinear(WARP_inverse, WARP_inverse_shape, s) * WARP_inside(s);
    }
    for (int i = 0; i < WARP_ITERATIONS; ++i) {
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
