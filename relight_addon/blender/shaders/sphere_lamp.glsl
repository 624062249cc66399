/* Relight: the part of a lamp one sphere hides, shared by the viewport's shaders (read before
 * their bodies: ar_shader.py, relit_shader.py).  The numpy twin is
 * relight_addon/core/relight/sphere_shadow.py, blocked_part: the same operations in the same
 * order.  Keep the "const float NAME = ...;" form: a test compares it with the twin. */
const float EPS_ANGLE = 1e-4;

/* relight/sphere_shadow.py: cap_visibility's blocked part (1 - visibility) */
float relight_lamp_blocked(vec3 p, vec3 lamp_pos, float lamp_radius, vec3 c, float r)
{
  vec3 to_l = lamp_pos - p;
  vec3 to_c = c - p;
  float d_l = max(length(to_l), 1e-12);
  float d_c = max(length(to_c), 1e-12);
  if (d_c < r) {
    return 1.0;
  }
  if (d_c >= d_l) {
    return 0.0;
  }
  /* the angle between the axes, as atan(|a x b|, a.b): acos loses float32 precision near 0 */
  vec3 ul = to_l / d_l;
  vec3 uc = to_c / d_c;
  float gamma = atan(length(cross(ul, uc)), dot(ul, uc));
  float s_l = min(lamp_radius / d_l, 1.0);
  float s_o = min(r / d_c, 1.0);
  float th_l = asin(s_l);
  float th_o = asin(s_o);
  float om_l = s_l * s_l / (1.0 + sqrt(max(1.0 - s_l * s_l, 0.0)));
  float om_o = s_o * s_o / (1.0 + sqrt(max(1.0 - s_o * s_o, 0.0)));
  float width = max(2.0 * min(th_l, th_o), EPS_ANGLE);
  float t = clamp((th_l + th_o - gamma) / width, 0.0, 1.0);
  return clamp(min(om_o / max(om_l, 1e-30), 1.0) * t * t * (3.0 - 2.0 * t), 0.0, 1.0);
}

