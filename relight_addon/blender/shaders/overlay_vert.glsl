/* Relight element overlay: vertex stage BODY (see overlay_frag.glsl for the colour map).
 *
 * This file holds only the body.  Blender's gpu.types.GPUShaderCreateInfo declares the
 * interface and gpu.shader.create_from_info() prepends it; the declarations live once, in
 * relight_addon/blender/overlay.py (VERTEX_INPUTS, PUSH_CONSTANTS, VARYINGS, FRAGMENT_OUTPUTS),
 * and overlay.standalone_glsl() wraps a body into a complete "#version 330 core" shader that
 * tests/test_overlay_shaders.py compiles with glslangValidator.
 *
 * Interface (declared by the create-info / the standalone wrapper):
 *   in  vec3  pos;                        world-space corner of a leaf element
 *   in  float value;                      one scalar per element (B/D ratio or visibility type)
 *   uniform mat4 ModelViewProjectionMatrix;
 *   out float v_value;
 */
void main()
{
  v_value = value;
  gl_Position = ModelViewProjectionMatrix * vec4(pos, 1.0);
}
