// Trilinear-lattice warp (deform/lattice/warp.py; Knuth, Kohlhammer, Kuijper, GRAPP 2010).
// A grid of WARP_cells trilinear cells maps the unit cube (u) onto the deformed lattice;
// the content of the box [WARP_lo, WARP_lo + WARP_size] (original world, mm) is shown at
// grid(u), u = (x - lo) / size. The warp inverts it per sample: u with grid(u) = p, then
// q = lo + u * size.
// * Seed: the inverse baked on the CPU on a node grid over the deformed lattice's bounds
//   (WARP_seed: xyz = u, a = 1 near the lattice, 0 where no sample can be inside it),
//   one hardware-trilinear fetch.
// * Newton steps u <- u - du, du = J(u)^-1 (grid(u) - p). WARP_ADAPTIVE 1: a loop of at
//   most WARP_ITERATIONS steps that stops after the first step with
//   |du * WARP_size| <= WARP_tolerance (mm), the rule of LatticeWarp.solve. WARP_ADAPTIVE 0:
//   WARP_ITERATIONS fixed steps written out in the macro WARP_ITERATE. grid(u) and J come from the 8
//   corners of u's cell (texelFetch of the node texture WARP_nodes, RGBA32F): exact in
//   float32 on every GPU, with no filter-weight rounding; outside [0, 1]³ the boundary
//   cell's polynomial is extrapolated, so Newton steps may cross the lattice's surface.
// * Outside the lattice (u not in [0, 1]³): the identity where the lattice's boundary
//   is the box itself (WARP_OUTSIDE_IDENTITY 1), else nothing (q = WARP_FAR).
// A linear lattice (WARP_LINEAR 1) is one affine map of all space: q = WARP_matrix p.
// WARP_LINEAR, WARP_OUTSIDE_IDENTITY, WARP_ADAPTIVE, WARP_ITERATIONS, WARP_ITERATE and
// WARP_FAR are prepended by the warp (Warp.glsl_constants).
#if WARP_LINEAR
uniform mat4 WARP_matrix;   // deformed world -> original world (mm)

vec3 warp(vec3 p) { return (WARP_matrix * vec4(p, 1.0)).xyz; }
mat3 warp_jacobian(vec3 p) { return mat3(WARP_matrix); }
#else
uniform vec3 WARP_lo;           // the box's lower corner (original world, mm)
uniform vec3 WARP_size;         // its extent (mm)
uniform vec3 WARP_cells;        // lattice cells per axis
uniform sampler3D WARP_nodes;   // (cells + 1) node points (deformed world, mm), texelFetch
uniform sampler3D WARP_seed;    // baked inverse: xyz = u, a = near-lattice flag (linear)
uniform vec3 WARP_seed_lo;      // the baked nodes' box (deformed world, mm)
uniform vec3 WARP_seed_size;
uniform vec3 WARP_seed_shape;   // baked nodes per axis
uniform float WARP_tolerance;   // WARP_ADAPTIVE: stop once a step moves q by <= this (mm)

// grid(U) -> F and dF/dU -> J (columns), from the 8 corners of U's cell (the cell of
// clamp(U, 0, 1); its polynomial extrapolated beyond). A macro: llvmpipe is slow with
// samplers passed to functions.
#define WARP_EVAL(U, F, J) {                                                       \
    vec3 g_ = (U) * WARP_cells;                                                    \
    ivec3 i_ = ivec3(clamp(floor(g_), vec3(0.0), WARP_cells - 1.0));               \
    vec3 f_ = g_ - vec3(i_);                                                       \
    vec3 c000_ = texelFetch(WARP_nodes, i_, 0).xyz;                                \
    vec3 c100_ = texelFetch(WARP_nodes, i_ + ivec3(1, 0, 0), 0).xyz;               \
    vec3 c010_ = texelFetch(WARP_nodes, i_ + ivec3(0, 1, 0), 0).xyz;               \
    vec3 c110_ = texelFetch(WARP_nodes, i_ + ivec3(1, 1, 0), 0).xyz;               \
    vec3 c001_ = texelFetch(WARP_nodes, i_ + ivec3(0, 0, 1), 0).xyz;               \
    vec3 c101_ = texelFetch(WARP_nodes, i_ + ivec3(1, 0, 1), 0).xyz;               \
    vec3 c011_ = texelFetch(WARP_nodes, i_ + ivec3(0, 1, 1), 0).xyz;               \
    vec3 c111_ = texelFetch(WARP_nodes, i_ + ivec3(1, 1, 1), 0).xyz;               \
    vec3 x00_ = mix(c000_, c100_, f_.x);                                           \
    vec3 x10_ = mix(c010_, c110_, f_.x);                                           \
    vec3 x01_ = mix(c001_, c101_, f_.x);                                           \
    vec3 x11_ = mix(c011_, c111_, f_.x);                                           \
    vec3 y0_ = mix(x00_, x10_, f_.y);                                              \
    vec3 y1_ = mix(x01_, x11_, f_.y);                                              \
    F = mix(y0_, y1_, f_.z);                                                       \
    vec3 dx_ = mix(mix(c100_ - c000_, c110_ - c010_, f_.y),                        \
                   mix(c101_ - c001_, c111_ - c011_, f_.y), f_.z);                 \
    vec3 dy_ = mix(x10_ - x00_, x11_ - x01_, f_.z);                                \
    J = mat3(dx_ * WARP_cells.x, dy_ * WARP_cells.y, (y1_ - y0_) * WARP_cells.z);  \
}

