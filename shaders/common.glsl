// Shared helpers: ray/box intersection and a deterministic per-pixel hash.

// Entry and exit ray parameters of the box [lo, hi]; exit < entry when missed.
vec2 intersect_box(vec3 ro, vec3 rd, vec3 lo, vec3 hi) {
    vec3 inv = 1.0 / rd;
    vec3 ta = (lo - ro) * inv;
    vec3 tb = (hi - ro) * inv;
    vec3 tmin = min(ta, tb);
    vec3 tmax = max(ta, tb);
    return vec2(max(max(tmin.x, tmin.y), tmin.z), min(min(tmax.x, tmax.y), tmax.z));
}

// pcg3d hash (Jarzynski & Olano 2020): well distributed, deterministic.
uvec3 pcg3d(uvec3 v) {
    v = v * 1664525u + 1013904223u;
    v.x += v.y * v.z; v.y += v.z * v.x; v.z += v.x * v.y;
    v ^= v >> 16u;
    v.x += v.y * v.z; v.y += v.z * v.x; v.z += v.x * v.y;
    return v;
}

// Uniform float in [0, 1) from pixel coordinates and a seed.
float hash01(uvec2 pixel, uint seed) {
    return float(pcg3d(uvec3(pixel, seed)).x >> 8u) * (1.0 / 16777216.0);
}
