#version 430
// voxwarp raycaster. About this technique:
// One fragment per pixel casts a ray in *deformed* (display) space through the box
// u_bounds_lo..hi (the volume box pushed through the warp chain, clipped by the
// clipping box). Samples lie at t = t0 + (k + j) * step, j being a per-pixel jitter in
// [0, 1) (or 0.5 without jitter). Each sample position p is mapped by the warp chain to
// the original volume (the volume is never resampled) and classified by the
// compositing mode included as "mode.glsl" (dvr, mip, minip, average, flm, iso).
//
// Two paths, chosen at compile time:
// * LINEAR_PATH: every warp is affine; the chain folds into one matrix, so the ray is a
//   straight line in texel space. Empty-space skipping walks the min/max block grid
//   (BLOCK³ voxels per block, with a one-voxel apron). Each block stores its chessboard
//   distance d to the nearest block the mode can see; a ray in an invisible block jumps
//   out of the whole (2d-1)³ cube of invisible blocks around it in one step, landing on
//   the same sample lattice, so skipping never changes the image. With CELL_SKIP
//   (dvr, iso, flm) the map is kept per trilinear cell instead of per block, and per
//   ray-direction octant: the cube a ray may jump through starts at its cell and
//   extends ahead of it (app/render/skipping/maps.py). One nearest fetch per sample
//   (or per SAMPLES_PER_CHECK samples, app/render/skipping/checks.py).
// * otherwise: each sample goes through warp_chain(p). When every warp bounds its
//   displacement (and the mode is dvr, iso or flm), CELL_SKIP applies in *deformed*
//   space: the ray walks octant skip maps of the original cell visibility dilated by
//   the local displacement bound (app/render/skipping/maps.py warped_cell_visibility), so it jumps
//   wherever no sample could land on visible content, again on the sample lattice.
//   Without a bound, invisible blocks still save the volume fetch and classification.
// SUPPORT_MAP (warped rays): the chain's support, the bricks of the ray box where some
// warp may move a point by more than a tolerance (deform/support.py,
// app/render/skipping/support.py). A ray marches in three phases: straight up to its
// first crossing of the support's surface (rasterised per pixel, u_support_ranges,
// within the box around the bricks), through the chain up to its last, straight after.
// Straight samples use the undeformed ray's own matrix and arithmetic (the same texels,
// bit for bit). Each phase is its own loop (march_cells / march_blocks, inlined per
// kind): a CPU rasteriser runs both sides of a branch, but a loop that no lane of a SIMD
// group needs costs one test, and neighbouring rays enter and leave the box together.
// Early ray termination: the mode returns true from mode_sample when nothing further
// can change the pixel (opacity > 0.99, MIP at the window top, iso hit, ...).
// The renderer clears the viewport to u_background first; rays that miss the volume
// (or, with CELL_SKIP, meet nothing visible) discard instead of writing it.
// COMPARE: a fixed image is sampled at each sample's deformed world point and combined
// with the moving value (compare.glsl); the renderer then draws without skipping.
// MESH_DEPTH (mixed scenes, app/render/mesh_pass.py): the meshes were drawn first into
// u_mesh_color (premultiplied, over the background) and u_mesh_depth, at the viewport's
// size. Each ray stops at the mesh surface (the depth value unprojected to a point on
// the pixel's ray, which works for both projections) and the volume is composited over
// the mesh image; rays that would discard write the mesh image instead.

#include "common.glsl"
#include "volume_sample.glsl"
#include "transfer_function.glsl"
#include "shading.glsl"

uniform mat4 u_inv_view_proj;   // clip -> deformed world (mm)
uniform vec4 u_viewport;        // x, y, width, height in pixels
uniform vec3 u_bounds_lo;       // deformed-space box the rays march in
uniform vec3 u_bounds_hi;
uniform float u_step;           // sample distance in deformed space, mm
uniform int u_max_steps;
uniform int u_jitter;           // 0: samples at (k + 0.5) * step; 1: hashed jitter
uniform uint u_seed;
uniform vec4 u_background;      // premultiplied
uniform vec2 u_value_limits;    // min and max data value of the volume

