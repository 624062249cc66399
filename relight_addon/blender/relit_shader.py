# SPDX-License-Identifier: GPL-3.0-or-later
"""The viewport's relit-preview shader: its GLSL stage bodies (shaders/relit_{vert,frag}.glsl,
after shaders/sphere_lamp.glsl) and their interface, as ar_shader.py lists the AR shader's
(ar_shader.standalone_glsl and create_info take this module).  Values come from
core/display/relit.py (pack_uniforms), which is also the numpy twin of the maths.  No gpu
import here: relit_draw.py builds the shader.
"""
import os

from ..core.display.relit import MAX_LAMPS, MAX_OBJECTS, MAX_SPHERES

SHADER_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "shaders")
FILES = {"vert": (os.path.join(SHADER_DIR, "relit_vert.glsl"),),
         "frag": (os.path.join(SHADER_DIR, "sphere_lamp.glsl"),
                  os.path.join(SHADER_DIR, "relit_frag.glsl"))}
VERTEX_INPUTS = ((0, "VEC3", "pos"), (1, "VEC2", "uv"))
PUSH_CONSTANTS = (("MAT4", "ModelViewProjectionMatrix", 0), ("VEC4", "lamps", MAX_LAMPS),
                  ("VEC4", "lamp_scale", MAX_LAMPS), ("INT", "n_lamps", 0),
                  ("VEC4", "spheres", MAX_SPHERES),
                  ("VEC4", "hulls", MAX_OBJECTS), ("VEC4", "bounds", MAX_OBJECTS),
                  ("INT", "object_end", MAX_OBJECTS),
                  ("INT", "n_objects", 0))
SAMPLERS = ((0, "FLOAT_2D", "t_image"), (1, "FLOAT_2D_ARRAY", "maps"))
VARYINGS = (("VEC3", "v_pos"), ("VEC2", "v_uv"))
FRAGMENT_OUTPUTS = ((0, "VEC4", "FragColor"),)


def standalone_glsl(stage):
    from . import ar_shader
    import sys
    return ar_shader.standalone_glsl(stage, sys.modules[__name__])


def create_info():
    from . import ar_shader
    import sys
    return ar_shader.create_info(sys.modules[__name__], "relight_relit_iface")


def read_body(stage):
    from . import ar_shader
    return ar_shader.read_body(stage, FILES)
