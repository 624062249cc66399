/* Relight AR sphere shadows: vertex stage BODY (declarations injected: see ar_shader.py).
 *
 * Interface:
 *   in  vec3 pos;                          world-space position of a receiver's vertex
 *   in  vec3 nor;                          its world-space normal
 *   uniform mat4 ModelViewProjectionMatrix;
 *   out vec3 v_pos;                        world position for the fragment stage
 *   out vec3 v_nor;                        world normal
 */
/* The receivers are drawn again over Blender's own drawing of them, whose depths differ from
 * these in their last bits: pulled towards the camera as relit_vert.glsl says why and how far. */
const float DEPTH_PULL = 2e-6;

void main()
{
  v_pos = pos;
  v_nor = nor;
  gl_Position = ModelViewProjectionMatrix * vec4(pos, 1.0);
  gl_Position.z -= DEPTH_PULL * gl_Position.w;
}
