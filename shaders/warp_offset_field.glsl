// Offset-field warp (deform/elements/offset_field.py). Grid nodes ("elements") rest at
// X = lo + (i, j, k) * spacing and are displaced by u (mm), stored per node in the RGBA16F
// 2D array texture WARP_displacement (layer k = z-slice k; xyz = u, a = material); u is
// trilinear between nodes and 0 outside the grid box [lo, lo + size]. The material
// point X is seen at X + u(X), so the warp solves q + u(q) = p by the fixed point
// q <- p - u(q), WARP_ITERATIONS times, starting from q = p (1 step = the thesis'
// approximation q = p - u(p)) or, when WARP_SEEDED, from q = p - v(p), v the inverse
// offsets baked on a finer node grid over the same box (WARP_inverse, an RGBA16F 3D
// texture: one hardware-trilinear fetch; shaders/offset_field_bake.comp.glsl).
// WARP_ITERATIONS, WARP_SEEDED and the macro WARP_ITERATE (the steps written out) are
// prepended by the warp (Warp.glsl_constants): llvmpipe does not unroll the loop itself.
uniform vec3 WARP_lo;          // grid box corner (node 0, 0, 0), mm
uniform vec3 WARP_size;        // hi - lo, mm
uniform vec3 WARP_shape;       // nodes per axis (n_x, n_y, n_z)
uniform sampler2DArray WARP_displacement;
uniform sampler3D WARP_inverse;   // baked inverse offsets (WARP_SEEDED only)
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

// u and grad u (columns d u / d x, y, z) at s in [0, 1]³ of the grid box (clamped) from
// the 8 nodes of its cell, fetched unfiltered: the trilinear value and the analytic
// gradient of the trilinear interpolant (the cell of the lower node on cell faces), as
// the CPU reference (OffsetFieldWarp.jacobian); both 0 outside the grid box.
void WARP_cell(vec3 s, out vec3 u, out mat3 grad) {
    vec3 x = clamp(s, 0.0, 1.0) * (WARP_shape - 1.0);
    vec3 i0 = min(floor(x), WARP_shape - 2.0);
    vec3 f = x - i0;
    ivec3 i = ivec3(i0);   // (x, y, layer = z)
    vec3 u000 = texelFetch(WARP_displacement, i, 0).xyz;
    vec3 u100 = texelFetch(WARP_displacement, i + ivec3(1, 0, 0), 0).xyz;
    vec3 u010 = texelFetch(WARP_displacement, i + ivec3(0, 1, 0), 0).xyz;
    vec3 u110 = texelFetch(WARP_displacement, i + ivec3(1, 1, 0), 0).xyz;
    vec3 u001 = texelFetch(WARP_displacement, i + ivec3(0, 0, 1), 0).xyz;
    vec3 u101 = texelFetch(WARP_displacement, i + ivec3(1, 0, 1), 0).xyz;
    vec3 u011 = texelFetch(WARP_displacement, i + ivec3(0, 1, 1), 0).xyz;
    vec3 u111 = texelFetch(WARP_displacement, i + ivec3(1, 1, 1), 0).xyz;
    vec3 dx = mix(mix(u100 - u000, u110 - u010, f.y), mix(u101 - u001, u111 - u011, f.y), f.z);
    vec3 dy = mix(mix(u010 - u000, u110 - u100, f.x), mix(u011 - u001, u111 - u101, f.x), f.z);
    vec3 dz = mix(mix(u001 - u000, u101 - u100, f.x), mix(u011 - u010, u111 - u110, f.x), f.y);
    float inside = WARP_inside(s);
    vec3 k = inside * (WARP_shape - 1.0) / WARP_size;   // grid units -> mm
    grad = mat3(dx * k.x, dy * k.y, dz * k.z);
    vec3 lo = mix(mix(u000, u100, f.x), mix(u010, u110, f.x), f.y);
    vec3 hi = mix(mix(u001, u101, f.x), mix(u011, u111, f.x), f.y);
    u = mix(lo, hi, f.z) * inside;
}

// grad u at q (8 texel reads instead of the 12 bilinear ones of central differences).
mat3 WARP_grad_u(vec3 q) {
    vec3 u;
    mat3 grad;
    WARP_cell((q - WARP_lo) / WARP_size, u, grad);
    return grad;
}

// WARP_KEEP_GRADIENT (shaded rays without the det J overlay): the last fixed-point step
// (WARP_offset_last in WARP_ITERATE) reads u from its cell's 8 nodes and keeps grad u
// there; the shading's Jacobian uses it instead of reading the 8 nodes of the final q's
// cell again (the step moves q by the last correction only, hundredths of a voxel).
#if defined(SHADING) && !defined(DETJ_OVERLAY)
#define WARP_KEEP_GRADIENT
mat3 WARP_kept_grad = mat3(0.0);
vec3 WARP_offset_last(vec3 q) {
    vec3 u;
    WARP_cell((q - WARP_lo) / WARP_size, u, WARP_kept_grad);
    return u;
}
#else
#define WARP_offset_last WARP_offset
#endif

vec3 warp(vec3 p) {
    vec3 q = p;
    if (WARP_SEEDED) {  // a constant: the compiler keeps one branch
        vec3 s = (p - WARP_lo) / WARP_size;
        vec3 tc = (clamp(s, 0.0, 1.0) * (WARP_inverse_shape - 1.0) + 0.5) / WARP_inverse_shape;
        q = p - textureLod(WARP_inverse, tc, 0.0).xyz * WARP_inside(s);
    }
    WARP_ITERATE   // WARP_ITERATIONS times q = p - WARP_offset(q), unrolled, the last
                   // one WARP_offset_last
    return q;
}

// d warp / d p = (I + grad u(q))^-1 at q = warp(p), given q (the raycaster keeps it
// from the sample's own warp: no second inverse). For shading normals only; a folded
// field (singular I + grad u) gives the identity.
mat3 warp_jacobian_at(vec3 p, vec3 q) {
#ifdef WARP_KEEP_GRADIENT
    // a constant condition: the seed alone (0 steps) keeps no gradient
    mat3 a = mat3(1.0) + (WARP_ITERATIONS >= 1 ? WARP_kept_grad : WARP_grad_u(q));
#else
    mat3 a = mat3(1.0) + WARP_grad_u(q);
#endif
    return abs(determinant(a)) > 1e-6 ? inverse(a) : mat3(1.0);
}

mat3 warp_jacobian(vec3 p) { return warp_jacobian_at(p, warp(p)); }
