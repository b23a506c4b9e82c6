// Synthetic capture: a posed head under one lighting scene, with its ground truth in four float targets.
// Albedo is a solid texture of the canonical (unposed) position, made here: skin with fine detail, lips,
// brows, iris and sclera. Light: second-order spherical harmonics, plus a key light for diffuse shading,
// a specular lobe scaled by a map strongest on forehead and nose, and shadow-mapped cast shadows.
#if defined VERTEX_SHADER
in vec3 in_position;    // posed, world metres
in vec3 in_normal;      // posed, world
in vec3 in_canonical;   // neutral (identity applied), metres
in vec4 in_eye;         // xyz: eyeball centre (canonical), w: 1 on an eyeball, 0 on skin
uniform mat4 u_view_projection;
uniform mat4 u_view;
uniform mat4 u_light_view_projection;
uniform float u_normal_offset;
out vec3 v_position;
out vec3 v_normal;
out vec3 v_canonical;
out vec4 v_eye;
out vec4 v_light_clip;
out float v_depth;
void main() {
    v_position = in_position;
    v_normal = in_normal;
    v_canonical = in_canonical;
    v_eye = in_eye;
    v_light_clip = u_light_view_projection * vec4(in_position + u_normal_offset * normalize(in_normal), 1.0);
    v_depth = -(u_view * vec4(in_position, 1.0)).z;
    gl_Position = u_view_projection * vec4(in_position, 1.0);
}
#elif defined FRAGMENT_SHADER
in vec3 v_position;
in vec3 v_normal;
in vec3 v_canonical;
in vec4 v_eye;
in vec4 v_light_clip;
in float v_depth;
uniform vec3 u_camera_position;
uniform vec3 u_sh[9];            // irradiance SH coefficients (linear RGB), Ramamoorthi-Hanrahan order
uniform vec3 u_light_dir;        // towards the key light
uniform vec3 u_light_color;
uniform int u_use_diffuse;
uniform int u_use_specular;
uniform int u_use_shadows;
uniform float u_shininess;
uniform float u_shadow_bias;
uniform sampler2DShadow u_shadow_map;
uniform vec3 u_skin_color;
uniform vec3 u_lip_color;
uniform vec3 u_brow_color;
uniform vec3 u_iris_color;
uniform vec3 u_lip_center;       // canonical metres
uniform vec2 u_lip_radii;
uniform vec3 u_brow_center[2];
uniform vec2 u_brow_radii;
uniform vec3 u_nose_top;
uniform vec3 u_nose_tip;
uniform vec3 u_forehead_center;
uniform vec3 u_forehead_radii;
uniform vec2 u_specular_range;   // specular strength: base, peak (forehead and nose)
uniform float u_seed;
layout(location = 0) out vec4 f_color;    // lit colour, linear; a = 1
layout(location = 1) out vec4 f_normal;   // world unit normal; a = 1
layout(location = 2) out vec4 f_albedo;   // rgb albedo; a = specular strength
layout(location = 3) out vec4 f_light;    // r: key light visibility (1 lit, 0 blocked), g: n.l, b: depth (m)

float hash(vec3 p) {
    p = fract(p * 0.3183099 + vec3(0.71, 0.113, 0.419) + u_seed);
    p *= 17.0;
    return fract(p.x * p.y * p.z * (p.x + p.y + p.z));
}

float value_noise(vec3 x) {
    vec3 i = floor(x);
    vec3 f = fract(x);
    f = f * f * (3.0 - 2.0 * f);
    return mix(mix(mix(hash(i), hash(i + vec3(1, 0, 0)), f.x),
                   mix(hash(i + vec3(0, 1, 0)), hash(i + vec3(1, 1, 0)), f.x), f.y),
               mix(mix(hash(i + vec3(0, 0, 1)), hash(i + vec3(1, 0, 1)), f.x),
                   mix(hash(i + vec3(0, 1, 1)), hash(i + vec3(1, 1, 1)), f.x), f.y), f.z);
}

float ellipse(vec2 p, vec2 c, vec2 r) {
    return length((p - c) / r);
}

