// The guide mesh's surface: lit by a directional light with a shadow map (mode 0), the light's
// visibility alone (mode 1), or world normals as colours (mode 2). Compiled with WIREFRAME defined, a
// geometry stage adds barycentric coordinates and edges are drawn in the same pass (no line pass); without
// it there is no geometry stage, which halves the cost of a draw on llvmpipe. Eyeballs (in_eye.w = 1) are
// drawn with a sclera, an iris and a pupil about their forward axis at rest, from each vertex's rest position,
// so the guide's eyes follow the gaze.
#if defined VERTEX_SHADER
in vec3 in_position;
in vec3 in_normal;
in vec3 in_canonical;    // the vertex at rest (no pose, no gaze)
in vec4 in_eye;          // xyz: its eyeball's centre at rest, w: 1 on an eyeball, 0 elsewhere
uniform mat4 u_view_projection;
uniform mat4 u_light_view_projection;
uniform float u_normal_offset;   // metres: look the shadow map up a little off the surface (no acne)
out Surface {
    vec3 normal;
    vec4 light_clip;
    vec3 canonical;
    vec4 eye;
} vs_out;
void main() {
    vs_out.normal = in_normal;
    vs_out.canonical = in_canonical;
    vs_out.eye = in_eye;
    vs_out.light_clip = u_light_view_projection * vec4(in_position + u_normal_offset * normalize(in_normal), 1.0);
    gl_Position = u_view_projection * vec4(in_position, 1.0);
}
#elif defined GEOMETRY_SHADER && defined WIREFRAME
layout(triangles) in;
layout(triangle_strip, max_vertices = 3) out;
in Surface {
    vec3 normal;
    vec4 light_clip;
    vec3 canonical;
    vec4 eye;
} gs_in[];
out Surface {
    vec3 normal;
    vec4 light_clip;
    vec3 canonical;
    vec4 eye;
} gs_out;
out vec3 v_bary;
void main() {
    for (int i = 0; i < 3; ++i) {
        gl_Position = gl_in[i].gl_Position;
        gs_out.normal = gs_in[i].normal;
        gs_out.light_clip = gs_in[i].light_clip;
        gs_out.canonical = gs_in[i].canonical;
        gs_out.eye = gs_in[i].eye;
        v_bary = vec3(i == 0, i == 1, i == 2);
        EmitVertex();
    }
    EndPrimitive();
}
#elif defined FRAGMENT_SHADER
in Surface {
    vec3 normal;
    vec4 light_clip;
    vec3 canonical;
    vec4 eye;
} fs_in;
#if defined WIREFRAME
in vec3 v_bary;
#endif
uniform vec3 u_light_dir;        // unit vector from the surface towards the light, world space
uniform vec3 u_albedo;
uniform vec3 u_ambient;
uniform vec3 u_light_color;
uniform float u_shadow_bias;
uniform int u_use_shadows;
uniform int u_mode;
uniform sampler2DShadow u_shadow_map;
uniform vec4 u_wire_color;       // rgb, and alpha = how strongly edges cover the surface
uniform float u_wire_width_px;
out vec4 f_color;
vec3 eye_albedo(vec3 p, vec3 center) {  // sclera, a blue-grey iris 0.42 rad about the forward axis, a pupil
    float angle = acos(clamp(normalize(p - center).z, -1.0, 1.0));
    vec3 c = mix(vec3(0.30, 0.40, 0.52), vec3(0.88, 0.86, 0.84), smoothstep(0.40, 0.44, angle));
    return mix(vec3(0.03), c, smoothstep(0.15, 0.18, angle));
}
void main() {
    vec3 c;
    vec3 n = normalize(fs_in.normal);
    if (u_mode == 2) {
        c = n * 0.5 + 0.5;
    } else if (!gl_FrontFacing) {  // the inside of the head, seen through the mouth or eyes
        c = vec3(0.08, 0.03, 0.03);
    } else {
        float cos_theta = max(dot(n, u_light_dir), 0.0);
        float visibility = 1.0;
        if (u_use_shadows == 1) {
            vec3 p = fs_in.light_clip.xyz / fs_in.light_clip.w * 0.5 + 0.5;
            float slope_bias = u_shadow_bias * (1.0 + 2.0 * sqrt(1.0 - cos_theta * cos_theta));
            visibility = texture(u_shadow_map, vec3(p.xy, p.z - slope_bias));
        }
        if (u_mode == 1) {
            c = vec3(cos_theta > 0.0 ? visibility : 0.0);
        } else {
            vec3 albedo = fs_in.eye.w > 0.5 ? eye_albedo(fs_in.canonical, fs_in.eye.xyz) : u_albedo;
            c = albedo * (u_ambient + u_light_color * cos_theta * visibility);
        }
    }
#if defined WIREFRAME
    vec3 a = smoothstep(vec3(0.0), fwidth(v_bary) * u_wire_width_px, v_bary);
    float edge = 1.0 - min(min(a.x, a.y), a.z);
    c = mix(c, u_wire_color.rgb, edge * u_wire_color.a);
#endif
    f_color = vec4(c, 1.0);
}
#endif
