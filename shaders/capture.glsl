// Synthetic capture: a posed head (with its hair, teeth and lashes) under one lighting scene, with its ground truth
// in four float targets. Each vertex carries a material (in_material.w: 0 skin, 1 eye, 2 hair, 3 teeth, 4 lashes)
// and the material's own coordinates (xyz). Skin albedo is a solid texture of the canonical (unposed) position,
// made here: tone variation, blush, fine grain and pores, lips, brows drawn as strands, the mouth's dark inside;
// hair is strands along its own coordinates, cut at the hairline with a fringe. Light: second-order spherical
// harmonics, plus a key light for diffuse shading, a specular lobe (Blinn-Phong scaled by a map strongest on
// forehead and nose; on hair, Kajiya-Kay along the strands), and shadow-mapped cast shadows.
#if defined VERTEX_SHADER
in vec3 in_position;    // posed, world metres
in vec3 in_normal;      // posed, world
in vec3 in_canonical;   // neutral (identity applied), metres
in vec4 in_material;    // w: material id; xyz: eyeball centre (eye), strand coordinates and coverage (hair),
                        // arch length, height, row (teeth), along the lid and the lash (lashes),
                        // inside the mouth 0..1 (skin)
in vec3 in_tangent;     // posed, world: the direction the hair's strands run (0 off the hair)
uniform mat4 u_view_projection;
uniform mat4 u_view;
uniform mat4 u_light_view_projection;
uniform float u_normal_offset;
out vec3 v_position;
out vec3 v_normal;
out vec3 v_canonical;
out vec4 v_material;
out vec3 v_tangent;
out vec4 v_light_clip;
out float v_depth;
void main() {
    v_position = in_position;
    v_normal = in_normal;
    v_canonical = in_canonical;
    v_material = in_material;
    v_tangent = in_tangent;
    v_light_clip = u_light_view_projection * vec4(in_position + u_normal_offset * normalize(in_normal), 1.0);
    v_depth = -(u_view * vec4(in_position, 1.0)).z;
    gl_Position = u_view_projection * vec4(in_position, 1.0);
}
#elif defined FRAGMENT_SHADER
in vec3 v_position;
in vec3 v_normal;
in vec3 v_canonical;
in vec4 v_material;
in vec3 v_tangent;
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
uniform vec3 u_hair_color;
uniform vec3 u_cheek_center[2];  // canonical metres
uniform float u_blush;           // 0..1
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

float brow_strands(vec3 p, vec3 center) {
    // Coverage 0..1 of one brow: thick at the inner end, thinning outwards, on an arch, made of strands that
    // rise from the inner end and lie flatter towards the outer (rotated coordinates, stretched noise).
    float side = sign(center.x);
    float t = (p.x - center.x) * side / u_brow_radii.x;                 // -1 inner end, 1 outer end
    float arch = center.y + 0.45 * u_brow_radii.y * (1.0 - (t - 0.15) * (t - 0.15));
    float half_height = u_brow_radii.y * mix(1.35, 0.45, clamp(0.5 * (t + 1.0), 0.0, 1.0));
    float angle = radians(mix(75.0, 12.0, smoothstep(-1.0, 0.3, t)));
    vec2 dir = vec2(cos(angle) * side, sin(angle));
    vec2 d = p.xy - center.xy;
    float along = dot(d, dir), across = dot(d, vec2(-dir.y, dir.x));
    float strands = value_noise(vec3(across * 2600.0, along * 320.0, 5.0 + center.x * 100.0));
    float ragged = 0.35 * (value_noise(vec3(p.xy * 900.0, 2.0)) - 0.5);
    float inside = (1.0 - smoothstep(0.75, 1.05, abs(p.y - arch) / half_height + ragged))
                 * (1.0 - smoothstep(0.85, 1.08, abs(t) + ragged));
    float front = smoothstep(center.z - 0.03, center.z - 0.01, p.z);
    return inside * front * mix(0.55, 1.0, smoothstep(0.3, 0.7, strands));
}

vec3 skin_albedo(vec3 p, float inside_mouth) {
    float fine = value_noise(p * 650.0) - 0.5;          // ~1.5 mm grain
    float blotch = value_noise(p * 80.0 + 3.7) - 0.5;   // ~1 cm unevenness
    float tone = value_noise(p * 16.0 + 7.1) - 0.5;     // ~6 cm: a face is never one tone
    vec3 c = u_skin_color * (1.0 + 0.12 * fine + 0.10 * blotch + 0.14 * tone);
    float pores = smoothstep(0.80, 0.92, value_noise(p * 1500.0 + 11.0));
    c *= 1.0 - 0.22 * pores;
    float blush = 0.0;
    for (int k = 0; k < 2; ++k) {
        vec3 q = (p - u_cheek_center[k]) / vec3(0.022, 0.016, 0.03);
        blush = max(blush, exp(-dot(q, q)));
    }
    float to_nose = length(p - u_nose_tip) / 0.012;
    blush = max(blush, 0.7 * exp(-to_nose * to_nose));
    c = mix(c, c * vec3(1.06, 0.74, 0.74), u_blush * blush);
    float front = smoothstep(u_lip_center.z - 0.035, u_lip_center.z - 0.015, p.z);
    float lip = (1.0 - smoothstep(0.85, 1.1, ellipse(p.xy, u_lip_center.xy, u_lip_radii))) * front;
    c = mix(c, u_lip_color * (1.0 + 0.12 * fine), lip);
    for (int k = 0; k < 2; ++k) {
        float hair = 0.65 + 0.7 * value_noise(p * vec3(2200.0, 260.0, 260.0));
        c = mix(c, u_brow_color * hair, 0.95 * brow_strands(p, u_brow_center[k]));
    }
    vec3 mouth = vec3(0.10, 0.03, 0.03) * (1.0 + 0.3 * fine);  // the inside of the mouth: dark, red
    return clamp(mix(c, mouth, inside_mouth), 0.0, 1.0);
}