// RGBA32F per block: x = chessboard distance in blocks to the nearest block the mode
// may see (0 = visible), y, z = min and max of the block's values (apron included).
// One fetch per block change.
uniform sampler3D u_block_info;
uniform ivec3 u_blocks;             // blocks per axis

out vec4 f_color;

#ifdef MESH_DEPTH
uniform sampler2D u_mesh_color;     // premultiplied mesh image over the background
uniform sampler2D u_mesh_depth;     // its depth buffer (window depth in [0, 1])
uniform mat4 u_mesh_inv_view_proj;  // clip -> world of the mesh pass
vec4 g_under;                       // what the volume is composited over at this pixel
#endif

bool g_inside = false;   // some sample of this ray lies inside the volume
vec3 g_ro;   // ray origin (deformed world)
vec3 g_rd;   // unit ray direction (deformed world)

#ifdef LINEAR_PATH
uniform mat4 u_world_to_texel;  // deformed world -> texel coordinates (folded chain)
uniform mat3 u_jacobian;        // d(original world) / d(deformed world)
vec3 g_u0;
vec3 g_du;
vec3 texel_at(float t) { return g_u0 + t * g_du; }
mat3 jacobian_at(float t) { return u_jacobian; }
#else
#include "warps.glsl"
vec3 texel_at(float t) { return world_to_texel(warp_chain(g_ro + t * g_rd)); }
#ifdef SUPPORT_MAP
uniform vec3 u_support_lo;            // deformed-space box holding the chain's support
uniform vec3 u_support_hi;
uniform mat4 u_straight_to_texel;     // deformed world -> texel of an undeformed ray
// per pixel (at its offset in the viewport): r = the first, a = the last ray parameter
// at which the ray crosses the support's surface (app/render/support_ranges.py)
uniform sampler2D u_support_ranges;
vec3 g_s0;
vec3 g_sd;
bool g_straight = false;   // the current sample is straight (its Jacobian is I)
vec3 straight_texel(float t) { return g_s0 + t * g_sd; }
#endif
#ifdef PIECEWISE
// Piecewise-linear warped rays: the chain is evaluated exactly at the ends of segments
// of up to u_segment samples (the current one: ray parameters g_ta..g_tb, texel
// positions g_ua..g_ub) and interpolated linearly in between, with its Jacobian.
// app/render/skipping/segments.py measures how long a segment may be, per region.
#ifdef SEGMENT_MAP
uniform int u_max_segment;              // up to this many samples, from the map:
uniform sampler3D u_segment_map;        // R32F: longest segment (mm) starting in a cell
uniform mat4 u_segment_world_to_map;    // deformed world -> map cell coordinates
uniform ivec3 u_segment_map_dims;
#else
uniform int u_segment;                  // fixed samples per segment
#endif
float g_ta = 0.0;
float g_tb = 0.0;
vec3 g_ua;
vec3 g_ub;
float segment_weight(float t) { return clamp((t - g_ta) / max(g_tb - g_ta, 1e-30), 0.0, 1.0); }
vec3 segment_texel(float t) { return mix(g_ua, g_ub, segment_weight(t)); }
#ifdef SHADING
mat3 g_Ja;   // the chain's Jacobian at the segment's ends
mat3 g_Jb;
#endif
// Samples the segment starting at ray parameter t may span (at least 1).
int segment_samples(float t) {
#ifndef SEGMENT_MAP
    return max(u_segment, 1);
#else
    vec3 m = (u_segment_world_to_map * vec4(g_ro + t * g_rd, 1.0)).xyz;
    ivec3 c = clamp(ivec3(floor(m)), ivec3(0), u_segment_map_dims - 1);
    float len = texelFetch(u_segment_map, c, 0).r;
    return clamp(int(len / u_step), 1, u_max_segment);
#endif
}
// Start a new segment ending at ray parameter te: from the previous end when the
// samples join up (joined), else from te itself (a segment of one sample).
void segment_to(float te, bool joined) {
    vec3 p = g_ro + te * g_rd;
#ifdef SHADING
    mat3 J;
    vec3 ue = world_to_texel(warp_chain_and_jacobian(p, J));
    g_Ja = joined ? g_Jb : J;
    g_Jb = J;
#else
    vec3 ue = world_to_texel(warp_chain(p));
#endif
    g_ta = joined ? g_tb : te;
    g_ua = joined ? g_ub : ue;
    g_tb = te;
    g_ub = ue;
}
#endif
#if defined(PIECEWISE) && defined(SHADING)
mat3 jacobian_at(float t) {   // interpolated along the segment, as the position
    float f = segment_weight(t);
    return g_Ja * (1.0 - f) + g_Jb * f;
}
#else
mat3 jacobian_at(float t) {
#ifdef SUPPORT_MAP
    if (g_straight) return mat3(1.0);
#endif
    return warp_chain_jacobian(g_ro + t * g_rd);
}
#ifndef PIECEWISE
// jacobian_at(t) for the sample texel_at(t) computed last: from the points its chain
// kept (warp_chain_kept_jacobian), without warping again.
mat3 jacobian_last(float t) {
#ifdef SUPPORT_MAP
    if (g_straight) return mat3(1.0);
#endif
    return warp_chain_kept_jacobian();
}
#define HAS_JACOBIAN_LAST
#endif
#endif
#ifdef CELL_SKIP
// Warped rays skip through *deformed* space: the skip map's cells are those of the
// original cell grid padded to the ray box, their visibility the original one dilated
// by the warps' local displacement bound (app/render/skipping/maps.py warped_cell_visibility).
uniform mat4 u_skip_world_to_texel;   // deformed world -> skip-map texel coordinates
uniform ivec3 u_cell_dims;            // cells of the skip map
vec3 g_u0;
vec3 g_du;
#endif
#endif
#if defined(LINEAR_PATH) || defined(CELL_SKIP)
// Where the ray is in the skip map's cells (straight rays: the volume's texels).
vec3 skip_at(float t) { return g_u0 + t * g_du; }
#endif

