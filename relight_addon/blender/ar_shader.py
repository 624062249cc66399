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
import sys

SHADER_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "shaders")
FILES = {"vert": (os.path.join(SHADER_DIR, "ar_shadow_vert.glsl"),),
         "frag": (os.path.join(SHADER_DIR, "sphere_lamp.glsl"),
                  os.path.join(SHADER_DIR, "ar_shadow_frag.glsl"))}

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

_GLSL = {"FLOAT": "float", "INT": "int", "VEC2": "vec2", "VEC3": "vec3", "VEC4": "vec4",
         "MAT4": "mat4",
         "FLOAT_2D": "sampler2D", "FLOAT_2D_ARRAY": "sampler2DArray"}


def read_body(stage, files=None):
    """The GLSL body of ``stage`` ('vert' or 'frag') as Blender consumes it: its files (``files``:
    {stage: paths}, this shader's by default) one after the other."""
    out = []
    for path in (files or FILES)[stage]:
        with open(path, encoding="utf-8") as f:
            out.append(f.read())
    return "\n".join(out)


def standalone_glsl(stage, interface=None):
    """A complete GLSL 330 core shader: version + the declarations + the body.  ``interface``:
    a module with this one's FILES, PUSH_CONSTANTS, VERTEX_INPUTS, SAMPLERS, VARYINGS and
    FRAGMENT_OUTPUTS (relit_shader), this one by default."""
    m = interface or sys.modules[__name__]
    lines = ["#version 330 core"]
    for t, name, size in m.PUSH_CONSTANTS:
        lines.append(f"uniform {_GLSL[t]} {name}{f'[{size}]' if size else ''};")
    if stage == "vert":
        lines += [f"layout(location = {i}) in {_GLSL[t]} {n};" for i, t, n in m.VERTEX_INPUTS]
        lines += [f"out {_GLSL[t]} {n};" for t, n in m.VARYINGS]
    elif stage == "frag":
        lines += [f"uniform {_GLSL[t]} {n};" for _, t, n in m.SAMPLERS]
        lines += [f"in {_GLSL[t]} {n};" for t, n in m.VARYINGS]
        lines += [f"layout(location = {i}) out {_GLSL[t]} {n};"
                  for i, t, n in m.FRAGMENT_OUTPUTS]
    else:
        raise ValueError(stage)
    lines.append("#line 1")
    return "\n".join(lines) + "\n" + read_body(stage, m.FILES)


def create_info(interface=None, name="relight_ar_iface"):
    """Blender's gpu.types.GPUShaderCreateInfo of ``interface`` (this shader by default)."""
    import gpu
    m = interface or sys.modules[__name__]
    info = gpu.types.GPUShaderCreateInfo()
    for slot, typ, nm in m.VERTEX_INPUTS:
        info.vertex_in(slot, typ, nm)
    for typ, nm, size in m.PUSH_CONSTANTS:
        info.push_constant(typ, nm, size)
    for slot, typ, nm in m.SAMPLERS:
        info.sampler(slot, typ, nm)
    iface = gpu.types.GPUStageInterfaceInfo(name)
    for typ, nm in m.VARYINGS:
        iface.smooth(typ, nm)
    info.vertex_out(iface)
    for slot, typ, nm in m.FRAGMENT_OUTPUTS:
        info.fragment_out(slot, typ, nm)
    info.vertex_source(read_body("vert", m.FILES))
    info.fragment_source(read_body("frag", m.FILES))
    return info
