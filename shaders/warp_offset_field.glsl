// Offset-field warp (deform/elements/offset_field.py). Grid nodes ("elements") rest at
// X = lo + (i, j, k) * spacing and are displaced by u (mm), stored per node in the RGBA16F
// 2D array texture WARP_displacement (layer k = z-slice k; xyz = u, a = material); u is
// trilinear between nodes and 0 outside the grid box [lo, lo + size]. The material
// point X is seen at X + u(X), so the warp solves q + u(q) = p by the fixed point
// q <- p - u(q), WARP_ITERATIONS times, starting from q = p (1 step = the thesis'
// approximation q = p - u(p)) or, when WARP_SEEDED, from q = p - v(p), v the inverse
// offsets baked on a finer node grid over the same box (WARP_inverse, same layout;
// shaders/offset_field_bake.comp.glsl).
// WARP_ITERATIONS, WARP_SEEDED and the macro WARP_ITERATE (the steps written out) are
// prepended by the warp (Warp.glsl_constants): llvmpipe does not unroll the loop itself.
uniform vec3 WARP_lo;          // grid box corner (node 0, 0, 0), mm
uniform vec3 WARP_size;        // hi - lo, mm
uniform vec3 WARP_shape;       // nodes per axis (n_x, n_y, n_z)
uniform sampler2DArray WARP_displacement;
uniform sampler2DArray WARP_inverse;   // baked inverse offsets (WARP_SEEDED only)
uniform vec3 WARP_inverse_shape;       // its nodes per axis (finer than WARP_shape)

// Trilinear value of a node grid stored as z-slice layers, at s in [0, 1]³ of the grid
// box: two bilinear fetches (layers k, k + 1; x and y clamp to edge) and a lerp along z.
// A macro, not a function: a sampler passed as a function argument costs llvmpipe
// ~25 % of a deformed frame.
#define WARP_TRILINEAR(FIELD, SHAPE, S, OUT) {                                  \
    vec3 g_ = (S) * ((SHAPE) - 1.0);                                            \
    vec2 tc_ = (g_.xy + 0.5) / (SHAPE).xy;                                      \
    float z_ = clamp(g_.z, 0.0, (SHAPE).z - 1.0);                               \
    float layer_ = min(floor(z_), (SHAPE).z - 2.0);                             \
    OUT = mix(textureLod(FIELD, vec3(tc_, layer_), 0.0).xyz,                    \
              textureLod(FIELD, vec3(tc_, layer_ + 1.0), 0.0).xyz, z_ - layer_); \
}

// 1 inside the grid box, 0 outside (branch-free).
float WARP_inside(vec3 s) {
    vec3 in3 = step(vec3(0.0), s) * step(s, vec3(1.0));
    return in3.x * in3.y * in3.z;
}

// u(q), 0 outside the grid box.
vec3 WARP_offset(vec3 q) {
    vec3 s = (q - WARP_lo) / WARP_size;
    vec3 u;
    WARP_TRILINEAR(WARP_displacement, WARP_shape, s, u)
    return u * WARP_inside(s);
}

vec3 warp(vec3 p) {
    vec3 q = p;
    if (WARP_SEEDED) {  // a constant: the compiler keeps one branch
        vec3 s = (p - WARP_lo) / WARP_size;
        vec3 v;
        WARP_TRILINEAR(WARP_inverse, WARP_inverse_shape, s, v)
        q = p - v * WARP_inside(s);
    }
    WARP_ITERATE   // WARP_ITERATIONS times q = p - WARP_offset(q), unrolled
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
