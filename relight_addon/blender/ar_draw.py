# SPDX-License-Identifier: GPL-3.0-or-later
"""AR mode's live viewport: a SpaceView3D draw handler that darkens the receivers by the
virtual objects' sphere soft shadows while they are dragged or animated.

The viewport shows the photo as the camera's background image and the receivers as holdouts
(their AR material: ar_write.py), so the photo shows through them; the virtual objects are
drawn by the engine, lit by the World.  This handler draws the receivers' triangles once more,
per virtual object, with the sphere-shadow shader (shaders/ar_shadow_*.glsl, interface in
ar_shader.py, numpy twin core/ar/env_shadow.env_shadow_factor) and multiplicative blending:
the photo x the shadow factor, the render's composite without its compositor.  The spheres,
the silhouette and the lights are uniform arrays read from what Set Up stored (the objects'
shadow groups, the scene's lights and floor, the tables image): a drag changes uniforms,
nothing recompiles, no Update is needed.  What the set hides from itself (receiver_view.py)
is the render's only: the viewport's factor is env_shadow's.

Only with a UI: :func:`register_draw` does nothing in background mode (no gpu module there).
:func:`frame_data` (no gpu) gathers one frame's arrays; the tests check it.
"""
from __future__ import annotations

import numpy as np

from . import ar_nodes, draw_handlers, ids

# the handle and the GPU objects the handler made (made once, dropped when it is removed)
cache = {"handle": None, "shader": None, "batch": None, "batch_key": None,
         "textures": None, "tables_key": None, "failed": None}


def _ar_state(scene):
    st = scene.get("relight_ar")
    return st.to_dict() if hasattr(st, "to_dict") else None


def receiver_key(scene, st):
    """What the receivers' batch depends on (cheap: names, transforms, geometry keys)."""
    out = []
    for name in st.get("receivers", ()):
        obj = scene.objects.get(name)
        if obj is None or obj.type != "MESH":
            continue
        out.append((name, tuple(round(x, 6) for row in obj.matrix_world for x in row),
                    draw_handlers.geometry_key(obj)))
    return tuple(out)


def receiver_arrays(scene, st, depsgraph):
    """(positions (3 t, 3), normals (3 t, 3)) float32: the receivers' world triangles, each
    vertex with its face's normal."""
    from .sphere_nodes import object_triangles
    tris = []
    for name in st.get("receivers", ()):
        obj = scene.objects.get(name)
        if obj is None:
            continue
        m = np.array(obj.evaluated_get(depsgraph).matrix_world, float)
        t = object_triangles(obj, depsgraph)
        if len(t):
            tris.append(t @ m[:3, :3].T + m[:3, 3])
    if not tris:
        return np.zeros((0, 3), np.float32), np.zeros((0, 3), np.float32)
    tri = np.concatenate(tris)
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    return (tri.reshape(-1, 3).astype(np.float32),
            np.repeat(n, 3, axis=0).astype(np.float32))


def object_spheres(obj, group):
    """(centres (m, 3), radii (m,), hull (centre, radius)) of ``obj``'s fitted spheres in world
    space now, as its shadow group's drivers place them (the matrix's rotation and location,
    the radii times the mean scale)."""
    a = ids.array(group.get("relight_ar_spheres", [])).reshape(-1, 4)
    h = np.asarray(list(group.get("relight_ar_hull", [0, 0, 0, 0])), float)
    m = np.array(obj.matrix_world, float)
    scale = float(np.mean(obj.matrix_world.to_scale()))
    return (a[:, :3] @ m[:3, :3].T + m[:3, 3], a[:, 3] * scale,
            (m[:3, :3] @ h[:3] + m[:3, 3], h[3] * scale))


def frame_data(scene):
    """One frame's uniforms: [(object name, shader_data.pack_uniforms dict)] of the virtual
    objects Set Up stored (those still in the scene and shown), or [] when the scene is not
    set up for AR."""
    from ..core.ar.shader_data import pack_uniforms
    st = _ar_state(scene)
    key = ids.scene_key(scene)
    if st is None or key is None:
        return []
    lights = [(ids.array(r["direction"]), float(r["half_angle"]),
               ids.array(r["radiance"])) for r in st.get("lights", [])]
    out = []
    for name, group in sorted(ar_nodes.shadow_groups(key).items()):
        obj = scene.objects.get(name)
        if obj is None or not obj.visible_get():
            continue
        centres, radii, hull = object_spheres(obj, group)
        out.append((name, pack_uniforms(centres, radii, hull, lights, st.get("floor", 0.0))))
    return out


