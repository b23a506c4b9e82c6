// One flat colour: landmark points over the mesh.
#if defined VERTEX_SHADER
in vec3 in_position;
uniform mat4 u_view_projection;
uniform float u_point_size_px;
void main() {
    gl_Position = u_view_projection * vec4(in_position, 1.0);
    gl_PointSize = u_point_size_px;
}
#elif defined FRAGMENT_SHADER
uniform vec4 u_color;
out vec4 f_color;
void main() {
    f_color = u_color;
}
#endif
