#version 430
// voxwarp slice views (multi-planar reformatting through the warp chain). About this
// technique: one fragment per pixel of a plane in *deformed* (display) world space.
// The pixel's world point p = u_pixel_to_world * (col, row, 0, 1) (row 0 at the image
// top) is mapped by the same warp chain as the raycaster's samples to the original
// volume, which is sampled there: the volume is never resampled, so a slice costs one
// chain evaluation and one texture fetch per pixel (per slab sample).
// Thick slabs: u_slab_samples samples spread evenly over [-slab/2, slab/2] along the
// plane's normal (u_slab_step apart), combined as MIP (max), MinIP (min) or the average
// of the samples that land inside the volume.
// NEAREST: the texel holding the point, read at its centre (exact with either texture
// layout); otherwise trilinear, as the raycaster samples.
// Output (RGBA32F): r = deformed value, g = fraction of the slab's samples inside the
// volume (0: nothing here), b = the rest-state (undeformed) value at p, a = its fraction.
// SUPPORT_MAP: the chain's support, a brick map (app/render/skipping/support.py); a
// pixel outside it samples p itself (the chain moves it by less than the tolerance),
// one inside or beyond the map's box pays for the chain.
// DETJ (the det J overlay, app/render/jacobian_overlay.py): also f_detj (location 1,
// R32F) = det of the chain's Jacobian at the plane's own point p0 (no slab); a thin
// slice then samples the point that same chain evaluation gave.

#include "volume_sample.glsl"
#include "warps.glsl"

uniform mat4 u_pixel_to_world;  // (col, row, 0, 1) -> deformed world point (mm)
uniform vec4 u_viewport;        // x, y, width, height in framebuffer pixels
uniform vec3 u_slab_step;       // world vector between slab samples (mm)
uniform int u_slab_samples;     // 1: a thin slice
uniform int u_slab_mode;        // 0 MIP, 1 MinIP, 2 average

#ifdef SUPPORT_MAP
uniform sampler3D u_support;          // R8 per brick: 1 = some warp moves points here
uniform mat4 u_world_to_support;      // deformed world -> brick coordinates
uniform ivec3 u_support_dims;         // bricks per axis
bool in_support(vec3 p) {
    ivec3 c = ivec3(floor((u_world_to_support * vec4(p, 1.0)).xyz));
    if (any(lessThan(c, ivec3(0))) || any(greaterThanEqual(c, u_support_dims))) return true;
    return texelFetch(u_support, c, 0).r > 0.5;
}
vec3 chain_where_moved(vec3 p) { return in_support(p) ? warp_chain(p) : p; }
#else
vec3 chain_where_moved(vec3 p) { return warp_chain(p); }
#endif

layout(location = 0) out vec4 f_value;
#ifdef DETJ
layout(location = 1) out float f_detj;
#endif

float fetch(vec3 q, out bool inside) {
    vec3 u = world_to_texel(q);
    inside = inside_texels(u);
#ifdef NEAREST
    u = floor(clamp(u, vec3(0.0), u_dims - 0.5)) + 0.5;
#endif
    return sample_value(u);
}

// Slab reduction of one sample into (accumulator, count).
void combine(inout vec2 acc, float v) {
    if (acc.y == 0.0) {
        acc = vec2(v, 1.0);
        return;
    }
    if (u_slab_mode == 0) acc.x = max(acc.x, v);
    else if (u_slab_mode == 1) acc.x = min(acc.x, v);
    else acc.x += v;
    acc.y += 1.0;
}

void main() {
    vec2 pixel = gl_FragCoord.xy - u_viewport.xy - 0.5;     // (col, row from the bottom)
    vec2 cr = vec2(pixel.x, u_viewport.w - 1.0 - pixel.y);   // row 0 at the image top
    vec3 p0 = (u_pixel_to_world * vec4(cr, 0.0, 1.0)).xyz;
#ifdef DETJ
    mat3 J;
    vec3 q0 = warp_chain_and_jacobian(p0, J);
    f_detj = determinant(J);
    if (u_slab_samples == 1) {   // a thin slice: the one sample is q0
        bool in_d;
        bool in_r;
        float vd = fetch(q0, in_d);
        float vr = fetch(p0, in_r);
        f_value = vec4(in_d ? vd : 0.0, in_d ? 1.0 : 0.0, in_r ? vr : 0.0, in_r ? 1.0 : 0.0);
        return;
    }
#endif
    vec3 first = p0 - 0.5 * float(u_slab_samples - 1) * u_slab_step;
    vec2 deformed = vec2(0.0);
    vec2 rest = vec2(0.0);
    for (int k = 0; k < u_slab_samples; ++k) {
        vec3 p = first + float(k) * u_slab_step;
        bool inside;
        float v = fetch(chain_where_moved(p), inside);
        if (inside) combine(deformed, v);
        v = fetch(p, inside);
        if (inside) combine(rest, v);
    }
    float n = float(u_slab_samples);
    if (u_slab_mode == 2) {
        deformed.x /= max(deformed.y, 1.0);
        rest.x /= max(rest.y, 1.0);
    }
    f_value = vec4(deformed.x, deformed.y / n, rest.x, rest.y / n);
}
