// Affine warp: WARP_matrix maps deformed world (mm) to original world (mm).
uniform mat4 WARP_matrix;
vec3 warp(vec3 p) { return (WARP_matrix * vec4(p, 1.0)).xyz; }
mat3 warp_jacobian(vec3 p) { return mat3(WARP_matrix); }
