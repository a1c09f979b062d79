#version 450
// The static-mesh limit (renderer/src/limit.rs): the simplest vertex shader a terrain grid
// can have, as the yardstick for what the terrain shader costs per triangle. A vertex's grid
// column and row follow from its index; no memory is read, nothing is morphed.

layout(push_constant) uniform Grid {
    mat4 view_proj;
    uint side;               // vertices per grid row
    float spacing;           // metres between vertices
} grid;

void main() {
    uint i = uint(gl_VertexIndex);
    vec2 at = vec2(float(i % grid.side), float(i / grid.side)) * grid.spacing;
    gl_Position = grid.view_proj * vec4(at.x, -at.y, 0.0, 1.0);
}
