/* Relight relit preview: vertex stage BODY (declarations injected: see relit_shader.py).
 *
 * Interface:
 *   in  vec3 pos;                          world-space position of a relit surface's vertex
 *   in  vec2 uv;                           its texture coordinates (the relit material's)
 *   uniform mat4 ModelViewProjectionMatrix;
 *   out vec3 v_pos;                        world position for the fragment stage
 *   out vec2 v_uv;
 */
/* The triangles are Solid shading's own, drawn again: Blender transforms the same vertices
 * with its own float32 matrices, so the two depths differ in their last bits and fight under
 * LESS_EQUAL.  Pulled towards the camera by about 16 steps of a 24-bit depth buffer (2e-6 in
 * clip z is 1e-6 in window depth): 0.1 mm at 1 m and 2.5 mm at 5 m with a 1 cm clip start, so
 * little of what stands on a relit surface is drawn over. */
const float DEPTH_PULL = 2e-6;

void main()
{
  v_pos = pos;
  v_uv = uv;
  gl_Position = ModelViewProjectionMatrix * vec4(pos, 1.0);
  gl_Position.z -= DEPTH_PULL * gl_Position.w;
}
