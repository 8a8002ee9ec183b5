// Transfer function lookup. u_tf is a (N x 2) RGBA table over data values, looked up
// without filtering (N = 4096 entries; llvmpipe pays per filtered texel):
//   row 0: premultiplied colour with the opacity already corrected for the sample
//          distance, a' = 1 - (1 - a)^(step / reference), so compositing is one FMA;
//   row 1: the straight colour and opacity (for opaque modes: flm, iso).
uniform sampler2D u_tf;
uniform vec2 u_tf_map;            // table index = value * x + y (+0.5 rounding included)
uniform float u_tf_size;          // N

int tf_index(float v) { return int(clamp(v * u_tf_map.x + u_tf_map.y, 0.0, u_tf_size - 1.0)); }
vec4 transfer(float v) { return texelFetch(u_tf, ivec2(tf_index(v), 0), 0); }
vec4 transfer_straight(float v) { return texelFetch(u_tf, ivec2(tf_index(v), 1), 0); }

// Window/level mapping for the grey-value modes: data value -> [0, 1].
uniform vec2 u_window;            // (low, high) in data units
float window_gray(float v) { return clamp((v - u_window.x) / (u_window.y - u_window.x), 0.0, 1.0); }
