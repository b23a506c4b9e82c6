// Guide mesh lit by one directional light with a shadow map, plus ambient.
// u_mode 0: albedo * (ambient + diffuse * visibility); u_mode 1: the light's visibility alone (shadow pass).
#if defined VERTEX_SHADER
in vec3 in_position;
in vec3 in_normal;
uniform mat4 u_view_projection;
uniform mat4 u_light_view_projection;
uniform float u_normal_offset;   // metres: look the shadow map up a little off the surface (no acne)
out vec3 v_normal;
out vec4 v_light_clip;
void main() {
    v_normal = in_normal;
    v_light_clip = u_light_view_projection * vec4(in_position + u_normal_offset * normalize(in_normal), 1.0);
    gl_Position = u_view_projection * vec4(in_position, 1.0);
}
#elif defined FRAGMENT_SHADER
in vec3 v_normal;
in vec4 v_light_clip;
uniform vec3 u_light_dir;        // unit vector from the surface towards the light, world space
uniform vec3 u_albedo;
uniform vec3 u_ambient;
uniform vec3 u_light_color;
uniform float u_shadow_bias;
uniform int u_use_shadows;
uniform int u_mode;
uniform sampler2DShadow u_shadow_map;
out vec4 f_color;
void main() {
    if (!gl_FrontFacing) {       // the inside of the head, seen through the mouth or eyes
        f_color = vec4(0.08, 0.03, 0.03, 1.0);
        return;
    }
    vec3 n = normalize(v_normal);
    float cos_theta = max(dot(n, u_light_dir), 0.0);
    float visibility = 1.0;
    if (u_use_shadows == 1) {
        vec3 p = v_light_clip.xyz / v_light_clip.w * 0.5 + 0.5;
        float slope_bias = u_shadow_bias * (1.0 + 2.0 * sqrt(1.0 - cos_theta * cos_theta));
        visibility = texture(u_shadow_map, vec3(p.xy, p.z - slope_bias));
    }
    if (u_mode == 1) {
        float lit = cos_theta > 0.0 ? visibility : 0.0;
        f_color = vec4(vec3(lit), 1.0);
    } else {
        vec3 c = u_albedo * (u_ambient + u_light_color * cos_theta * visibility);
        f_color = vec4(c, 1.0);
    }
}
#endif
