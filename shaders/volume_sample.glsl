// The volume texture and its sampling in texel coordinates u (voxel i spans [i, i+1],
// its centre is at i + 0.5), returning values in data units.
#if defined(SLICE_PAIRS) || defined(SLICE_LAYERS)
// SLICE_PAIRS: layer k of a 2D array texture holds the slice pair (v[., ., k],
// v[., ., k+1]) in two channels: one hardware-bilinear fetch plus one lerp across z gives
// the trilinear value with half the texel reads of a 3D texture (software rasterisers
// pay per texel), at twice the memory. SLICE_LAYERS: layer k holds slice k only (each
// voxel once): two bilinear fetches (layers k and k + 1) and the same lerp.
uniform sampler2DArray u_volume;
#else
uniform sampler3D u_volume;
#endif
uniform vec3 u_dims;          // voxels per axis (nx, ny, nz)
uniform vec3 u_inv_dims;      // 1 / u_dims
uniform vec2 u_value_map;     // data value = texel * x + y (undoes normalised formats)
uniform vec3 u_spacing;       // voxel size in mm
uniform vec3 u_origin;        // world position of voxel (0, 0, 0)'s centre, mm
uniform mat3 u_direction;     // world directions of the texel axes (identity unless oblique)

float sample_value(vec3 u) {
#ifdef SLICE_PAIRS
    float cz = clamp(u.z - 0.5, 0.0, u_dims.z - 1.0);   // clamp to edge along z
    float layer = floor(cz);
    vec2 pair = textureLod(u_volume, vec3(u.xy * u_inv_dims.xy, layer), 0.0).rg;
    return mix(pair.x, pair.y, cz - layer) * u_value_map.x + u_value_map.y;
#elif defined(SLICE_LAYERS)
    float cz = clamp(u.z - 0.5, 0.0, u_dims.z - 1.0);   // clamp to edge along z
    float layer = floor(cz);
    vec2 xy = u.xy * u_inv_dims.xy;
    float v0 = textureLod(u_volume, vec3(xy, layer), 0.0).r;
    float v1 = textureLod(u_volume, vec3(xy, min(layer + 1.0, u_dims.z - 1.0)), 0.0).r;
    return mix(v0, v1, cz - layer) * u_value_map.x + u_value_map.y;
#else
    return textureLod(u_volume, u * u_inv_dims, 0.0).r * u_value_map.x + u_value_map.y;
#endif
}

// Original-world point (mm) -> texel coordinates.
// Oblique scans map through their rotation here: the volume is never resampled.
// (With the identity this is exactly (q - origin) / spacing + 0.5, as the folded
// straight-ray map computes it.)
vec3 world_to_texel(vec3 q) {
    return (transpose(u_direction) * (q - u_origin)) / u_spacing + 0.5;
}

bool inside_texels(vec3 u) {
    return all(greaterThanEqual(u, vec3(0.0))) && all(lessThanEqual(u, u_dims));
}

// Gradient of the data in original world units (per mm), central differences.
#ifdef GRADIENT_TEXTURE
// precomputed: half the central differences per voxel (app/render/gradients.py)
uniform sampler3D u_gradient;
vec3 gradient_original(vec3 u) {
    return u_direction * (textureLod(u_gradient, u * u_inv_dims, 0.0).xyz / u_spacing);
}
#else
vec3 gradient_original(vec3 u) {
    vec3 g;
    g.x = sample_value(u + vec3(1, 0, 0)) - sample_value(u - vec3(1, 0, 0));
    g.y = sample_value(u + vec3(0, 1, 0)) - sample_value(u - vec3(0, 1, 0));
    g.z = sample_value(u + vec3(0, 0, 1)) - sample_value(u - vec3(0, 0, 1));
    return u_direction * (0.5 * g / u_spacing);
}
#endif
