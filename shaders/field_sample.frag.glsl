#version 430
// voxwarp field export (voxwarp export-field --sampler gpu): the warp chain's pull-back
// displacement on a run of planes of nodes of an export grid, stacked in the target's
// rows (u_rows rows a plane). Fragment (x, y) of the target is node
// (u_plane + y / u_rows, y % u_rows, x): its world point p = u_index_to_world * (u_plane, y, x, 1)
// goes through the same warp chain as the raycaster's and slice views' samples, and
// the pixel holds u = warp_chain(p) - p (RGB, mm) and 1 (A). A point the chain does
// not carry (a wire's vacated space) is sent to WARP_FAR or NaN; the caller tells it
// from |u| (as voxwarp.deform.warp.chain_apply_carried does on the CPU).

#include "warps.glsl"

uniform mat4 u_index_to_world;  // node index (i, j, k, 1) -> world point (mm)
uniform float u_plane;          // the first index i of this run of planes
uniform float u_rows;           // rows a plane (ny)

layout(location = 0) out vec4 f_value;

void main() {
    vec2 node = gl_FragCoord.xy - 0.5;  // (k, row)
    float i = floor((node.y + 0.5) / u_rows);
    vec3 p = (u_index_to_world * vec4(u_plane + i, node.y - i * u_rows, node.x, 1.0)).xyz;
    f_value = vec4(warp_chain(p) - p, 1.0);
}
