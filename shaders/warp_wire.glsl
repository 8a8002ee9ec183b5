// Wire-field warp (deform/wires/field.py; Journal of WSCG 2006 wire paper, section 6).
// The attribute field covers the box [WARP_lo, WARP_lo + WARP_size] with WARP_shape voxels
// (voxel i centred at i + 1/2). Per sample: the nearest voxel says identity, vacated (the
// original place of a swept object: shows nothing) or swept by wire w; a swept sample
// takes t (table units 0..WARP_LUT_SIZE-1) trilinearly and maps q = A(t) p + b(t), where
// A = d q / d p and b = C - A M (C, M the base and modified wire points) are read from the
// wire's 3 rows of the lookup table WARP_lut (linear in t): row r = (A[r][0..2], b[r]).
// Layouts (WARP_LAYOUT_PACKED, a #define prepended by the warp):
//   0: WARP_state (R8UI: 0 identity, 1 vacated, 2 + wire) and WARP_t (R32F, linear filter);
//   1: WARP_code (R16UI: bit 15 swept, bits 8-14 wire, bits 0-7 integer t; 0x7FFF vacated),
//      t interpolated here from the 8 neighbours of the same wire.
// WARP_LAYOUT_PAPER 1 (the paper's section 7.2 split): WARP_code (R16UI: bit 15 swept,
//      bits 11-14 wire, bits 7-10 segment s, bits 0-6 integer t in s; 0x7FFF vacated) and
//      WARP_seg (16 wires x 17 floats: where segment s of wire w starts, in table units, at
//      [17 w + s]); each neighbour's (s, t) becomes its table coordinate before the 8 are
//      interpolated.
uniform vec3 WARP_lo;
uniform vec3 WARP_size;
uniform vec3 WARP_shape;
uniform float WARP_rows;      // rows of WARP_lut (3 per wire)
uniform sampler2D WARP_lut;
#if WARP_SMOOTH
// smooth wire sides and ends (deform/wires/wire.py Wire.sides, Wire.ends): per-voxel
// weight of the displacement, fading to 0 beyond the wire's radius and ends
uniform sampler3D WARP_weight;

#define WARP_W(OFF) texelFetch(WARP_weight, min(i0 + OFF, top), 0).r
// The weight at field coordinates g, trilinear from its 8 texels (clamped to the edge,
// as deform/wires/layouts.py _sample_t_float), and its exact gradient in mm.
float WARP_weight_at(vec3 g, out vec3 grad) {
    vec3 raw = g - 0.5;
    vec3 gc = clamp(raw, vec3(0.0), WARP_shape - 1.0);
    ivec3 top = ivec3(WARP_shape) - 1;
    ivec3 i0 = min(ivec3(floor(gc)), max(top - 1, ivec3(0)));
    vec3 f = gc - vec3(i0);
    vec3 e = 1.0 - f;
    float c000 = WARP_W(ivec3(0, 0, 0)), c100 = WARP_W(ivec3(1, 0, 0));
    float c010 = WARP_W(ivec3(0, 1, 0)), c110 = WARP_W(ivec3(1, 1, 0));
    float c001 = WARP_W(ivec3(0, 0, 1)), c101 = WARP_W(ivec3(1, 0, 1));
    float c011 = WARP_W(ivec3(0, 1, 1)), c111 = WARP_W(ivec3(1, 1, 1));
    grad.x = e.y * e.z * (c100 - c000) + f.y * e.z * (c110 - c010)
           + e.y * f.z * (c101 - c001) + f.y * f.z * (c111 - c011);
    grad.y = e.x * e.z * (c010 - c000) + f.x * e.z * (c110 - c100)
           + e.x * f.z * (c011 - c001) + f.x * f.z * (c111 - c101);
    grad.z = e.x * e.y * (c001 - c000) + f.x * e.y * (c101 - c100)
           + e.x * f.y * (c011 - c010) + f.x * f.y * (c111 - c110);
    vec3 inside = vec3(greaterThan(raw, vec3(0.0))) * vec3(lessThan(raw, WARP_shape - 1.0));
    grad *= inside * WARP_shape / WARP_size;  // per field voxel -> per mm
    float a = mix(mix(c000, c100, f.x), mix(c010, c110, f.x), f.y);
    float b = mix(mix(c001, c101, f.x), mix(c011, c111, f.x), f.y);
    return mix(a, b, f.z);
}
#endif
#if WARP_LAYOUT_PAPER
uniform usampler3D WARP_code;
uniform float WARP_seg[272];   // 16 wires x 17 segment starts (a uniform array: cheaper
                               // than texel fetches on llvmpipe)
#elif WARP_LAYOUT_PACKED
uniform usampler3D WARP_code;
#else
uniform usampler3D WARP_state;
uniform sampler3D WARP_t;
#endif

