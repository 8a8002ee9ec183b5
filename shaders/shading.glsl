// Blinn-Phong shading with a headlight; normals from data gradients carried into
// deformed space by the warp Jacobian (grad_p = J^T grad_q). `color` may be
// premultiplied by `alpha`; the specular term is scaled by alpha accordingly.
uniform vec4 u_light;   // ambient, diffuse, specular, shininess

vec3 shade(vec3 color, float alpha, vec3 grad_deformed, vec3 view_dir) {
    float len = length(grad_deformed);
    if (len < 1e-8) return color * (u_light.x + u_light.y);
    vec3 n = grad_deformed / len;
    vec3 l = -view_dir;                     // headlight
    float ndl = abs(dot(n, l));             // two-sided
    vec3 h = normalize(l - view_dir);
    float spec = pow(abs(dot(n, h)), u_light.w);
    return color * (u_light.x + u_light.y * ndl) + vec3(u_light.z * spec * alpha);
}
