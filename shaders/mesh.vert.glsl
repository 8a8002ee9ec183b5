#version 430
// Mesh vertices placed in the world by a 4x4 matrix (LINEAR) or by a lattice of
// trilinear cells (Knuth, Kohlhammer, Kuijper, GRAPP 2010, sections 3-5). About this
// technique:
// * The lattice is a grid of (nx+1)(ny+1)(nz+1) node points in an RGBA32F 3D texture
//   (voxwarp.deform.lattice.trilinear.TrilinearGrid.texture_data). It acts on the box-normalised vertex
//   coordinate u = (p - lo) / (hi - lo); the cell holding u is a trilinear map of its 8
//   corner nodes. Each vertex costs O(1) fetches, however deep the scene graph that
//   composed the lattice (voxwarp.core.mesh.instances_from_scene_graph).
// * The position is evaluated from the 8 corner nodes (texelFetch; the same fetches give
//   the Jacobian), exactly in float arithmetic. With HW_TRILINEAR it is one hardware
//   trilinear fetch at the node-centred coordinate (u * cells + 0.5) / (cells + 1),
//   which is the same map on paper, but GPUs filter with 8-bit fixed-point weights
//   (1/256 of a cell), so it is an option, not the default. Vertices outside the box
//   continue the border cell's trilinear map (as TrilinearGrid.__call__ does).
// * Normals (section 4.2), per instance. The paper names two methods and numbers them
//   oppositely in Figure 5's caption (method 1: direct) and in the text of 4.2 (first:
//   tangent space), so they go by what they do. u_normal_method 0 ("normal", the direct
//   transform): J n, the normal carried as a vector. Where a surface crosses a shared
//   cell face its normal lies nearly in the face, whose Jacobian columns agree on both
//   sides, so J n is continuous there: smooth shading, though J n need not be orthogonal
//   to the deformed surface. 1 ("tangent"): two tangents t1, t2 (t1 x t2 = n) through J,
//   crossed, = cof(J) n = det(J) J^-T n: orthogonal to the deformed surface, but the
//   derivative across a cell face of a C0 lattice jumps, so seams show. Where J n nearly
//   vanishes (a flattened lattice) method 0 falls back to method 1. CPU reference:
//   voxwarp.deform.lattice.trilinear.carry_normals.
// * LINEAR draws matrix instances and lattices whose grid is one affine map (the paper's
//   parallelepiped check, section 4.1) with J = the matrix's linear part: a lattice keeps
//   its method (the same normals as the trilinear path). A matrix instance has no cell
//   faces to smooth, so its "normal" is the exact inverse transpose (u_normal_method 2,
//   u_normal_matrix; the cofactor matrix where it is singular) and its "tangent" is
//   cof(J) n as above.
//   Normals are normalised per vertex before interpolation; the fragment shader lights
//   both sides.

in vec3 in_position;    // local coordinates
in vec3 in_normal;      // local unit normal

uniform mat4 u_view_proj;       // world -> clip
uniform int u_normal_method;    // 0: J n; 1: cross(J t1, J t2); 2 (LINEAR): u_normal_matrix n

out vec3 v_world;
out vec3 v_normal;

#ifdef LINEAR
uniform mat4 u_model;           // local -> world (affine)
uniform mat3 u_normal_matrix;   // matrix instances: inverse transpose of the linear part

vec3 place(vec3 p, out mat3 J) {
    J = mat3(u_model);
    return (u_model * vec4(p, 1.0)).xyz;
}
#else
uniform sampler3D u_nodes;      // node world points (xyz), linear filtering
uniform vec3 u_cells;           // cells per axis
uniform vec3 u_box_lo;          // box the lattice acts on (local coordinates)
uniform vec3 u_box_inv_size;    // 1 / (hi - lo)

// Trilinear map of the cell holding u and its Jacobian d world / d local.
vec3 place(vec3 p, out mat3 J) {
    vec3 u = (p - u_box_lo) * u_box_inv_size;
    vec3 g = u * u_cells;
    ivec3 c = ivec3(clamp(floor(g), vec3(0.0), u_cells - 1.0));
    vec3 f = g - vec3(c);       // cell-local coordinate (outside [0, 1]: extrapolation)
    vec3 p000 = texelFetch(u_nodes, c, 0).xyz;
    vec3 p100 = texelFetch(u_nodes, c + ivec3(1, 0, 0), 0).xyz;
    vec3 p010 = texelFetch(u_nodes, c + ivec3(0, 1, 0), 0).xyz;
    vec3 p110 = texelFetch(u_nodes, c + ivec3(1, 1, 0), 0).xyz;
    vec3 p001 = texelFetch(u_nodes, c + ivec3(0, 0, 1), 0).xyz;
    vec3 p101 = texelFetch(u_nodes, c + ivec3(1, 0, 1), 0).xyz;
    vec3 p011 = texelFetch(u_nodes, c + ivec3(0, 1, 1), 0).xyz;
    vec3 p111 = texelFetch(u_nodes, c + ivec3(1, 1, 1), 0).xyz;
    vec3 d00 = p100 - p000, d10 = p110 - p010, d01 = p101 - p001, d11 = p111 - p011;
    vec3 x00 = p000 + f.x * d00, x10 = p010 + f.x * d10;
    vec3 x01 = p001 + f.x * d01, x11 = p011 + f.x * d11;
    vec3 y0 = mix(x00, x10, f.y), y1 = mix(x01, x11, f.y);
    vec3 s = u_cells * u_box_inv_size;  // d f / d local, per axis
    J = mat3(mix(mix(d00, d10, f.y), mix(d01, d11, f.y), f.z) * s.x,
             mix(x10 - x00, x11 - x01, f.z) * s.y,
             (y1 - y0) * s.z);
#ifdef HW_TRILINEAR
    if (all(greaterThanEqual(u, vec3(0.0))) && all(lessThanEqual(u, vec3(1.0)))) {
        return texture(u_nodes, (u * u_cells + 0.5) / (u_cells + 1.0)).xyz;
    }
#endif
    return mix(y0, y1, f.z);
}
#endif

vec3 carry_normal(mat3 J, vec3 n) {
#ifdef LINEAR
    if (u_normal_method == 2) return u_normal_matrix * n;
#endif
    if (u_normal_method == 0) {
        vec3 d = J * n;
        float scale = max(max(length(J[0]), length(J[1])), length(J[2])) * length(n);
        if (length(d) > 1e-6 * scale) return d;
        // n in J's null space (a flattened lattice): the tangent form below stays defined
    }
    vec3 a = abs(n.x) < 0.9 ? vec3(1.0, 0.0, 0.0) : vec3(0.0, 1.0, 0.0);
    vec3 t1 = normalize(cross(a, n));
    vec3 t2 = cross(n, t1);     // t1 x t2 = n
    return cross(J * t1, J * t2);
}

void main() {
    mat3 J;
    vec3 world = place(in_position, J);
    v_world = world;
    // unit length before interpolation: |J n| and |cof(J) n| vary over a bent lattice
    // and would weight the interpolation differently
    v_normal = normalize(carry_normal(J, in_normal));
    gl_Position = u_view_proj * vec4(world, 1.0);
}
