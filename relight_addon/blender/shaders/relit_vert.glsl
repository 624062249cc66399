/* Relight relit preview: vertex stage BODY (declarations injected: see relit_shader.py).
 *
 * Interface:
 *   in  vec3 pos;                          world-space position of a relit surface's vertex
 *   in  vec2 uv;                           its texture coordinates (the relit material's)
 *   uniform mat4 ModelViewProjectionMatrix;
 *   out vec3 v_pos;                        world position for the fragment stage
 *   out vec2 v_uv;
 */
void main()
{
  v_pos = pos;
  v_uv = uv;
  gl_Position = ModelViewProjectionMatrix * vec4(pos, 1.0);
}
