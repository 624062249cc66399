/* Relight AR sphere shadows under an environment: fragment stage BODY (declarations injected,
 * see relight_addon/blender/ar_shader.py).  The numpy twin is
 * relight_addon/core/ar/env_shadow.py, env_shadow_factor(weighting="light+caps", cap="exact"):
 * the same operations in the same order (cap.py, env_shadow.py, relight/sphere_shadow.py;
 * relight_lamp_blocked and EPS_ANGLE come from sphere_lamp.glsl, read before this body).
 *
 * Interface:
 *   in  vec3 v_pos, v_nor;                 receiver point and normal, world space
 *   uniform vec4  spheres[MAX_SPHERES];    xyz centre, w radius (world space)
 *   uniform int   n_spheres;
 *   uniform vec4  hull;                    the silhouette sphere; w <= 0: none (plain product)
 *   uniform vec4  light_dir[MAX_LIGHTS];   xyz unit direction towards the light, w half-angle
 *   uniform vec4  light_rad[MAX_LIGHTS];   rgb radiance the light adds
 *   uniform int   n_lights;
 *   uniform float e_floor;                 smallest residual irradiance (env_shadow.E_FLOOR)
 *   uniform float cap_angles[N_CAP];       half-angles (rad) of the cap tables' layers
 *   uniform sampler2D      irradiance_map; E(n), equirectangular (lighting.irradiance)
 *   uniform sampler2DArray cap_tables;     residual's cap means, one layer per cap angle
 *   out vec4 FragColor;                    rgb = the shadow factor F in [0, 1], a = 1: draw
 *                                          with multiplicative blending over the photograph
 * Textures: latitude-node tables (core/ar/envmap.py: the first and last rows on the poles),
 * uploaded rows bottom first (shader_data.shadow_textures), linear filtering, REPEAT in s,
 * CLAMP_TO_EDGE in t, read at t = (0.5 + v (h - 1)) / h.  Blender's equirectangular
 * convention: u = 0.5 - atan(y, x) / 2 pi, v = 0.5 + asin(z) / pi.
 *
 * Keep the "const int/float NAME = ...;" form: a test compares them with the twin.
 */
const int MAX_SPHERES = 128;
const int MAX_LIGHTS = 4;
const int N_CAP = 10;
const float PI = 3.14159265358979;
const float SUN_DISTANCE = 1.0e5;

/* envmap.py: sample_nodes' texture coordinates for a table of h rows */
vec2 relight_node_uv(vec3 d, float h)
{
  float u = 0.5 - atan(d.y, d.x) / (2.0 * PI);
  float v = 0.5 + asin(clamp(d.z, -1.0, 1.0)) / PI;
  return vec2(u, (0.5 + v * (h - 1.0)) / h);
}

/* cap.py: cap_cosine_integral */
float relight_cap_cosine(float cb, float s2)
{
  cb = clamp(cb, -1.0, 1.0);
  s2 = max(s2, 0.0);
  if (s2 >= 1.0) {
    return PI;
  }
  if (cb * cb > s2) {
    return PI * s2 * max(cb, 0.0);
  }
  float sb = sqrt(max(1.0 - cb * cb, 0.0));
  float x = sqrt(1.0 / max(s2, 1e-30) - 1.0);
  float y = clamp(-x * cb / max(sb, 1e-30), -1.0, 1.0);
  float sy = sb * sqrt(max(1.0 - y * y, 0.0));
  float c = (cb * acos(y) - x * sy) * s2 + atan(sy, x);
  return clamp(c, 0.0, PI);
}