// WARP_KEEP_JACOBIAN (shaded rays without the det J overlay): each Newton step keeps
// the J it evaluated (at the step's start; the last step moves u by at most the
// tolerance), and the shading's Jacobian uses it instead of reading u's 8 nodes again.
#if defined(SHADING) && !defined(DETJ_OVERLAY)
#define WARP_KEEP_JACOBIAN
mat3 WARP_step_J = mat3(1.0);
#define WARP_KEEP_STEP_J(J) WARP_step_J = (J);
#else
#define WARP_KEEP_STEP_J(J)
#endif

// The Newton step D = J(U)^-1 (grid(U) - P) on grid(U) = P, solved by cross products
// (Cramer's rule); 0 where J is (nearly) singular (a folded lattice).
#define WARP_NEWTON_DELTA(U, P, D) {                                               \
    vec3 fn_;                                                                      \
    mat3 jn_;                                                                      \
    WARP_EVAL(U, fn_, jn_)                                                         \
    WARP_KEEP_STEP_J(jn_)                                                          \
    vec3 r_ = fn_ - (P);                                                           \
    vec3 a_ = cross(jn_[1], jn_[2]);                                               \
    float det_ = dot(jn_[0], a_);                                                  \
    float scale_ = length(jn_[0]) * length(jn_[1]) * length(jn_[2]);               \
    D = vec3(0.0);                                                                 \
    if (abs(det_) > 1.0e-6 * scale_) {                                             \
        D = vec3(dot(a_, r_), dot(cross(jn_[2], jn_[0]), r_),                      \
                 dot(cross(jn_[0], jn_[1]), r_)) / det_;                           \
    }                                                                              \
}

// One Newton step; a (nearly) singular J leaves U unchanged.
#define WARP_NEWTON(U, P) {                                                        \
    vec3 dn_;                                                                      \
    WARP_NEWTON_DELTA(U, P, dn_)                                                   \
    U -= dn_;                                                                      \
}

// The last sample's u (the raycaster asks for the Jacobian where it just warped).
vec3 WARP_memo_p = vec3(1.0e30);
vec3 WARP_memo_u = vec3(0.0);
bool WARP_memo_inside = false;

vec3 WARP_outside(vec3 p) {
#if WARP_OUTSIDE_IDENTITY
    return p;
#else
    return vec3(WARP_FAR);
#endif
}

// u of p (false: p is outside the lattice).
bool WARP_invert(vec3 p, out vec3 u) {
    u = vec3(0.0);
    vec3 s = (p - WARP_seed_lo) / WARP_seed_size;
    if (any(lessThan(s, vec3(0.0))) || any(greaterThan(s, vec3(1.0)))) return false;
    vec4 seed = textureLod(WARP_seed, (s * (WARP_seed_shape - 1.0) + 0.5) / WARP_seed_shape, 0.0);
    if (seed.a == 0.0) return false;   // no baked node near: far from the lattice
    u = seed.xyz;
#if WARP_ADAPTIVE
    float tol2 = WARP_tolerance * WARP_tolerance;
    for (int k = 0; k < WARP_ITERATIONS; ++k) {
        vec3 du;
        WARP_NEWTON_DELTA(u, p, du)
        u -= du;
        vec3 dq = du * WARP_size;
        if (dot(dq, dq) <= tol2) break;
    }
#else
    WARP_ITERATE   // WARP_ITERATIONS times WARP_NEWTON(u, p), unrolled
#endif
    return all(greaterThanEqual(u, vec3(0.0))) && all(lessThanEqual(u, vec3(1.0)));
}

vec3 warp(vec3 p) {
    vec3 u;
    bool inside = WARP_invert(p, u);
    WARP_memo_p = p;
    WARP_memo_u = u;
    WARP_memo_inside = inside;
    return inside ? WARP_lo + u * WARP_size : WARP_outside(p);
}

// d warp / d p = diag(size) J(u)^-1 inside the lattice, the identity outside (and where
// J is singular).
mat3 warp_jacobian(vec3 p) {
    vec3 u = WARP_memo_u;
    bool inside = WARP_memo_inside;
    if (p != WARP_memo_p) inside = WARP_invert(p, u);
    if (!inside) return mat3(1.0);
    vec3 f;
    mat3 j;
#ifdef WARP_KEEP_JACOBIAN
    // from p's last Newton step (an inside point takes one when there are steps; a
    // constant condition)
    if (WARP_ITERATIONS >= 1) j = WARP_step_J; else WARP_EVAL(u, f, j)
#else
    WARP_EVAL(u, f, j)
#endif
    vec3 a = cross(j[1], j[2]);
    float det = dot(j[0], a);
    if (abs(det) <= 1.0e-6 * length(j[0]) * length(j[1]) * length(j[2])) return mat3(1.0);
    // rows of J^-1 are (j1 x j2, j2 x j0, j0 x j1) / det; scaled by size per row
    mat3 inv_t = mat3(a, cross(j[2], j[0]), cross(j[0], j[1])) / det;   // columns = rows of J^-1
    return matrixCompMult(transpose(inv_t), mat3(WARP_size, WARP_size, WARP_size));
}
#endif
