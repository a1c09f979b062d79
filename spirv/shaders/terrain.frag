#version 450
// Terrain shading: a hypsometric tint lit by the surface normal, which comes from the
// heights themselves (screen-space derivatives of the interpolated position, so each
// triangle is lit by its own slope).

layout(location = 0) in vec3 relative;
layout(location = 1) in float height;
layout(location = 2) in float level;
layout(location = 3) flat in uint flags;

layout(location = 0) out vec4 colour;

vec3 ground(float h) {
    if (h <= 0.5) return vec3(0.16, 0.32, 0.50);            // water and tidal flats
    const float stops[6] = float[](0.0, 200.0, 800.0, 1600.0, 2600.0, 3600.0);
    const vec3 colours[6] = vec3[](
        vec3(0.30, 0.45, 0.22), vec3(0.36, 0.52, 0.25), vec3(0.55, 0.55, 0.32),
        vec3(0.50, 0.42, 0.33), vec3(0.56, 0.54, 0.52), vec3(0.95, 0.95, 0.97));
    for (int i = 1; i < 6; ++i) {
        if (h < stops[i]) {
            return mix(colours[i - 1], colours[i], (h - stops[i - 1]) / (stops[i] - stops[i - 1]));
        }
    }
    return colours[5];
}

// Debug colours of levels 0.. (coarse blue to fine red), blended at fractional levels.
vec3 level_colour(float l) {
    const vec3 colours[10] = vec3[](
        vec3(0.10, 0.20, 0.90), vec3(0.10, 0.55, 0.95), vec3(0.10, 0.85, 0.85),
        vec3(0.15, 0.80, 0.30), vec3(0.60, 0.90, 0.10), vec3(0.95, 0.90, 0.10),
        vec3(0.98, 0.60, 0.10), vec3(0.95, 0.30, 0.10), vec3(0.85, 0.10, 0.10),
        vec3(0.60, 0.05, 0.40));
    float c = clamp(l, 0.0, 9.0);
    int k = min(int(floor(c)), 8);
    return mix(colours[k], colours[k + 1], c - float(k));
}

void main() {
    vec3 n = normalize(cross(dFdx(relative), dFdy(relative)));
    if (n.z < 0.0) n = -n;
    // A degenerate (stitching) triangle has no slope of its own: light it as flat ground.
    if (any(isnan(n))) n = vec3(0.0, 0.0, 1.0);
    vec3 sun = normalize(vec3(-0.45, 0.55, 0.70));
    float light = 0.25 + 0.75 * max(dot(n, sun), 0.0);
    vec3 base = ground(height);
    if ((flags & 2u) != 0u) base = mix(base, level_colour(level), 0.65);
    colour = vec4(base * light, 1.0);
}
