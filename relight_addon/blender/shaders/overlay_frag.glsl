/* Relight element overlay: fragment stage BODY (declarations injected, see overlay_vert.glsl).
 *
 * Interface:
 *   in  float v_value;
 *   uniform float alpha;   overlay opacity in [0, 1]
 *   uniform int   mode;    0 = ratio colour map, 1 = visibility-type palette
 *   out vec4 FragColor;
 *
 * Mode 0, ratio colour map (e.g. B/D, radiosity over its reference), on a log2 scale:
 *   t = clamp(log2(max(value, RATIO_FLOOR)) / LOG2_RANGE, -1, 1)
 *   t < 0: mix(COLOR_MID, COLOR_LOW,  -t)      value 1 -> white,
 *   t > 0: mix(COLOR_MID, COLOR_HIGH,  t)      value <= 1/2 -> blue, value >= 2 -> red.
 *   Zero and negative values -> COLOR_LOW, +Inf -> COLOR_HIGH, NaN -> COLOR_NAN.
 * Mode 1, visibility type (relight_addon/core/radiosity/links.py: VISIBLE, PARTIAL, INVISIBLE
 *   = 0, 1, 2): the nearest integer picks COLOR_VISIBLE / COLOR_PARTIAL / COLOR_INVISIBLE;
 *   anything else (NaN, out of range) -> COLOR_NAN.
 *
 * The numpy twin is relight_addon/core/display/colormap.py; a test parses the constants below
 * and compares them with the twin's, so keep the "const float/vec3 NAME = ...;" form.
 */
const float RATIO_FLOOR = 1e-6;
const float LOG2_RANGE = 1.0;
const vec3 COLOR_LOW = vec3(0.05, 0.25, 1.0);
const vec3 COLOR_MID = vec3(1.0, 1.0, 1.0);
const vec3 COLOR_HIGH = vec3(1.0, 0.1, 0.05);
const vec3 COLOR_NAN = vec3(1.0, 0.0, 1.0);
const vec3 COLOR_VISIBLE = vec3(0.1, 0.8, 0.2);
const vec3 COLOR_PARTIAL = vec3(1.0, 0.8, 0.1);
const vec3 COLOR_INVISIBLE = vec3(0.35, 0.35, 0.35);

vec3 relight_ratio_color(float v)
{
  if (isnan(v)) {
    return COLOR_NAN;
  }
  float t;
  if (isinf(v)) {
    t = (v > 0.0) ? 1.0 : -1.0;
  }
  else {
    t = clamp(log2(max(v, RATIO_FLOOR)) / LOG2_RANGE, -1.0, 1.0);
  }
  return (t < 0.0) ? mix(COLOR_MID, COLOR_LOW, -t) : mix(COLOR_MID, COLOR_HIGH, t);
}

vec3 relight_visibility_color(float v)
{
  if (isnan(v) || isinf(v)) {
    return COLOR_NAN;
  }
  float k = floor(v + 0.5);
  if (k == 0.0) {
    return COLOR_VISIBLE;
  }
  if (k == 1.0) {
    return COLOR_PARTIAL;
  }
  if (k == 2.0) {
    return COLOR_INVISIBLE;
  }
  return COLOR_NAN;
}

void main()
{
  vec3 rgb = (mode == 1) ? relight_visibility_color(v_value) : relight_ratio_color(v_value);
  FragColor = vec4(rgb, clamp(alpha, 0.0, 1.0));
}