def table_textures(st):
    """{sampler name: float32 array} from the stored tables image, or None without it."""
    import bpy
    from ..core.ar.shader_data import textures_from_tables
    img = bpy.data.images.get(ar_nodes.TABLES_IMAGE)
    if img is None or "bands" not in st:
        return None
    w, h = img.size
    px = np.empty(w * h * img.channels, np.float32)
    img.pixels.foreach_get(px)
    return textures_from_tables(px.reshape(h, w, img.channels), int(st["bands"]),
                                int(st["rows"]))


# -- gpu (only reached with a UI) ---------------------------------------------------------------

def shader_create_info():
    from . import ar_shader
    return ar_shader.create_info()


def _texture(array, layers=0):
    import gpu
    a = np.asarray(array, np.float32)
    rgba = np.concatenate([a, np.ones(a.shape[:-1] + (1,), np.float32)], axis=-1)
    h, w = rgba.shape[-3], rgba.shape[-2]
    return gpu.types.GPUTexture((w, h), layers=layers, format="RGBA32F",
                                data=draw_handlers.float_buffer(rgba))


def _set_uniforms(shader, u):
    for name, length, count in (("spheres", 4, len(u["spheres"])),
                                ("light_dir", 4, len(u["light_dir"])),
                                ("light_rad", 4, len(u["light_rad"])),
                                ("cap_angles", 1, len(u["cap_angles"]))):
        shader.uniform_vector_float(shader.uniform_from_name(name),
                                    draw_handlers.float_buffer(u[name]), length, count)
    shader.uniform_int("n_spheres", int(u["n_spheres"]))
    shader.uniform_int("n_lights", int(u["n_lights"]))
    shader.uniform_float("hull", [float(x) for x in u["hull"]])
    shader.uniform_float("e_floor", float(u["e_floor"]))


def draw_frame(context=None):
    """One frame of the handler in ``context`` (bpy.context: the region being drawn)."""
    import bpy
    import gpu
    from gpu_extras.batch import batch_for_shader
    context = bpy.context if context is None else context
    scene = context.scene
    region_data = context.region_data
    st = _ar_state(scene) if scene is not None else None
    if st is None or region_data is None:
        return
    objects = frame_data(scene)
    if not objects:
        return
    if cache["shader"] is None:
        cache["shader"] = gpu.shader.create_from_info(shader_create_info())
    shader = cache["shader"]
    key = receiver_key(scene, st)
    if cache["batch"] is None or cache["batch_key"] != key:
        pos, nor = receiver_arrays(scene, st, context.evaluated_depsgraph_get())
        if len(pos) == 0:
            return
        cache["batch"] = batch_for_shader(shader, "TRIS", {"pos": draw_handlers.vertex_array(pos),
                                                            "nor": draw_handlers.vertex_array(nor)})
        cache["batch_key"] = key
    tables_key = (st.get("env_hash"), st.get("bands"), st.get("rows"))
    if cache["textures"] is None or cache["tables_key"] != tables_key:
        tex = table_textures(st)
        if tex is None:
            return
        cache["textures"] = (_texture(tex["irradiance_map"]),
                              _texture(tex["cap_tables"], layers=len(tex["cap_tables"])))
        cache["tables_key"] = tables_key
    irr, caps = cache["textures"]
    gpu.state.blend_set("MULTIPLY")
    gpu.state.depth_test_set("LESS_EQUAL")
    gpu.state.depth_mask_set(False)
    try:
        shader.bind()
        shader.uniform_float("ModelViewProjectionMatrix", region_data.perspective_matrix)
        shader.uniform_sampler("irradiance_map", irr)
        shader.uniform_sampler("cap_tables", caps)
        for _, u in objects:
            _set_uniforms(shader, u)
            cache["batch"].draw(shader)
    finally:
        gpu.state.depth_mask_set(True)
        gpu.state.depth_test_set("NONE")
        gpu.state.blend_set("NONE")


def retry():
    """Draw again after a failure (Set Up or Update wrote new data): from new gpu objects."""
    draw_handlers.retry(cache, batch=None, batch_key=None, textures=None, tables_key=None)


def is_registered():
    return cache["handle"] is not None


def register_draw():
    """Install the draw handler; False (and nothing done) in background mode."""
    return draw_handlers.install(cache, draw_handlers.guarded(cache, draw_frame, "the AR viewport shadows"))


def unregister_draw():
    """Remove the draw handler (if any) and drop the gpu objects."""
    draw_handlers.remove(cache, shader=None, batch=None, batch_key=None, textures=None, tables_key=None)