vec3 skin_albedo(vec3 p) {
    float fine = value_noise(p * 650.0) - 0.5;          // ~1.5 mm grain
    float blotch = value_noise(p * 80.0 + 3.7) - 0.5;   // ~1 cm unevenness
    vec3 c = u_skin_color * (1.0 + 0.12 * fine + 0.10 * blotch);
    float pores = smoothstep(0.80, 0.92, value_noise(p * 1500.0 + 11.0));
    c *= 1.0 - 0.22 * pores;
    float front = smoothstep(u_lip_center.z - 0.035, u_lip_center.z - 0.015, p.z);
    float lip = (1.0 - smoothstep(0.85, 1.1, ellipse(p.xy, u_lip_center.xy, u_lip_radii))) * front;
    c = mix(c, u_lip_color * (1.0 + 0.12 * fine), lip);
    for (int k = 0; k < 2; ++k) {
        float d = ellipse(p.xy, u_brow_center[k].xy, u_brow_radii);
        float hair = 0.65 + 0.7 * value_noise(p * vec3(2200.0, 260.0, 260.0));  // strands run sideways
        float brow = (1.0 - smoothstep(0.7, 1.05, d)) * smoothstep(u_brow_center[k].z - 0.03, u_brow_center[k].z - 0.01, p.z);
        c = mix(c, u_brow_color * hair, 0.92 * brow);
    }
    return clamp(c, 0.0, 1.0);
}

vec3 eye_albedo(vec3 p, vec3 center) {
    vec3 d = normalize(p - center);
    float angle = acos(clamp(d.z, -1.0, 1.0));
    vec3 sclera = vec3(0.86, 0.83, 0.80) * (1.0 - 0.06 * value_noise(p * 900.0));
    float streaks = value_noise(vec3(atan(d.y, d.x) * 8.0, angle * 40.0, 0.0));
    vec3 iris = u_iris_color * (0.7 + 0.6 * streaks);
    vec3 c = mix(iris, sclera, smoothstep(0.40, 0.45, angle));
    return mix(vec3(0.03), c, smoothstep(0.15, 0.18, angle));  // pupil
}

float specular_strength(vec3 p, float on_eye) {
    vec3 q = (p - u_forehead_center) / u_forehead_radii;
    float forehead = exp(-dot(q, q));
    vec3 axis = u_nose_tip - u_nose_top;
    float t = clamp(dot(p - u_nose_top, axis) / dot(axis, axis), 0.0, 1.0);
    float to_ridge = length(p - (u_nose_top + t * axis));
    float nose = exp(-pow(to_ridge / 0.012, 2.0));
    float s = u_specular_range.x + (u_specular_range.y - u_specular_range.x) * max(forehead, nose);
    return mix(s, 0.9, on_eye);
}

vec3 sh_irradiance(vec3 n) {
    return u_sh[0]
        + u_sh[1] * n.y + u_sh[2] * n.z + u_sh[3] * n.x
        + u_sh[4] * (n.x * n.y) + u_sh[5] * (n.y * n.z) + u_sh[6] * (3.0 * n.z * n.z - 1.0)
        + u_sh[7] * (n.x * n.z) + u_sh[8] * (n.x * n.x - n.y * n.y);
}

void main() {
    vec3 n = normalize(v_normal);
    if (!gl_FrontFacing) {
        n = -n;  // the inside of the mouth or eye socket, seen through the opening
    }
    bool on_eye = v_eye.w > 0.5;
    vec3 albedo = on_eye ? eye_albedo(v_canonical, v_eye.xyz) : skin_albedo(v_canonical);
    if (!gl_FrontFacing) {
        albedo *= 0.25;
    }
    float spec = specular_strength(v_canonical, on_eye ? 1.0 : 0.0);
    float n_dot_l = dot(n, u_light_dir);
    float visibility = 1.0;
    if (u_use_shadows == 1) {
        vec3 p = v_light_clip.xyz / v_light_clip.w * 0.5 + 0.5;
        visibility = texture(u_shadow_map, vec3(p.xy, p.z - u_shadow_bias));
    }
    vec3 c = albedo * max(sh_irradiance(n), vec3(0.0));
    if (u_use_diffuse == 1) {
        c += albedo * u_light_color * max(n_dot_l, 0.0) * visibility;
    }
    if (u_use_specular == 1 && n_dot_l > 0.0) {
        vec3 v = normalize(u_camera_position - v_position);
        vec3 h = normalize(v + u_light_dir);
        c += spec * u_light_color * pow(max(dot(n, h), 0.0), u_shininess) * visibility;
    }
    f_color = vec4(c, 1.0);
    f_normal = vec4(n, 1.0);
    f_albedo = vec4(albedo, spec);
    f_light = vec4(visibility, n_dot_l, v_depth, 1.0);
}
#endif
