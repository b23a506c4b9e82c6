// World-space unit normals as colours: rgb = n * 0.5 + 0.5.
#if defined VERTEX_SHADER
in vec3 in_position;
in vec3 in_normal;
uniform mat4 u_view_projection;
out vec3 v_normal;
void main() {
    v_normal = in_normal;
    gl_Position = u_view_projection * vec4(in_position, 1.0);
}
#elif defined FRAGMENT_SHADER
in vec3 v_normal;
out vec4 f_color;
void main() {
    f_color = vec4(normalize(v_normal) * 0.5 + 0.5, 1.0);
}
#endif
