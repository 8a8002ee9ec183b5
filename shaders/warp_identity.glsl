// Identity warp: the deformed space is the original space. An oracle for tests.
vec3 warp(vec3 p) { return p; }
mat3 warp_jacobian(vec3 p) { return mat3(1.0); }
