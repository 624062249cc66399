/* Relight relit preview: fragment stage BODY (declarations injected, see relit_shader.py;
 * relight_lamp_blocked comes from sphere_lamp.glsl).  The numpy twin is
 * relight_addon/core/display/relit.py (relit_colour, lamp_visibility): the same operations
 * in the same order.
 *
 * Interface:
 *   in  vec3 v_pos;  in vec2 v_uv;         surface point (world) and texture coordinates
 *   uniform sampler2D      t_image;        T, the shadow-free texture
 *   uniform sampler2DArray maps;           layer l: lamp l's map (rgb), alpha its direct part
 *   uniform vec4 lamps[MAX_LAMPS];         xyz lamp position, w its radius (world; < 0: a
 *                                          lamp with no place, drawn unshadowed)
 *   uniform vec4 lamp_scale[MAX_LAMPS];    rgb the lamp's present scale (power and colour)
 *   uniform int  n_lamps;
 *   uniform vec4 spheres[MAX_SPHERES];     xyz centre, w radius, of every moving object
 *   uniform vec4 hulls[MAX_OBJECTS];       object k's silhouette sphere (w <= 0: none)
 *   uniform vec4 bounds[MAX_OBJECTS];      a sphere holding object k's spheres: out of its reach
 *                                          (relight_may_shadow) they are not evaluated
 *   uniform int  object_end[MAX_OBJECTS];  object k's spheres end there (they start at k - 1's)
 *   uniform int  n_objects;
 *   out vec4 FragColor;                    the relit colour, alpha 1 (drawn opaque)
 *
 * Keep the "const int NAME = ...;" form: a test compares them with the twin.
 */
const int MAX_LAMPS = 8;
const int MAX_OBJECTS = 8;
const int MAX_SPHERES = 128;

/* relight/sphere_shadow.py: may_shadow, the double cone tangent to the bound and the lamp's
 * ball (false: every sphere inside the bound leaves the lamp whole) */
bool relight_may_shadow(vec3 p, vec4 lamp, vec4 bound)
{
  vec3 cl = bound.xyz - lamp.xyz;
  float dist = length(cl);
  float r = max(lamp.w, 0.0) + 2.0 * (dist + bound.w) * sin(0.5 * EPS_ANGLE);
  float both = bound.w + r;
  if (dist <= both) {
    return true;
  }
  vec3 c = cl / dist;
  vec3 e = p - bound.xyz;
  float along = dot(e, c) + dist * bound.w / both;
  float across = length(cross(e, c));
  return across < abs(along) * (both / sqrt(dist * dist - both * both));
}

/* relight/sphere_shadow.py: sphere_visibility of one object's spheres [first, last) */
float relight_object_visibility(vec3 p, vec4 lamp, vec4 hull, int first, int last)
{
  bool has_hull = hull.w > 0.0;
  float part = has_hull ? max(relight_lamp_blocked(p, lamp.xyz, lamp.w, hull.xyz, hull.w), 1e-6)
                        : 1.0;
  float product = 1.0;
  float maximum = 0.0;
  for (int i = first; i < last; i++) {
    float b = relight_lamp_blocked(p, lamp.xyz, lamp.w, spheres[i].xyz, spheres[i].w);
    product *= 1.0 - min(b / part, 1.0);
    maximum = max(maximum, b);
  }
  return has_hull ? clamp(1.0 - max(part * (1.0 - product), maximum), 0.0, 1.0) :
                    clamp(product, 0.0, 1.0);
}

void main()
{
  vec3 t = texture(t_image, v_uv).rgb;
  vec3 total = vec3(0.0);
  for (int l = 0; l < n_lamps; l++) {
    vec4 m = texture(maps, vec3(v_uv, float(l)));
    float v = 1.0;
    int first = 0;
    for (int k = 0; k < n_objects && lamps[l].w >= 0.0; k++) {
      if (object_end[k] > first && relight_may_shadow(v_pos, lamps[l], bounds[k])) {
        v *= relight_object_visibility(v_pos, lamps[l], hulls[k], first, object_end[k]);
      }
      first = object_end[k];
    }
    total += m.rgb * lamp_scale[l].rgb * (1.0 - m.a * (1.0 - v));
  }
  FragColor = vec4(t * total, 1.0);
}