#include "compare.glsl"

#ifndef HAS_JACOBIAN_LAST
mat3 jacobian_last(float t) { return jacobian_at(t); }
#endif

// Gradient of the deformed field at the sample (texel u, ray parameter t) that
// texel_at(t) computed last; with COMPARE, combined with the fixed image's as the
// sample's value is (compare.glsl).
vec3 gradient_deformed(vec3 u, float t) {
    return compare_gradient(transpose(jacobian_last(t)) * gradient_original(u), t);
}
// gradient_deformed at any earlier sample (the chain warps its point again).
vec3 gradient_deformed_anew(vec3 u, float t) {
    return compare_gradient(transpose(jacobian_at(t)) * gradient_original(u), t);
}

bool block_in_grid(ivec3 b) {
    return all(greaterThanEqual(b, ivec3(0))) && all(lessThan(b, u_blocks));
}
vec4 block_info(ivec3 b) { return texelFetch(u_block_info, b, 0); }

// R8 (x255) per trilinear cell, for rays in the octant u_octant (signs of the texel-space
// direction, 0 counting as +): edge d of the largest cube of cells the mode cannot see
// that starts at the cell and extends in the octant's direction (0 = visible cell).
// Cell c spans texel coordinates [c - 1/2, c + 1/2]. The image is drawn once per
// octant present; pixels of other octants are discarded.
uniform sampler3D u_cell_skip;
uniform vec3 u_octant;
// COARSE_CELLS (straight rays of a big volume): the map's cells are CELL_FACTOR³
// trilinear cells (app/render/skipping/maps.py coarsen_visibility). A compile-time
// variant: a uniform branch runs both sides on llvmpipe, and a division by a uniform
// is scalarised (the per-cell program paid ~40 % of a frame for it).

// DETJ_OVERLAY: the modes tint their colour by det J (app/render/jacobian_overlay.py)
#ifdef DETJ_OVERLAY
#include "jacobian_overlay.glsl"
#else
vec3 detj_tint(vec3 rgb, float a, float t) { return rgb; }
#endif

#include "mode.glsl"

