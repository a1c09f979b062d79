#version 450
// One vertex of a tile level: x, y (9 bits each) and a height code (14 bits) packed in two
// 16-bit components (see tools/tiles/src/pack.rs).
//
// Positions are computed relative to the camera from integers wherever possible, so a grid
// point shared by two tiles (or by a tile and a stitching triangle) lands on the same f32
// position in every draw: its sample column/row relative to the camera's tile is the same
// integer, and its height the same integer code on the tile set's height lattice.

layout(location = 0) in uvec2 packed_vertex;

layout(push_constant) uniform Draw {
    mat4 view_proj;          // camera at the origin, world axes x east, y north, z up
    vec4 camera;             // xyz: camera relative to its tile's north-west corner (m); w: metres per column
    ivec2 tile_offset;       // this tile's first sample relative to the camera tile's (columns, rows)
    float spacing_y;         // metres per row (rows run south)
    float height_step;       // metres per height code, one for the tile set
    int height_base;         // the tile's lowest code on the shared lattice
    uint level;
    vec4 tint;               // rgb: level colour, a: how much of it to show
} draw;

layout(location = 0) out vec3 relative;   // position relative to the camera (m)
layout(location = 1) out float height;    // absolute height (m)
layout(location = 2) out vec4 tint;

// The one place a vertex gets its height: geomorphing will blend toward coarser levels here.
float vertex_height(uint code) {
    return float(draw.height_base + int(code)) * draw.height_step;
}

void main() {
    uint v = packed_vertex.x | (packed_vertex.y << 16);
    ivec2 sample_pos = draw.tile_offset + ivec2(int(v & 511u), int((v >> 9) & 511u));
    uint code = v >> 18;
    height = vertex_height(code);
    relative = vec3(float(sample_pos.x) * draw.camera.w, -float(sample_pos.y) * draw.spacing_y, height) - draw.camera.xyz;
    tint = draw.tint;
    gl_Position = draw.view_proj * vec4(relative, 1.0);
}
