// The guide mesh's surface: lit by a directional light with a shadow map (mode 0), the light's
// visibility alone (mode 1), or world normals as colours (mode 2); edges drawn in the same pass from
// barycentric coordinates made by the geometry stage (no second line pass).
#if defined VERTEX_SHADER
in vec3 in_position;
in vec3 in_normal;
uniform mat4 u_view_projection;
uniform mat4 u_light_view_projection;
uniform float u_normal_offset;   // metres: look the shadow map up a little off the surface (no acne)
out vec3 g_normal;
out vec4 g_light_clip;
void main() {
    g_normal = in_normal;
    g_light_clip = u_light_view_projection * vec4(in_position + u_normal_offset * normalize(in_normal), 1.0);
    gl_Position = u_view_projection * vec4(in_position, 1.0);
}
#elif defined GEOMETRY_SHADER
layout(triangles) in;
layout(triangle_strip, max_vertices = 3) out;
in vec3 g_normal[];
in vec4 g_light_clip[];
out vec3 v_normal;
out vec4 v_light_clip;
out vec3 v_bary;
void main() {
    for (int i = 0; i < 3; ++i) {
        gl_Position = gl_in[i].gl_Position;
        v_normal = g_normal[i];
        v_light_clip = g_light_clip[i];
        v_bary = vec3(i == 0, i == 1, i == 2);
        EmitVertex();
    }
    EndPrimitive();
}
#elif defined FRAGMENT_SHADER
in vec3 v_normal;
in vec4 v_light_clip;
in vec3 v_bary;
uniform vec3 u_light_dir;        // unit vector from the surface towards the light, world space
uniform vec3 u_albedo;
uniform vec3 u_ambient;
uniform vec3 u_light_color;
uniform float u_shadow_bias;
uniform int u_use_shadows;
uniform int u_mode;
uniform sampler2DShadow u_shadow_map;
uniform vec4 u_wire_color;       // rgb, and alpha = how strongly edges cover the surface (0: no edges)
uniform float u_wire_width_px;
out vec4 f_color;
void main() {
    vec3 c;
    vec3 n = normalize(v_normal);
    if (u_mode == 2) {
        c = n * 0.5 + 0.5;
    } else if (!gl_FrontFacing) {  // the inside of the head, seen through the mouth or eyes
        c = vec3(0.08, 0.03, 0.03);
    } else {
        float cos_theta = max(dot(n, u_light_dir), 0.0);
        float visibility = 1.0;
        if (u_use_shadows == 1) {
            vec3 p = v_light_clip.xyz / v_light_clip.w * 0.5 + 0.5;
            float slope_bias = u_shadow_bias * (1.0 + 2.0 * sqrt(1.0 - cos_theta * cos_theta));
            visibility = texture(u_shadow_map, vec3(p.xy, p.z - slope_bias));
        }
        if (u_mode == 1) {
            c = vec3(cos_theta > 0.0 ? visibility : 0.0);
        } else {
            c = u_albedo * (u_ambient + u_light_color * cos_theta * visibility);
        }
    }
    if (u_wire_color.a > 0.0) {
        vec3 a = smoothstep(vec3(0.0), fwidth(v_bary) * u_wire_width_px, v_bary);
        float edge = 1.0 - min(min(a.x, a.y), a.z);
        c = mix(c, u_wire_color.rgb, edge * u_wire_color.a);
    }
    f_color = vec4(c, 1.0);
}
#endif