// SAMPLES_PER_CHECK (1 to 4, default 1; the renderer's choice,
// app/render/skipping/checks.py): lattice samples a straight ray with cell maps takes
// per skip-map check (the main loop below). On a CPU rasteriser every iteration pays
// for the check and its jump, taken or not, and for every sample in it, needed or not:
// where a sample is cheap (unshaded dvr), checking every second one saves more than
// the samples it adds in empty space cost; where it is dear (shading, iso's
// bisection), it does not (docs/benchmarks.md, "Fewer skip-map fetches per straight
// sample").
#ifndef SAMPLES_PER_CHECK
#define SAMPLES_PER_CHECK 1
#endif
// CHAINED_PER_CHECK (1 or 2): the same for samples through the warp chain (the warped
// loop, a support's chained phase). A chained sample costs the chain even in an
// invisible cell, so only dense views take two (app/render/skipping/checks.py).
#ifndef CHAINED_PER_CHECK
#define CHAINED_PER_CHECK 1
#endif

#ifdef LINEAR_PATH
// Ray parameter where the ray leaves the cube of (2r+1)³ grid units centred on `unit`
// (grid units of `size` texels, the grid shifted by `offset` texels).
float cube_exit(vec3 unit, float r, float size, float offset, vec3 face, vec3 inv_du) {
    vec3 bound = (unit + face + (2.0 * face - 1.0) * r) * size + offset;
    vec3 te = (bound - g_u0) * inv_du;
    return min(min(te.x, te.y), te.z);
}
#endif

#ifdef LINEAR_PATH
// Lattice sample k of a straight ray, without a skip check; true when the ray is done.
bool straight_sample(inout State s, int k, float t0, float j) {
    float t = t0 + (float(k) + j) * u_step;
    vec3 u = texel_at(t);
    return mode_sample(s, scene_value(u, t), u, t);
}
#endif

// Index of the first lattice sample at or after t (always past sample k, at most n).
int lattice_after(float t, float t0, float j, int k, int n) {
    return clamp(int(ceil((t - t0) / u_step - j)), k + 1, n);
}

#ifdef CELL_SKIP
// Skip edge d of the cell c holding texel position u (0: the cell is visible).
float cell_skip(vec3 u, out ivec3 c) {
    c = ivec3(floor(u + 0.5));
#ifndef LINEAR_PATH
    // the deformed-space map covers the ray box; guard against rounding at its faces
    if (any(lessThan(c, ivec3(0))) || any(greaterThanEqual(c, u_cell_dims))) return 0.0;
#endif
#ifndef COARSE_CELLS
    return texelFetch(u_cell_skip, c, 0).r * 255.0;
#else
    // a coarse cell's invisible cube of edge D (coarse cells) holds the fine cube of
    // edge D * f - o starting at c, o the largest offset of c in its coarse cell counted
    // from the corner the ray starts at (u_octant's sign per axis); branch-free: a
    // visible coarse cell (D = 0) gives at most 0
    ivec3 cc = c / CELL_FACTOR;
    float d = texelFetch(u_cell_skip, cc, 0).r * 255.0;
    ivec3 o = c - cc * CELL_FACTOR;
    ivec3 back = ivec3(lessThan(u_octant, vec3(0.0)));  // 1 where the ray runs to -
    o += back * (ivec3(CELL_FACTOR - 1) - 2 * o);
    o = clamp(o, ivec3(0), ivec3(CELL_FACTOR - 1));
    return max(d * float(CELL_FACTOR) - float(max(o.x, max(o.y, o.z))), 0.0);
#endif
}

// First lattice sample after the ray (at sample k) leaves the invisible cube of edge d
// at cell c: the cube spans [c - 1/2, c + 1/2] per axis, widened by d - 1 cells on the
// side u_octant points to (widen, per ray: +1, -1 or 0 per axis); the ray leaves
// through the faces it travels towards (offset = face - 1/2).
int after_cube(ivec3 c, float d, vec3 offset, vec3 widen, vec3 inv_du, float t0, float j,
               int k, int n) {
    vec3 te = (vec3(c) + offset + widen * (d - 1.0) - g_u0) * inv_du;
    return lattice_after(min(min(te.x, te.y), te.z), t0, j, k, n);
}
#endif