#if WARP_LAYOUT_PAPER
// table coordinate of a paper code: segment start + (t / 127) x the segment's extent
float WARP_paper_t(uint c) {
    int i = 17 * int((c >> 11u) & 0xFu) + int((c >> 7u) & 0xFu);
    float a = WARP_seg[i];
    return a + (WARP_seg[i + 1] - a) * (float(c & 0x7Fu) / 127.0);
}
// wire id and table coordinate of a code
#define WARP_WIRE_OF(C) (((C) >> 11u) & 0xFu)
#define WARP_T_OF(C) WARP_paper_t(C)
#elif WARP_LAYOUT_PACKED
#define WARP_WIRE_OF(C) (((C) >> 8u) & 0x7Fu)
#define WARP_T_OF(C) float((C) & 0xFFu)
#endif

#if WARP_LAYOUT_PAPER || WARP_LAYOUT_PACKED
// weight and table coordinate of neighbour OFF, counted when it belongs to wire W
#define WARP_CORNER(OFF, WT) {                                                    \
    uint c_ = texelFetch(WARP_code, min(i0 + OFF, top), 0).r;                     \
    float w_ = WARP_WIRE_OF(c_) == wire && c_ != 0x7FFFu ? (WT) : 0.0;            \
    ts += w_ * WARP_T_OF(c_);                                                     \
    ws += w_;                                                                     \
}
#endif

// 0 identity (q = p), 1 vacated (q far away), 2 swept (q mapped, A its Jacobian).
int WARP_lookup(vec3 p, out vec3 q, out mat3 A) {
    q = p;
    A = mat3(1.0);
    vec3 g = (p - WARP_lo) / WARP_size * WARP_shape;
    if (any(lessThan(g, vec3(0.0))) || any(greaterThanEqual(g, WARP_shape))) return 0;
    ivec3 v = ivec3(g);
    float t;
    uint wire;
#if WARP_LAYOUT_PAPER || WARP_LAYOUT_PACKED
    uint c = texelFetch(WARP_code, v, 0).r;
    if ((c & 0x8000u) == 0u) {
        if (c == 0x7FFFu) { q = vec3(WARP_FAR); return 1; }
        return 0;
    }
    wire = WARP_WIRE_OF(c);
    vec3 gc = clamp(g - 0.5, vec3(0.0), WARP_shape - 1.0);
    ivec3 i0 = ivec3(floor(gc));
    ivec3 top = ivec3(WARP_shape) - 1;
    vec3 f = gc - vec3(i0);
    vec3 e = 1.0 - f;
    float ts = 0.0;
    float ws = 0.0;
    WARP_CORNER(ivec3(0, 0, 0), e.x * e.y * e.z)
    WARP_CORNER(ivec3(1, 0, 0), f.x * e.y * e.z)
    WARP_CORNER(ivec3(0, 1, 0), e.x * f.y * e.z)
    WARP_CORNER(ivec3(1, 1, 0), f.x * f.y * e.z)
    WARP_CORNER(ivec3(0, 0, 1), e.x * e.y * f.z)
    WARP_CORNER(ivec3(1, 0, 1), f.x * e.y * f.z)
    WARP_CORNER(ivec3(0, 1, 1), e.x * f.y * f.z)
    WARP_CORNER(ivec3(1, 1, 1), f.x * f.y * f.z)
    t = ws > 0.0 ? ts / ws : WARP_T_OF(c);
#else
    uint s = texelFetch(WARP_state, v, 0).r;
    if (s < 2u) {
        if (s == 1u) { q = vec3(WARP_FAR); return 1; }
        return 0;
    }
    wire = s - 2u;
    t = textureLod(WARP_t, g / WARP_shape, 0.0).r;
#endif
    float x = (t + 0.5) / float(WARP_LUT_SIZE);
    float row = float(wire) * 3.0 + 0.5;
    vec4 r0 = textureLod(WARP_lut, vec2(x, row / WARP_rows), 0.0);
    vec4 r1 = textureLod(WARP_lut, vec2(x, (row + 1.0) / WARP_rows), 0.0);
    vec4 r2 = textureLod(WARP_lut, vec2(x, (row + 2.0) / WARP_rows), 0.0);
    A = transpose(mat3(r0.xyz, r1.xyz, r2.xyz));  // GLSL matrices are built by columns
    q = A * p + vec3(r0.w, r1.w, r2.w);
#if WARP_SMOOTH
    // p + w (q - p); its Jacobian I + w (A - I) + (q - p) (x) grad w (t's gradient left
    // out, as the paper's section 6.1)
    vec3 gw;
    float wt = WARP_weight_at(g, gw);
    vec3 d = q - p;
    q = p + wt * d;
    A = mat3(1.0) + wt * (A - mat3(1.0)) + outerProduct(d, gw);
#endif
    return 2;
}

// The raycaster asks for the Jacobian at the point it just warped (to shade it): the
// last lookup is kept, so shading costs no second lookup.
vec3 WARP_memo_p = vec3(1.0e30);
mat3 WARP_memo_A = mat3(1.0);

vec3 warp(vec3 p) {
    vec3 q;
    WARP_lookup(p, q, WARP_memo_A);
    WARP_memo_p = p;
    return q;
}

// d warp / d p = A(t) where swept (section 6.1: the gradient at the mapped point is
// carried back by it), the identity elsewhere.
mat3 warp_jacobian(vec3 p) {
    if (p == WARP_memo_p) return WARP_memo_A;
    vec3 q;
    mat3 A;
    WARP_lookup(p, q, A);
    return A;
}
