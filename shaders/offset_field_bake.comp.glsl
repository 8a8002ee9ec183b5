#version 430
// Bakes the inverse of an offset field (deform/elements/offset_field.py,
// OffsetFieldWarp.baked_inverse is the CPU reference) on a node grid over the same box,
// bake_factor times finer than the field: for each baked node X, solve q + u(q) = X by
// u_iterations fixed-point steps q <- X - u(q) from q = X (fewer where q stops changing),
// and store v = X - q (mm) in the RGBA16F 3D image u_inverse. The warp then starts its
// own iteration at p - v(p), v trilinear: one or two steps reach the accuracy that many
// steps from q = p need.
// Positions are in field grid units (one field node spacing per unit along each axis),
// so the box corner and spacing drop out.
layout(local_size_x = 4, local_size_y = 4, local_size_z = 4) in;

uniform sampler2DArray u_field;   // RGBA16F, layer = z-slice, xyz = u (mm), linear filtering
uniform ivec3 u_field_shape;   // field nodes per axis
uniform ivec3 u_shape;         // baked nodes per axis
uniform vec3 u_size;           // grid box size (mm)
uniform int u_iterations;
layout(rgba16f, binding = 0) writeonly uniform image3D u_inverse;

void main() {
    ivec3 node = ivec3(gl_GlobalInvocationID);
    if (any(greaterThanEqual(node, u_shape))) return;
    vec3 field_shape = vec3(u_field_shape);
    vec3 to_grid = (field_shape - 1.0) / u_size;   // mm -> field node spacings
    // baked node position in field grid units
    vec3 x = vec3(node) * (field_shape - 1.0) / max(vec3(u_shape) - 1.0, vec3(1.0));
    vec3 q = x;
    for (int i = 0; i < u_iterations; ++i) {
        vec3 s = q / (field_shape - 1.0);   // [0, 1] inside the grid box
        vec3 in3 = step(vec3(0.0), s) * step(s, vec3(1.0));
        // trilinear u(q) from the z-slice layers, as the warp samples it
        vec3 g = clamp(q, vec3(0.0), field_shape - 1.0);
        vec2 tc = (g.xy + 0.5) / field_shape.xy;
        float layer = min(floor(g.z), field_shape.z - 2.0);
        vec3 ua = textureLod(u_field, vec3(tc, layer), 0.0).xyz;
        vec3 ub = textureLod(u_field, vec3(tc, layer + 1.0), 0.0).xyz;
        vec3 u = mix(ua, ub, g.z - layer) * (in3.x * in3.y * in3.z);
        vec3 next = x - u * to_grid;
        // a fixed point in float arithmetic: every later step would give this q again,
        // so stopping here is bit-identical to all u_iterations steps (nodes the field
        // does not move stop after two; a SIMD group loops while one of its nodes does)
        if (next == q) break;
        q = next;
    }
    imageStore(u_inverse, node, vec4((x - q) / to_grid, 0.0));
}
