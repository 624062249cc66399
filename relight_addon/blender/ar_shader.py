# SPDX-License-Identifier: GPL-3.0-or-later
"""The viewport's sphere-shadow shader under an environment (AR mode): its GLSL stage bodies
(shaders/ar_shadow_{vert,frag}.glsl) and their interface, listed once, as overlay.py does for
the overlay: Blender's create-info (gpu.types.GPUShaderCreateInfo) injects these declarations;
standalone_glsl() makes a complete "#version 330 core" shader of them for the tests
(glslangValidator, and moderngl on an EGL context).  Values come from
core/ar/shader_data.py (shadow_uniforms, shadow_textures); the numpy twin of the maths is
core/ar/env_shadow.py.  No gpu import here: the draw handler (the lead's) builds the shader.

In Blender the array uniforms (spheres, light_dir, light_rad, cap_angles) exceed the push-
constant budget of some backends: declare them in a uniform buffer there (the body reads the
same names).
"""
import os

SHADER_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "shaders")
FILES = {"vert": os.path.join(SHADER_DIR, "ar_shadow_vert.glsl"),
         "frag": os.path.join(SHADER_DIR, "ar_shadow_frag.glsl")}

# The sizes are the twin's: core/ar/shader_data.MAX_SPHERES, main_light.MAX_LIGHTS,
# len(cap_filter.CAP_ANGLES) (a test checks them against the GLSL constants).
MAX_SPHERES, MAX_LIGHTS, N_CAP = 128, 4, 10
VERTEX_INPUTS = ((0, "VEC3", "pos"), (1, "VEC3", "nor"))
PUSH_CONSTANTS = (("MAT4", "ModelViewProjectionMatrix", 0), ("VEC4", "spheres", MAX_SPHERES),
                  ("INT", "n_spheres", 0), ("VEC4", "hull", 0),
                  ("VEC4", "light_dir", MAX_LIGHTS), ("VEC4", "light_rad", MAX_LIGHTS),
                  ("INT", "n_lights", 0), ("FLOAT", "e_floor", 0),
                  ("FLOAT", "cap_angles", N_CAP))
SAMPLERS = ((0, "FLOAT_2D", "irradiance_map"), (1, "FLOAT_2D_ARRAY", "cap_tables"))
VARYINGS = (("VEC3", "v_pos"), ("VEC3", "v_nor"))
FRAGMENT_OUTPUTS = ((0, "VEC4", "FragColor"),)

_GLSL = {"FLOAT": "float", "INT": "int", "VEC3": "vec3", "VEC4": "vec4", "MAT4": "mat4",
         "FLOAT_2D": "sampler2D", "FLOAT_2D_ARRAY": "sampler2DArray"}


def read_body(stage):
    """The GLSL body of ``stage`` ('vert' or 'frag') as Blender consumes it."""
    with open(FILES[stage], encoding="utf-8") as f:
        return f.read()


def standalone_glsl(stage):
    """A complete GLSL 330 core shader: version + the declarations + the body."""
    lines = ["#version 330 core"]
    for t, name, size in PUSH_CONSTANTS:
        lines.append(f"uniform {_GLSL[t]} {name}{f'[{size}]' if size else ''};")
    if stage == "vert":
        lines += [f"layout(location = {i}) in {_GLSL[t]} {n};" for i, t, n in VERTEX_INPUTS]
        lines += [f"out {_GLSL[t]} {n};" for t, n in VARYINGS]
    elif stage == "frag":
        lines += [f"uniform {_GLSL[t]} {n};" for _, t, n in SAMPLERS]
        lines += [f"in {_GLSL[t]} {n};" for t, n in VARYINGS]
        lines += [f"layout(location = {i}) out {_GLSL[t]} {n};" for i, t, n in FRAGMENT_OUTPUTS]
    else:
        raise ValueError(stage)
    lines.append("#line 1")
    return "\n".join(lines) + "\n" + read_body(stage)