// Hair: m = (across the strands, along them, both metres; coverage). Strands are noise stretched along the hair,
// in clumps; the hairline is cut where coverage, roughened by strand-wise noise, falls under one half.
vec3 hair_albedo(vec3 m, out float keep, out float strand) {
    float strands = value_noise(vec3(m.x * 900.0, m.y * 30.0, 1.0));    // ~1 mm across, 3 cm along
    float fine = value_noise(vec3(m.x * 2000.0, m.y * 60.0, 2.0));
    float clumps = value_noise(vec3(m.x * 180.0, m.y * 8.0, 3.0));      // ~5 mm locks
    float shade = 0.45 + 0.7 * strands + 0.2 * fine + 0.35 * clumps;
    strand = strands;
    keep = m.z + 0.45 * (value_noise(vec3(m.x * 1200.0, m.y * 70.0, 4.0)) - 0.5);
    return clamp(u_hair_color * shade, 0.0, 1.0);
}

// Teeth: m = (arch length from the midline in metres, height 0 at the biting edge to 1 at the gum, row).
vec3 teeth_albedo(vec3 m) {
    float s = abs(m.x) / (m.z > 0.5 ? 0.75 : 1.0);  // lower teeth are narrower
    float gap = 1.0;
    const float edges[7] = float[7](0.0, 0.0085, 0.0150, 0.0225, 0.0295, 0.0365, 0.0470);
    for (int k = 0; k < 7; ++k) {
        float d = (s - edges[k]) / 0.0006;
        gap = min(gap, 1.0 - 0.6 * exp(-d * d));
    }
    vec3 c = vec3(0.78, 0.72, 0.60) * gap * (1.0 - 0.15 * m.y);
    c = mix(c, vec3(0.55, 0.22, 0.22), smoothstep(0.82, 0.92, m.y));  // the gum
    return c * mix(1.0, 0.35, smoothstep(0.012, 0.035, abs(m.x)));  // darker deeper in the mouth
}

// Lashes: m = (along the lid 0..1, along the lash 0 root to 1 tip); thin curved strands, the rest cut away.
vec3 lash_albedo(vec3 m, out float keep) {
    float k = m.x * 46.0 + 0.8 * value_noise(vec3(m.x * 90.0, 0.0, 6.0)) + 0.25 * m.y * m.y;
    float width = mix(0.42, 0.12, m.y);
    keep = width - abs(fract(k) - 0.5) + 0.5;
    return u_brow_color * 0.45;
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

vec3 hair_tangent(vec3 n) {
    vec3 t = v_tangent - n * dot(v_tangent, n);
    float len = length(t);
    return len > 1e-6 ? t / len : normalize(cross(n, vec3(1.0, 0.0, 0.0)));
}

void main() {
    vec3 n = normalize(v_normal);
    if (!gl_FrontFacing) {
        n = -n;  // the inside of the mouth, an eye socket or the hair, seen through an opening
    }
    int material = int(v_material.w + 0.5);
    float keep = 1.0;
    float strand = 0.5;
    vec3 albedo;
    float spec;
    if (material == 1) {
        albedo = eye_albedo(v_canonical, v_material.xyz);
        spec = 0.9;
    } else if (material == 2) {
        albedo = hair_albedo(v_material.xyz, keep, strand);
        spec = 0.0;
    } else if (material == 3) {
        albedo = teeth_albedo(v_material.xyz);
        spec = 0.3;
    } else if (material == 4) {
        albedo = lash_albedo(v_material.xyz, keep);
        spec = 0.05;
    } else {
        albedo = skin_albedo(v_canonical, v_material.x);
        spec = mix(specular_strength(v_canonical, 0.0), 0.02, v_material.x);
    }
    if (keep < 0.5) {
        discard;
    }
    if (!gl_FrontFacing) {
        albedo *= 0.25;
    }
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
    vec3 v = normalize(u_camera_position - v_position);
    vec3 h = normalize(v + u_light_dir);
    if (material == 2) {
        // Kajiya-Kay: a white lobe along the strands and a second, tinted by the hair and shifted towards the
        // tips (Marschner's R and TRT), strength written to the specular map as their peak.
        vec3 t = hair_tangent(n);
        vec3 t2 = normalize(t - 0.25 * n);
        float r = pow(sqrt(max(1.0 - pow(dot(t, h), 2.0), 0.0)), 80.0);
        float trt = pow(sqrt(max(1.0 - pow(dot(t2, h), 2.0), 0.0)), 24.0);
        spec = 0.12;
        if (u_use_specular == 1 && n_dot_l > 0.0) {
            c += u_light_color * (0.12 * r + 0.6 * trt * albedo) * (0.4 + 1.2 * strand) * smoothstep(0.0, 0.2, n_dot_l)
                 * visibility;
        }
    } else if (u_use_specular == 1 && n_dot_l > 0.0) {
        c += spec * u_light_color * pow(max(dot(n, h), 0.0), u_shininess) * visibility;
    }
    f_color = vec4(c, 1.0);
    f_normal = vec4(n, 1.0);
    f_albedo = vec4(albedo, spec);
    f_light = vec4(visibility, n_dot_l, v_depth, 1.0);
}
#endif
