// det J overlay: the volume coloured by the Jacobian determinant of the warp chain at
// each sample (deformed point p = g_ro + t g_rd). The colour map on log2(det J) is the
// CPU one of app/render/jacobian_overlay.py: u_detj_expansion below 1,
// u_detj_compression above 1, opacity u_detj_opacity * |log2 det J| / u_detj_range
// (at most u_detj_opacity), folds (det J <= 0) solid u_detj_fold.
uniform float u_detj_opacity;
uniform float u_detj_range;
uniform vec3 u_detj_expansion;
uniform vec3 u_detj_compression;
uniform vec3 u_detj_fold;

float detj_at(float t) {
#ifdef LINEAR_PATH
    return determinant(u_jacobian);
#else
    return determinant(warp_chain_jacobian(g_ro + t * g_rd));
#endif
}

// rgb: the colour the mode computed (premultiplied by alpha), a: its alpha.
vec3 detj_tint(vec3 rgb, float a, float t) {
    float det = detj_at(t);
    if (!(det > 0.0)) return u_detj_fold * a;
    float level = clamp(log2(det) / u_detj_range, -1.0, 1.0);
    vec3 hue = level < 0.0 ? u_detj_expansion : u_detj_compression;
    return mix(rgb, hue * a, u_detj_opacity * abs(level));
}
