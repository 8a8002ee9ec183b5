// ChainMail's link constraints on the z-slice atlas, shared by the constraint pass
// (chainmail_pass.frag.glsl) and the relaxation (chainmail_relax.frag.glsl). The
// including shader declares u_pos (positions) and u_link[5] (the packed link limits of
// chainmail_pass.frag.glsl).

// The texels of element e's neighbours (+x, -x, +y, -y, +z, -z), clamped into the grid
// (the links past a face are absent); x and y neighbours are the next texels of the tile.
void cm_neighbours(ivec2 t, ivec3 e, out ivec2 n[6]) {
    n[0] = t + ivec2(int(e.x < NX - 1), 0);
    n[1] = t - ivec2(int(e.x > 0), 0);
    n[2] = t + ivec2(0, int(e.y < NY - 1));
    n[3] = t - ivec2(0, int(e.y > 0));
    n[4] = ms_texel(ivec3(e.xy, min(e.z + 1, NZ - 1)));
    n[5] = ms_texel(ivec3(e.xy, max(e.z - 1, 0)));
}

// The interval [lo, hi] per coordinate that the element's links (limits l[0..4] of
// texel t) allow with its neighbours at xn (the order of cm_neighbours). Forward link
// along i to n = e + e_i: n_i - x_i in [min, max], |n_j - x_j| <= shear; backward link
// along i from n = e - e_i: x_i - n_i in [min, max], |x_j - n_j| <= shear.
void cm_interval(vec4 l[5], vec3 xn[6], out vec3 lo, out vec3 hi) {
    lo = max(xn[0] - vec3(l[0].y, l[0].z, l[0].z), xn[1] + vec3(l[0].w, -l[1].y, -l[1].y));
    hi = min(xn[0] + vec3(-l[0].x, l[0].z, l[0].z), xn[1] + vec3(l[1].x, l[1].y, l[1].y));
    lo = max(lo, max(xn[2] - vec3(l[2].x, l[1].w, l[2].x), xn[3] + vec3(-l[2].w, l[2].y, -l[2].w)));
    hi = min(hi, min(xn[2] + vec3(l[2].x, -l[1].z, l[2].x), xn[3] + vec3(l[2].w, l[2].z, l[2].w)));
    lo = max(lo, max(xn[4] - vec3(l[3].z, l[3].z, l[3].y), xn[5] + vec3(-l[4].y, -l[4].y, l[3].w)));
    hi = min(hi, min(xn[4] + vec3(l[3].z, l[3].z, -l[3].x), xn[5] + vec3(l[4].y, l[4].y, l[4].x)));
}

// The link limits of texel t and the positions of its neighbours n.
void cm_load(ivec2 t, ivec2 n[6], out vec4 l[5], out vec3 xn[6]) {
    for (int k = 0; k < 5; ++k) l[k] = imageLoad(u_link[k], t);
    for (int k = 0; k < 6; ++k) xn[k] = imageLoad(u_pos, n[k]).xyz;
}
