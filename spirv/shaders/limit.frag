#version 450
// The static-mesh limit's fragment shader: one constant colour.

layout(location = 0) out vec4 colour;

void main() {
    colour = vec4(0.36, 0.52, 0.25, 1.0);
}