#ifndef LINEAR_PATH
// The texel of sample t: straight (as an undeformed ray computes it) or through the
// chain (without SUPPORT_MAP always through the chain).
vec3 span_texel(float t, bool straight) {
#ifdef SUPPORT_MAP
    g_straight = straight;
    return straight ? straight_texel(t) : texel_at(t);
#else
    return texel_at(t);
#endif
}
#ifdef CELL_SKIP
// Lattice sample k without a skip check (SAMPLES_PER_CHECK, CHAINED_PER_CHECK: an
// unchecked sample in an invisible cell adds exactly nothing), straight or through the
// chain (a warped sample may land outside the volume, where it shows nothing); true
// when the ray is finished.
bool unchecked_sample(inout State s, int k, float t0, float j, bool straight) {
    float t = t0 + (float(k) + j) * u_step;
    vec3 u = span_texel(t, straight);
    if (!inside_texels(u)) return mode_skip(s, -1.0);
    return mode_sample(s, scene_value(u, t), u, t);
}
// One more sample of a straight phase after a check (as the straight rays of the main
// loop below).
#define PHASE_UNCHECKED_SAMPLE                                              \
    if (straight && k < kb) {                                               \
        if (unchecked_sample(s, k, t0, j, true)) return true;               \
        ++k;                                                                \
    }
// Samples k .. kb - 1 (one phase of the ray), straight or through the chain, with the
// cell skipping of the main loop below; returns true when the ray is finished. A jump
// may leave k past kb.
bool march_cells(inout State s, inout int k, int kb, int n, float t0, float j,
                 vec3 inv_du, vec3 exit_offset, vec3 exit_widen, bool straight) {
    while (k < kb) {
        float t = t0 + (float(k) + j) * u_step;
        ivec3 c;
        float d = cell_skip(skip_at(t), c);
        if (d > 0.5) {
            k = after_cube(c, d, exit_offset, exit_widen, inv_du, t0, j, k, n);
            if (mode_skip(s, t0 + (float(k - 1) + j) * u_step)) return true;
            if (k >= kb) break;
            t = t0 + (float(k) + j) * u_step;
        }
        vec3 u = span_texel(t, straight);
        if (!inside_texels(u)) {
            if (mode_skip(s, -1.0)) return true;
            ++k;
            continue;
        }
        if (mode_sample(s, scene_value(u, t), u, t)) return true;
        ++k;
#if CHAINED_PER_CHECK > 1
        if (!straight && k < kb) {
            if (unchecked_sample(s, k, t0, j, false)) return true;
            ++k;
        }
#endif
#if SAMPLES_PER_CHECK > 1
        PHASE_UNCHECKED_SAMPLE
#endif
#if SAMPLES_PER_CHECK > 2
        PHASE_UNCHECKED_SAMPLE
#endif
#if SAMPLES_PER_CHECK > 3
        PHASE_UNCHECKED_SAMPLE
#endif
    }
    return false;
}
#else
// Samples k .. kb - 1 of a warped ray without cell maps (a phase with SUPPORT_MAP, the
// whole ray without), each checked against its block; true when the ray is finished.
bool march_blocks(inout State s, inout int k, int kb, float t0, float j, bool straight) {
    for (; k < kb; ++k) {
        float t = t0 + (float(k) + j) * u_step;
        vec3 u = span_texel(t, straight);
        if (!inside_texels(u)) {
            if (mode_skip(s, -1.0)) return true;
            continue;
        }
        g_inside = true;
        ivec3 blk = min(ivec3(u * (1.0 / float(BLOCK))), u_blocks - 1);
        vec4 info = block_info(blk);
        bool visible = info.x < 0.5 && block_visible(info.yz, s);
#ifdef NO_SKIPPING
        visible = true;
#endif
        if (!visible) {
            if (mode_skip(s, t)) return true;
            continue;
        }
        if (mode_sample(s, scene_value(u, t), u, t)) return true;
    }
    return false;
}
#endif
#endif
#ifdef SUPPORT_MAP
// The samples [x, y) of the ray that may lie in a support brick: between its first and
// last crossing of the support's surface, within the box around the bricks (one more
// sample on either side against rounding); the others are straight.
ivec2 support_phases(float t0, float j, int n) {
    vec2 ts = intersect_box(g_ro, g_rd, u_support_lo, u_support_hi);
    vec4 range = texelFetch(u_support_ranges, ivec2(gl_FragCoord.xy - u_viewport.xy), 0);
    ts = vec2(max(ts.x, range.r), min(ts.y, range.a));
    if (ts.y < ts.x) return ivec2(n);
    int a = int(floor((ts.x - t0) / u_step - j));
    int b = int(ceil((ts.y - t0) / u_step - j)) + 1;
    return clamp(ivec2(a, b), 0, n);
}
#endif

