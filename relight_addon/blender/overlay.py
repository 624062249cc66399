"""Viewport overlay of the radiosity leaf elements (SpaceView3D draw handler, gpu module).

Only active with a UI: in background mode (``bpy.app.background``) the gpu module has no
context (``gpu.texture.from_image`` even crashes there), so register_overlay() is a no-op that
returns False, and nothing here imports ``gpu`` at module level: every gpu import is inside a
function reached only when not in background mode.

The shader is built from relight_addon/blender/shaders/overlay_{vert,frag}.glsl.  Those files
hold only the stage BODIES: Blender's create-info API (gpu.types.GPUShaderCreateInfo +
gpu.shader.create_from_info) injects the declarations, which are listed once below
(VERTEX_INPUTS, PUSH_CONSTANTS, VARYINGS, FRAGMENT_OUTPUTS).  standalone_glsl() turns a body
into a complete "#version 330 core" shader from the same lists, which
tests/test_overlay_shaders.py compiles with glslangValidator.  The colour maps' numpy twin is
relight_addon/core/display/colormap.py.

Usage (the caller, e.g. after a precompute):
    set_overlay_data(corners, values, mode=MODE_RATIO)   # corners (n, 4, 3), values (n,)
    register_overlay()                                   # True if a handler is installed
    unregister_overlay()
"""
import os

import numpy as np

from ..core.display.colormap import MODE_RATIO, MODE_VISIBILITY  # noqa: F401 (re-export)

SHADER_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "shaders")
VERTEX_FILE = os.path.join(SHADER_DIR, "overlay_vert.glsl")
FRAGMENT_FILE = os.path.join(SHADER_DIR, "overlay_frag.glsl")

# The shader interface, in GPUShaderCreateInfo type names.
VERTEX_INPUTS = ((0, "VEC3", "pos"), (1, "FLOAT", "value"))
PUSH_CONSTANTS = (("MAT4", "ModelViewProjectionMatrix"), ("FLOAT", "alpha"), ("INT", "mode"))
VARYINGS = (("FLOAT", "v_value"),)  # smooth; the value is constant over an element anyway
FRAGMENT_OUTPUTS = ((0, "VEC4", "FragColor"),)

_GLSL_TYPES = {"FLOAT": "float", "INT": "int", "VEC2": "vec2", "VEC3": "vec3", "VEC4": "vec4",
               "MAT4": "mat4"}

# Module state: the data to draw, the lazily built shader/batch, and the handler.
_state = {
    "handle": None,
    "shader": None,
    "batch": None,
    "positions": None,   # (6n, 3) float32
    "values": None,      # (6n,) float32
    "mode": MODE_RATIO,
    "alpha": 0.6,
    "lines": None,       # (2m, 3) float32 link segments, drawn with a builtin shader
    "line_batch": None,
}


def read_body(stage):
    """The GLSL body of ``stage`` ('vert' or 'frag') as Blender consumes it."""
    path = {"vert": VERTEX_FILE, "frag": FRAGMENT_FILE}[stage]
    with open(path, encoding="utf-8") as f:
        return f.read()


def standalone_glsl(stage):
    """A complete GLSL 330 core shader: version + the create-info declarations + the body."""
    lines = ["#version 330 core"]
    lines += ["uniform %s %s;" % (_GLSL_TYPES[t], n) for t, n in PUSH_CONSTANTS]
    if stage == "vert":
        lines += ["layout(location = %d) in %s %s;" % (i, _GLSL_TYPES[t], n)
                  for i, t, n in VERTEX_INPUTS]
        lines += ["out %s %s;" % (_GLSL_TYPES[t], n) for t, n in VARYINGS]
    elif stage == "frag":
        lines += ["in %s %s;" % (_GLSL_TYPES[t], n) for t, n in VARYINGS]
        lines += ["layout(location = %d) out %s %s;" % (i, _GLSL_TYPES[t], n)
                  for i, t, n in FRAGMENT_OUTPUTS]
    else:
        raise ValueError(stage)
    lines.append("#line 1")
    return "\n".join(lines) + "\n" + read_body(stage)


def element_triangles(corners, values):
    """Leaf quads (n, 4, 3) + one value each -> two triangles per quad (0,1,2), (0,2,3):
    positions (6n, 3) float32 and per-vertex values (6n,) float32."""
    c = np.asarray(corners, dtype=np.float32).reshape(-1, 4, 3)
    v = np.asarray(values, dtype=np.float32).reshape(-1)
    if v.shape[0] != c.shape[0]:
        raise ValueError("%d elements but %d values" % (c.shape[0], v.shape[0]))
    tri = c[:, [0, 1, 2, 0, 2, 3], :].reshape(-1, 3)
    return np.ascontiguousarray(tri), np.repeat(v, 6)


