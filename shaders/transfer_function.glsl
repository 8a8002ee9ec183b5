// Transfer function: a table of RGBA over [u_tf_range.x, u_tf_range.y] in data units,
// linearly interpolated; alpha is the opacity per reference sample distance and is
// corrected for the actual sample distance by 1 - (1 - a)^(step / reference).
uniform sampler2D u_tf;
uniform vec2 u_tf_range;
uniform float u_tf_size;          // number of table entries
uniform float u_alpha_exponent;   // step / reference distance

vec4 transfer(float v) {
    float x = clamp((v - u_tf_range.x) / (u_tf_range.y - u_tf_range.x), 0.0, 1.0);
    return texture(u_tf, vec2((x * (u_tf_size - 1.0) + 0.5) / u_tf_size, 0.5));
}

float correct_alpha(float a) {
    return 1.0 - pow(max(1.0 - a, 0.0), u_alpha_exponent);
}

// Window/level mapping for the grey-value modes: data value -> [0, 1].
uniform vec2 u_window;            // (low, high) in data units
float window_gray(float v) { return clamp((v - u_window.x) / (u_window.y - u_window.x), 0.0, 1.0); }