void main() {
    vec2 frag = gl_FragCoord.xy - u_viewport.xy;
    vec2 ndc = frag / u_viewport.zw * 2.0 - 1.0;
    vec4 a = u_inv_view_proj * vec4(ndc, -1.0, 1.0);
    vec4 b = u_inv_view_proj * vec4(ndc, 1.0, 1.0);
    g_ro = a.xyz / a.w;
    vec3 far_point = b.xyz / b.w;
    float t_far = length(far_point - g_ro);
    g_rd = (far_point - g_ro) / t_far;

    vec2 tb = intersect_box(g_ro, g_rd, u_bounds_lo, u_bounds_hi);
    // The sample lattice is anchored at the entry into the deformed-space box, so both
    // paths (and skipping on or off) sample at exactly the same positions.
    float t_lattice = max(tb.x, 0.0);
    float t0 = t_lattice;
    float t1 = min(tb.y, t_far);
#ifdef LINEAR_PATH
    g_u0 = (u_world_to_texel * vec4(g_ro, 1.0)).xyz;
    g_du = mat3(u_world_to_texel) * g_rd;
#elif defined(CELL_SKIP)
    g_u0 = (u_skip_world_to_texel * vec4(g_ro, 1.0)).xyz;
    g_du = mat3(u_skip_world_to_texel) * g_rd;
#endif
#ifdef CELL_SKIP
    // This pass draws the rays of octant u_octant only (each pixel exactly once). A
    // component counts as negative only below -OCTANT_EPS * max|du|, so directions
    // along an axis (components ~0 of either sign) agree with app/render/skipping/maps.py.
    float du_max = max(max(abs(g_du.x), abs(g_du.y)), abs(g_du.z));
    vec3 ray_octant = mix(vec3(1.0), vec3(-1.0), lessThan(g_du, vec3(-OCTANT_EPS * du_max)));
    if (any(notEqual(ray_octant, u_octant))) discard;
#endif
#ifdef SUPPORT_MAP
    g_s0 = (u_straight_to_texel * vec4(g_ro, 1.0)).xyz;
    g_sd = mat3(u_straight_to_texel) * g_rd;
    g_sd = mix(g_sd, sign(g_sd) * 1e-12 + vec3(1e-30), lessThan(abs(g_sd), vec3(1e-12)));
#endif
#if defined(LINEAR_PATH) || defined(CELL_SKIP)
    // keep direction components away from 0 so 1/du stays finite
    g_du = mix(g_du, sign(g_du) * 1e-12 + vec3(1e-30), lessThan(abs(g_du), vec3(1e-12)));
#endif
#ifdef LINEAR_PATH
    vec2 tt = intersect_box(g_u0, g_du, vec3(0.0), u_dims);
    t0 = max(t0, tt.x);
    t1 = min(t1, tt.y);
#endif
#ifdef MESH_DEPTH
    ivec2 mesh_texel = ivec2(gl_FragCoord.xy - u_viewport.xy);
    g_under = texelFetch(u_mesh_color, mesh_texel, 0);
    float mesh_depth = texelFetch(u_mesh_depth, mesh_texel, 0).r;
    if (mesh_depth < 1.0) {
        vec4 hit = u_mesh_inv_view_proj * vec4(ndc, mesh_depth * 2.0 - 1.0, 1.0);
        t1 = min(t1, dot(hit.xyz / hit.w - g_ro, g_rd));
    }
#endif
    if (t1 <= t0) {
#ifdef MESH_DEPTH
        f_color = g_under;
        return;
#endif
        // The renderer clears the viewport to the background before drawing. On a CPU
        // rasteriser discard is the one real early exit: SIMD groups whose lanes all
        // miss skip the rest of the shader (loops run at least once otherwise).
        discard;
    }
    float j = u_jitter != 0 ? hash01(uvec2(gl_FragCoord.xy), u_seed) : 0.5;
    int n = clamp(int(ceil((t1 - t_lattice) / u_step - j)), 0, u_max_steps);
    int k = clamp(int(ceil((t0 - t_lattice) / u_step - j)), 0, n);
    t0 = t_lattice;

    State s;
    mode_init(s);
#if defined(LINEAR_PATH) || defined(CELL_SKIP)
    // One flat loop (no nested per-block loop): SIMD lanes of a CPU rasteriser stay in
    // step whether they sample or skip. The block's visibility is looked up only when
    // a sample enters a new block; an invisible block is jumped to its exit, on the
    // sample lattice.
    vec3 inv_du = 1.0 / g_du;
    vec3 face = step(vec3(0.0), g_du);   // 1 where the ray leaves a block through its upper face
    g_inside = k < n;
    float t_last = t0 + (float(n) - 1.0 + j) * u_step;   // last sample on the lattice
#endif
#ifdef CELL_SKIP
    // Empty-space skipping at cell resolution: one nearest fetch per sample. An
    // invisible cell with edge d lets the ray leave the cube of d³ invisible cells
    // starting at the cell (towards u_octant) in one jump, to the next lattice sample.
    vec3 exit_offset = face - 0.5;
    vec3 exit_widen = face * max(u_octant, 0.0) - (1.0 - face) * max(-u_octant, 0.0);
    // Leading empty space first, in a loop that only jumps (no volume or transfer
    // function fetch: on a CPU rasteriser every iteration of the main loop pays for
    // both branches), up to the first sample in a visible cell.
    bool finished = false;
    while (k < n) {
        ivec3 c;
        float d = cell_skip(skip_at(t0 + (float(k) + j) * u_step), c);
        if (d < 0.5) break;
        k = after_cube(c, d, exit_offset, exit_widen, inv_du, t0, j, k, n);
        // the last skipped sample lies in the invisible cube: where bisection may start
        if (mode_skip(s, t0 + (float(k - 1) + j) * u_step)) {
            finished = true;
            break;
        }
    }
    // A ray that met nothing visible leaves the background (cleared) untouched.
#ifdef MESH_DEPTH
    if (k >= n && !finished) {
        f_color = g_under;
        return;
    }
#endif
    if (k >= n && !finished) discard;
#ifdef PIECEWISE
    // One chain evaluation per outer iteration, for every lane of a SIMD group at once
    // (a CPU rasteriser runs both sides of a branch: evaluating only where a lane
    // needs a new segment would cost every lane every time); the inner loop walks the
    // segment's samples with the same skipping as below. A jump past the segment
    // starts the next one at the landing sample.
    int kb = -2;   // lattice index of the last evaluated point (g_ub)
    while (k < n && !finished) {
        bool joined = k == kb + 1;
        int ke = joined ? min(kb + segment_samples(g_tb), n - 1) : k;
        segment_to(t0 + (float(ke) + j) * u_step, joined);
        kb = ke;
        while (k <= ke) {
            float t = t0 + (float(k) + j) * u_step;
            ivec3 c;
            float d = cell_skip(skip_at(t), c);
            if (d > 0.5) {
                k = after_cube(c, d, exit_offset, exit_widen, inv_du, t0, j, k, n);
                if (mode_skip(s, t0 + (float(k - 1) + j) * u_step)) {
                    finished = true;
                    break;
                }
                if (k > ke) break;
                t = t0 + (float(k) + j) * u_step;
            }
            vec3 u = segment_texel(t);
            if (!inside_texels(u)) {
                if (mode_skip(s, -1.0)) {
                    finished = true;
                    break;
                }
                ++k;
                continue;
            }
            if (mode_sample(s, scene_value(u, t), u, t)) {
                finished = true;
                break;
            }
            ++k;
        }
    }
#elif defined(SUPPORT_MAP)
    // straight before the support's box, through the chain in it, straight after it
    ivec2 kio = support_phases(t0, j, n);
    finished = march_cells(s, k, kio.x, n, t0, j, inv_du, exit_offset, exit_widen, true)
        || march_cells(s, k, kio.y, n, t0, j, inv_du, exit_offset, exit_widen, false)
        || march_cells(s, k, n, n, t0, j, inv_du, exit_offset, exit_widen, true);
#elif defined(LINEAR_PATH)
    // Straight rays: one skip-map check per SAMPLES_PER_CHECK lattice samples. The
    // unchecked samples keep the lattice; one that lies in an invisible cell adds
    // exactly nothing (zero opacity, below the isovalue/threshold), so the image stays
    // the same bit for bit; early termination is still tested after every sample.
    while (k < n) {
        ivec3 c;
        float d = cell_skip(skip_at(t0 + (float(k) + j) * u_step), c);
        if (d > 0.5) {
            k = after_cube(c, d, exit_offset, exit_widen, inv_du, t0, j, k, n);
            if (mode_skip(s, t0 + (float(k - 1) + j) * u_step)) break;
            if (k >= n) break;
            // Sample the landing position in the same iteration (a CPU rasteriser
            // runs both sides of a branch anyway): if its cell is invisible too, the
            // sample cannot contribute.
        }
        if (straight_sample(s, k, t0, j)) break;
        ++k;
#if SAMPLES_PER_CHECK > 1
        if (k >= n || straight_sample(s, k, t0, j)) break;
        ++k;
#endif
#if SAMPLES_PER_CHECK > 2
        if (k >= n || straight_sample(s, k, t0, j)) break;
        ++k;
#endif
#if SAMPLES_PER_CHECK > 3
        if (k >= n || straight_sample(s, k, t0, j)) break;
        ++k;
#endif
    }
#else
    // warped rays with cell skipping through deformed space
    while (k < n) {
        float t = t0 + (float(k) + j) * u_step;
        ivec3 c;
        float d = cell_skip(skip_at(t), c);
        if (d > 0.5) {
            k = after_cube(c, d, exit_offset, exit_widen, inv_du, t0, j, k, n);
            if (mode_skip(s, t0 + (float(k - 1) + j) * u_step)) break;
            if (k >= n) break;
            t = t0 + (float(k) + j) * u_step;   // the landing sample, as above
        }
        vec3 u = texel_at(t);
        // a warped sample may land outside the volume: it shows nothing
        if (!inside_texels(u)) {
            if (mode_skip(s, -1.0)) break;
            ++k;
            continue;
        }
        if (mode_sample(s, scene_value(u, t), u, t)) break;
        ++k;
#if CHAINED_PER_CHECK > 1
        if (k < n) {
            if (unchecked_sample(s, k, t0, j, false)) break;
            ++k;
        }
#endif
    }
#endif
#elif defined(LINEAR_PATH)
    ivec3 cur = ivec3(-1000000);
    while (k < n) {
        float t = t0 + (float(k) + j) * u_step;
        vec3 u = texel_at(t);
        ivec3 blk = ivec3(floor(u * (1.0 / float(BLOCK))));
        if (blk != cur) {
            cur = blk;
            vec4 info = block_in_grid(blk) ? block_info(blk) : vec4(1.0, 0.0, 0.0, 0.0);
            float d = info.x;
            bool visible = d < 0.5 && block_visible(info.yz, s);
#ifdef NO_SKIPPING
            visible = true;   // reference runs: measure what skipping buys
#endif
            if (!visible) {
                // leave the cube of blocks within distance d - 1: all invisible
                // (dynamic skips of mip/minip have d = 0: only this block is clear)
                float r = max(d, 1.0) - 1.0;
                float t_exit = cube_exit(vec3(blk), r, float(BLOCK), 0.0, face, inv_du);
                if (mode_skip(s, min(t_exit, t_last))) break;
                k = lattice_after(t_exit, t0, j, k, n);
                continue;
            }
        }
        if (mode_sample(s, scene_value(u, t), u, t)) break;
        ++k;
    }
#elif defined(SUPPORT_MAP)
    ivec2 kio = support_phases(t0, j, n);
    bool finished = march_blocks(s, k, kio.x, t0, j, true)
        || march_blocks(s, k, kio.y, t0, j, false) || march_blocks(s, k, n, t0, j, true);
#else
    march_blocks(s, k, n, t0, j, false);   // warped rays, block checks per sample
#endif
    vec4 c = mode_finish(s);
#ifdef MESH_DEPTH
    f_color = c + (1.0 - c.a) * g_under;
#else
    f_color = c + (1.0 - c.a) * u_background;
#endif
}