/* env_shadow.py: cap_filter.sample_cap_filtered at visible_cap + cosine_centroid */
vec3 relight_cap_radiance(vec3 axis, float cb, float s2, vec3 n)
{
  float alpha = asin(sqrt(clamp(s2, 0.0, 1.0)));
  float e = asin(clamp(cb, -1.0, 1.0));
  float lo = max(e - alpha, 0.0);
  float hi = e + alpha;
  vec3 ax = axis;
  float a2 = alpha;
  if (e < alpha && hi > 0.0) {
    vec3 t = axis - cb * n;
    float tn = length(t);
    t = (tn > 1e-12) ? t / tn : axis;
    float e2 = 0.5 * (lo + hi);
    ax = cos(e2) * t + sin(e2) * n;
    a2 = max(0.5 * (hi - lo), 0.0);
  }
  /* cosine-weighted centroid of the cap (ax, a2) */
  float cb2 = dot(ax, n);
  float sa = sin(a2);
  float ca = sqrt(clamp(1.0 - sa * sa, 0.0, 1.0));
  float A = 2.0 * PI * (1.0 - ca * ca * ca) / 3.0;
  float B = PI * (2.0 / 3.0 - ca + ca * ca * ca / 3.0);
  vec3 m = A * cb2 * ax + B * (n - cb2 * ax);
  float mn = length(m);
  vec3 dir = (mn > 1e-12) ? m / mn : ax;
  /* linear in the half-angle between the two nearest layers */
  float a = clamp(a2, cap_angles[0], cap_angles[N_CAP - 1]);
  int k = 0;
  for (int i = 0; i < N_CAP - 1; i++) {
    if (a >= cap_angles[i]) {
      k = i;
    }
  }
  k = min(k, N_CAP - 2);
  float f = (a - cap_angles[k]) / (cap_angles[k + 1] - cap_angles[k]);
  vec2 uv = relight_node_uv(dir, float(textureSize(cap_tables, 0).y));
  vec3 l0 = texture(cap_tables, vec3(uv, float(k))).rgb;
  vec3 l1 = texture(cap_tables, vec3(uv, float(k + 1))).rgb;
  return l0 * (1.0 - f) + l1 * f;
}

vec3 relight_ambient_blocked(vec3 p, vec3 n, vec4 s, vec3 e_amb)
{
  vec3 to_c = s.xyz - p;
  float d = max(length(to_c), 1e-12);
  vec3 axis = to_c / d;
  float cb = dot(axis, n);
  float s2 = (s.w / d) * (s.w / d);
  if (s2 >= 1.0) {
    return vec3(1.0);
  }
  vec3 b = relight_cap_radiance(axis, cb, s2, n) * relight_cap_cosine(cb, s2) / e_amb;
  return min(b, vec3(1.0));
}

void main()
{
  vec3 p = v_pos;
  vec3 n = normalize(v_nor);
  bool has_hull = hull.w > 0.0;

  /* irradiance of the lights, and the residual's: the map's less the lights' */
  float rows = float(textureSize(irradiance_map, 0).y);
  vec3 e_amb = texture(irradiance_map, relight_node_uv(n, rows)).rgb;
  vec3 e_light[MAX_LIGHTS];
  for (int j = 0; j < n_lights; j++) {
    float sl = sin(min(light_dir[j].w, PI / 2.0));
    e_light[j] = light_rad[j].rgb * relight_cap_cosine(dot(n, light_dir[j].xyz), sl * sl);
    e_amb -= e_light[j];
  }
  e_amb = max(e_amb, vec3(e_floor));

  /* the residual: sphere_shadow.combined_visibility over the spheres, within the hull */
  vec3 part = has_hull ? max(relight_ambient_blocked(p, n, hull, e_amb), vec3(1e-6)) : vec3(1.0);
  vec3 product = vec3(1.0);
  vec3 maximum = vec3(0.0);
  for (int i = 0; i < n_spheres; i++) {
    vec3 b = relight_ambient_blocked(p, n, spheres[i], e_amb);
    product *= 1.0 - min(b / part, vec3(1.0));
    maximum = max(maximum, b);
  }
  vec3 visible = has_hull ? clamp(1.0 - max(part * (1.0 - product), maximum), 0.0, 1.0) :
                            clamp(product, 0.0, 1.0);
  vec3 lit = e_amb * visible;
  vec3 total = e_amb;

  /* each light as a lamp: sphere_shadow.sphere_visibility (a disk SUN_DISTANCE away) */
  for (int j = 0; j < n_lights; j++) {
    vec3 lamp = light_dir[j].xyz * SUN_DISTANCE;
    float lamp_r = SUN_DISTANCE * tan(light_dir[j].w);
    float lpart = has_hull ? max(relight_lamp_blocked(p, lamp, lamp_r, hull.xyz, hull.w), 1e-6) :
                             1.0;
    float lprod = 1.0;
    float lmax = 0.0;
    for (int i = 0; i < n_spheres; i++) {
      float b = relight_lamp_blocked(p, lamp, lamp_r, spheres[i].xyz, spheres[i].w);
      lprod *= 1.0 - min(b / lpart, 1.0);
      lmax = max(lmax, b);
    }
    float v = has_hull ? clamp(1.0 - max(lpart * (1.0 - lprod), lmax), 0.0, 1.0) :
                         clamp(lprod, 0.0, 1.0);
    lit += e_light[j] * v;
    total += e_light[j];
  }
  FragColor = vec4(clamp(lit / total, 0.0, 1.0), 1.0);
}