def set_overlay_data(corners, values, mode=MODE_RATIO, alpha=None):
    """Store the elements to draw (e.g. from the last precompute); no gpu work here."""
    _state["positions"], _state["values"] = element_triangles(corners, values)
    _state["mode"] = int(mode)
    if alpha is not None:
        _state["alpha"] = float(alpha)
    _state["batch"] = None  # rebuilt on the next draw
    _tag_redraw()


def set_link_data(starts, ends):
    """Store link segments (receiver -> source centroids) to draw as lines."""
    a = np.asarray(starts, np.float32).reshape(-1, 3)
    b = np.asarray(ends, np.float32).reshape(-1, 3)
    _state["lines"] = np.ascontiguousarray(np.stack([a, b], axis=1).reshape(-1, 3))
    _state["line_batch"] = None
    _tag_redraw()


def clear_overlay_data():
    _state["positions"] = _state["values"] = _state["batch"] = None
    _state["lines"] = _state["line_batch"] = None
    _tag_redraw()


def is_registered():
    return _state["handle"] is not None


def _tag_redraw():
    import bpy
    if bpy.app.background:
        return
    screen = getattr(bpy.context, "screen", None)
    for area in (screen.areas if screen is not None else ()):
        if area.type == "VIEW_3D":
            area.tag_redraw()


def shader_create_info():
    """The gpu.types.GPUShaderCreateInfo of the overlay shader (no GPU context needed, but
    production code only reaches it with a UI, through the draw callback)."""
    import gpu

    info = gpu.types.GPUShaderCreateInfo()
    for slot, typ, name in VERTEX_INPUTS:
        info.vertex_in(slot, typ, name)
    for typ, name in PUSH_CONSTANTS:
        info.push_constant(typ, name)
    iface = gpu.types.GPUStageInterfaceInfo("relight_overlay_iface")
    for typ, name in VARYINGS:
        iface.smooth(typ, name)
    info.vertex_out(iface)
    for slot, typ, name in FRAGMENT_OUTPUTS:
        info.fragment_out(slot, typ, name)
    info.vertex_source(read_body("vert"))
    info.fragment_source(read_body("frag"))
    return info


def _build_shader():
    import gpu  # only reached with a UI (see register_overlay)

    return gpu.shader.create_from_info(shader_create_info())


def _draw_lines():
    import gpu
    from gpu_extras.batch import batch_for_shader

    shader = gpu.shader.from_builtin("UNIFORM_COLOR")
    if _state["line_batch"] is None:
        _state["line_batch"] = batch_for_shader(shader, "LINES", {"pos": _state["lines"]})
    gpu.state.blend_set("ALPHA")
    try:
        shader.bind()
        shader.uniform_float("color", (1.0, 0.85, 0.2, 0.25))
        _state["line_batch"].draw(shader)
    finally:
        gpu.state.blend_set("NONE")


def _draw():
    """The SpaceView3D POST_VIEW callback."""
    if _state["lines"] is not None and len(_state["lines"]):
        _draw_lines()
    if _state["positions"] is None or len(_state["positions"]) == 0:
        return
    import bpy
    import gpu
    from gpu_extras.batch import batch_for_shader

    region_data = bpy.context.region_data
    if region_data is None:
        return
    if _state["shader"] is None:
        _state["shader"] = _build_shader()
    shader = _state["shader"]
    if _state["batch"] is None:
        _state["batch"] = batch_for_shader(
            shader, "TRIS", {"pos": _state["positions"], "value": _state["values"]})
    gpu.state.blend_set("ALPHA")
    gpu.state.depth_test_set("LESS_EQUAL")
    gpu.state.depth_mask_set(False)
    try:
        shader.bind()
        shader.uniform_float("ModelViewProjectionMatrix", region_data.perspective_matrix)
        shader.uniform_float("alpha", _state["alpha"])
        shader.uniform_int("mode", _state["mode"])
        _state["batch"].draw(shader)
    finally:
        gpu.state.depth_mask_set(True)
        gpu.state.depth_test_set("NONE")
        gpu.state.blend_set("NONE")


def register_overlay():
    """Install the draw handler; False (and nothing done) in background mode."""
    import bpy
    if bpy.app.background:
        return False
    if _state["handle"] is None:
        _state["handle"] = bpy.types.SpaceView3D.draw_handler_add(
            _draw, (), "WINDOW", "POST_VIEW")
    _tag_redraw()
    return True


def unregister_overlay():
    """Remove the draw handler (if any) and drop the gpu objects."""
    import bpy
    handle = _state["handle"]
    _state["handle"] = None
    _state["shader"] = _state["batch"] = None
    if handle is not None:
        bpy.types.SpaceView3D.draw_handler_remove(handle, "WINDOW")
        _tag_redraw()
