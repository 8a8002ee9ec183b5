// Fixed/moving comparison (app/core/comparison.py). scene_value(u, t) is what the
// compositing modes classify at ray parameter t, u being the moving volume's texel
// position there (the warped sample). With COMPARE, the fixed volume (its own 3D
// texture and world -> texture map, no warps) is sampled at the same *deformed* world
// point p = g_ro + t * g_rd and combined with the moving value:
//   checkerboard: cubes of u_checker_mm (anchored at world 0) pick moving (even sum of
//                 floor(p / size)) or fixed (odd);
//   difference:   |moving - fixed|;
//   blend:        (1 - u_blend) * moving + u_blend * fixed.
// Shading uses the same combination of the two gradients (the fixed one from its
// gradient texture with FIXED_GRADIENT_TEXTURE, else by central differences of
// u_fixed_step mm in world space).
#ifdef COMPARE
uniform sampler3D u_fixed;
uniform mat4 u_fixed_world_to_tex;   // world mm -> fixed texture coordinates in [0, 1]
uniform vec2 u_fixed_value_map;      // data value = texel * x + y
uniform float u_fixed_outside;       // the value outside the fixed image's box
uniform float u_fixed_step;          // central-difference step (mm)
uniform int u_compare;               // 0 checkerboard, 1 difference, 2 blend
uniform float u_blend;
uniform float u_checker_mm;
vec2 g_cmp_w = vec2(1.0, 0.0);       // weights (moving, fixed) of the last sample
float g_cmp_sign = 1.0;              // sign folded into the difference's abs

// The fixed value at p, clamped to the edge texels (as the moving volume's gradient).
float fixed_clamped(vec3 p) {
    vec3 c = (u_fixed_world_to_tex * vec4(p, 1.0)).xyz;
    return textureLod(u_fixed, c, 0.0).r * u_fixed_value_map.x + u_fixed_value_map.y;
}

float fixed_value(vec3 p) {
    vec3 c = (u_fixed_world_to_tex * vec4(p, 1.0)).xyz;
    if (any(lessThan(c, vec3(0.0))) || any(greaterThan(c, vec3(1.0)))) return u_fixed_outside;
    return fixed_clamped(p);
}

float scene_value(vec3 u, float t) {
    vec3 p = g_ro + t * g_rd;
    if (u_compare == 0) {
        ivec3 cell = ivec3(floor(p / u_checker_mm));
        bool odd = ((cell.x + cell.y + cell.z) & 1) != 0;
        g_cmp_w = odd ? vec2(0.0, 1.0) : vec2(1.0, 0.0);
    } else if (u_compare == 1) {
        g_cmp_w = vec2(1.0, -1.0);
    } else {
        g_cmp_w = vec2(1.0 - u_blend, u_blend);
    }
    float m = g_cmp_w.x != 0.0 ? sample_value(u) : 0.0;
    float f = g_cmp_w.y != 0.0 ? fixed_value(p) : 0.0;
    float v = g_cmp_w.x * m + g_cmp_w.y * f;
    g_cmp_sign = (u_compare == 1 && v < 0.0) ? -1.0 : 1.0;
    return g_cmp_sign * v;
}

#ifdef FIXED_GRADIENT_TEXTURE
// precomputed: half the central differences per voxel (app/render/gradients.py)
uniform sampler3D u_fixed_gradient;
uniform mat3 u_fixed_direction;
uniform vec3 u_fixed_spacing;
vec3 gradient_fixed(vec3 p) {
    vec3 c = (u_fixed_world_to_tex * vec4(p, 1.0)).xyz;
    return u_fixed_direction * (textureLod(u_fixed_gradient, c, 0.0).xyz / u_fixed_spacing);
}
#else
vec3 gradient_fixed(vec3 p) {
    float h = u_fixed_step;
    vec3 g;
    g.x = fixed_clamped(p + vec3(h, 0, 0)) - fixed_clamped(p - vec3(h, 0, 0));
    g.y = fixed_clamped(p + vec3(0, h, 0)) - fixed_clamped(p - vec3(0, h, 0));
    g.z = fixed_clamped(p + vec3(0, 0, h)) - fixed_clamped(p - vec3(0, 0, h));
    return g / (2.0 * h);
}
#endif

// The compared gradient from the moving one (deformed world units) at ray parameter t.
vec3 compare_gradient(vec3 g_moving, float t) {
    vec3 gf = g_cmp_w.y != 0.0 ? gradient_fixed(g_ro + t * g_rd) : vec3(0.0);
    return g_cmp_sign * (g_cmp_w.x * g_moving + g_cmp_w.y * gf);
}
#else
float scene_value(vec3 u, float t) { return sample_value(u); }
vec3 compare_gradient(vec3 g_moving, float t) { return g_moving; }
#endif
