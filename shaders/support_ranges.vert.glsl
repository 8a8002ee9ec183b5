#version 430
// The chain's support surface (deform/support.py SupportMap.boundary_triangles) in the
// raycaster's camera: each fragment is one face a pixel's ray crosses
// (app/render/support_ranges.py).
uniform mat4 u_view_proj;   // deformed world -> clip
in vec3 in_position;        // deformed world (mm)
out vec3 v_world;

void main() {
    v_world = in_position;
    gl_Position = u_view_proj * vec4(in_position, 1.0);
}
