#version 430 core
// GPU ChainMail passes (deform/elements/chainmail_gpu.py): the box [u_box_lo, u_box_hi) of
// elements as one quad per z-slice of the atlas (instance i: slice u_box_lo.z + i),
// in NDC; no vertex buffer (gl_VertexID 0..5 are the quad's two triangles).
#include "chainmail_config.glsl"

uniform ivec3 u_box_lo;
uniform ivec3 u_box_hi;  // exclusive

void main() {
    int k = u_box_lo.z + gl_InstanceID;
    ivec2 origin = ivec2((k % TX) * BX, (k / TX) * BY);
    int v = gl_VertexID;
    bool right = v == 1 || v == 2 || v == 4;
    bool top = v == 2 || v == 4 || v == 5;
    ivec2 c = origin + ivec2(right ? u_box_hi.x : u_box_lo.x, top ? u_box_hi.y : u_box_lo.y);
    gl_Position = vec4(vec2(c) / vec2(CM_ATLAS_W, CM_ATLAS_H) * 2.0 - 1.0, 0.0, 1.0);
}
