#version 430
// A convex polygon in NDC, drawn as a triangle fan without a vertex buffer: corner
// gl_VertexID of u_polygon. The raycaster draws the whole viewport as one polygon, or
// one polygon per ray-direction octant (see app/render/skipping/maps.py: octant_regions).
uniform vec2 u_polygon[8];
void main() {
    gl_Position = vec4(u_polygon[gl_VertexID], 0.0, 1.0);
}
