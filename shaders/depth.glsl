// Depth only: the shadow map from the light, and the camera depth buffer.
#if defined VERTEX_SHADER
in vec3 in_position;
uniform mat4 u_view_projection;
void main() {
    gl_Position = u_view_projection * vec4(in_position, 1.0);
}
#elif defined FRAGMENT_SHADER
void main() {
}
#endif
