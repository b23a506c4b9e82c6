// Rasterize a mesh into per-pixel geometry: view depth (metres) and triangle id + 1 (0 where no surface).
#if defined VERTEX_SHADER
in vec3 in_position;
uniform mat4 u_view_projection;
uniform mat4 u_view;
out float v_depth;
void main() {
    v_depth = -(u_view * vec4(in_position, 1.0)).z;
    gl_Position = u_view_projection * vec4(in_position, 1.0);
}
#elif defined FRAGMENT_SHADER
in float v_depth;
layout(location = 0) out float f_depth;
layout(location = 1) out int f_triangle;
void main() {
    f_depth = v_depth;
    f_triangle = gl_PrimitiveID + 1;
}
#endif
