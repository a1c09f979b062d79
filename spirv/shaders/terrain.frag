#version 450
#ifdef MIN_LOD
#extension GL_ARB_sparse_texture_clamp : require
#endif
// Terrain shading. Flag 16 (a diagnostic) gives each tile a flat colour. With texture tiles
// (flag 4) the colour is the tile's texture: a photo, or a
// relief tiletool lit from the full-resolution heights, so it needs no lighting here. Without
// (or for a tile that has no texture slot this frame): a hypsometric tint, or grey (flag 8),
// lit by the surface normal from the heights themselves (screen-space derivatives of the
// interpolated position, so each triangle is lit by its own slope).
//
// Texture level of detail follows the pixel footprint (trilinear, anisotropic where the
// sampler allows), clamped to the tile's finest resident mip. MIN_LOD (devices with
// shaderResourceMinLod) clamps with the sample's MinLod operand, which holds whatever level
// the sampler's anisotropic filtering picks. Without it the sampler is isotropic and the
// gradients are scaled so the footprint's shorter axis spans at least 2^finest texels: the
// level, from the longer axis, is then at least that mip. (Scaling alone does not hold under
// anisotropic filtering: how far an anisotropic sampler lowers the level is up to the
// implementation, and lavapipe lowers it by the full anisotropy.)

#include "interface.glsl"

// True in the pipeline that draws the tiles shaded by their texture this frame (flag 4 and a
// slot): the texture's path alone, so the inputs only the other shadings read (the position,
// height, level and sample) are not interpolated. A software rasteriser interpolates every
// input a shader reads for every fragment; one shader for every shading cost lavapipe
// 1.2-1.5x the draws of the Puget flyover at tau 3.
layout(constant_id = 1) const bool PHOTO = false;
// True in the photo pipeline for tiles whose every mip is resident (finest 0): the sampler's
// own level from the implicit derivatives, which lavapipe takes with 0.75-1.0x the frame of
// explicit gradients (bench/README.md, "Implicit derivatives"). A run-time branch on the
// finest mip instead cost lavapipe 1.1-1.35x the frame: it runs both sides of a branch it
// cannot prove uniform, so both samples.
layout(constant_id = 2) const bool WHOLE_MIPS = false;

layout(set = 0, binding = 2) uniform sampler2DArray textures;

layout(location = 0) in vec3 relative;
layout(location = 1) in float height;
layout(location = 2) in float level;
layout(location = 3) flat in uint flags;
layout(location = 4) in vec2 sample_xy;
layout(location = 5) flat in vec4 texture_tile;
layout(location = 6) in vec2 tile_xy;

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

// The tile's texture at texture coordinate `uv`, whose screen derivatives are `du` and `dv`.
vec4 photo(vec2 uv, vec2 du, vec2 dv) {
    vec3 at = vec3(uv, texture_tile.z);
    if (WHOLE_MIPS) {
        return vec4(texture(textures, at).rgb, 1.0);
    }
#ifdef MIN_LOD
    return vec4(textureGradClampARB(textures, at, du, dv, texture_tile.w).rgb, 1.0);
#else
    // With every mip resident the sampler's own level stands (the gradients as they are,
    // what WHOLE_MIPS samples with implicit derivatives).
    float shorter = min(length(du), length(dv)) * frame.texture_map.z;
    float k = texture_tile.w > 0.0 ? max(exp2(texture_tile.w + 0.01) / max(shorter, 1e-6), 1.0) : 1.0;
    return vec4(textureGrad(textures, at, du * k, dv * k).rgb, 1.0);
#endif
}

void main() {
    // Derivatives in uniform control flow, before any branch.
    vec2 uv = frame.texture_map.x + (tile_xy + texture_tile.xy) * frame.texture_map.y;
    vec2 du = dFdx(uv);
    vec2 dv = dFdy(uv);
    if (PHOTO) {
        colour = photo(uv, du, dv);
        return;
    }
    vec3 n = normalize(cross(dFdx(relative), dFdy(relative)));

    if ((flags & FLAG_TEXTURE) != 0u && texture_tile.z >= 0.0) {
        colour = photo(uv, du, dv);
        return;
    }
    if ((flags & FLAG_TILES) != 0u) {
        // The tile's column and row from the fragment's sample position (texture_map.w moves
        // the grid, for tests: lines that are not tile borders): neighbours differ in red or
        // green.
        ivec2 t = ivec2(floor((sample_xy - frame.texture_map.w) / 256.0));
        colour = vec4(0.2 + 0.6 * float(t.x & 1), 0.2 + 0.6 * float(t.y & 1), 0.5, 1.0);
        return;
    }
    if (n.z < 0.0) n = -n;
    // A degenerate (stitching) triangle has no slope of its own: light it as flat ground.
    if (any(isnan(n))) n = vec3(0.0, 0.0, 1.0);
    vec3 sun = normalize(vec3(-0.45, 0.55, 0.70));
    float light = 0.25 + 0.75 * max(dot(n, sun), 0.0);
    vec3 base = (flags & FLAG_RELIEF) != 0u ? vec3(0.82) : ground(height);
    if ((flags & FLAG_LEVEL_COLOURS) != 0u) base = mix(base, level_colour(level), 0.65);
    colour = vec4(base * light, 1.0);
}
