/* Relight AR sphere shadows: vertex stage BODY (declarations injected: see ar_shader.py).
 *
 * Interface:
 *   in  vec3 pos;                          world-space position of a receiver's vertex
 *   in  vec3 nor;                          its world-space normal
 *   uniform mat4 ModelViewProjectionMatrix;
 *   out vec3 v_pos;                        world position for the fragment stage
 *   out vec3 v_nor;                        world normal
 */
void main()
{
  v_pos = pos;
  v_nor = nor;
  gl_Position = ModelViewProjectionMatrix * vec4(pos, 1.0);
}
