# SPDX-License-Identifier: GPL-3.0-or-later
"""Relight mode's live viewport preview: a SpaceView3D draw handler that draws the relit
surfaces as their materials compute them, T x sum_l s_l M_l (1 - a_l (1 - V_l)), with the
moving objects' sphere shadows, in Solid shading.

Material Preview and Rendered shading show the relit materials themselves (EEVEE compiles them,
its shadow maps or spheres give the moving shadows).  Solid shading compiles nothing: there this
handler draws each relit object's triangles once more over Blender's own drawing with the
relit-preview shader (shaders/relit_*.glsl, interface in relit_shader.py, numpy twin
core/display/relit.py): T and the lamps' maps as textures, the lamps' scales (the materials'
"I" and "C" nodes, which their drivers keep up to date), the lamps' positions (the lamp groups'
driven values) and the moving objects' spheres (their sphere groups, carried by the objects'
transforms) as uniform arrays.  A drag, a keyframe, a dimmed lamp change uniforms: nothing
recompiles, no Update is needed.  The settled shadows (sphere_nodes: what the materials show
while the objects stand where Update traced them) are the render's only: the preview shows the
spheres' shadow everywhere.  UVs: the T node's UV Map node, else the mesh's active render UV
map (a Mapping node between them is not followed).

Only with a UI: :func:`register_draw` does nothing in background mode (no gpu module there);
:func:`frame_data` and :func:`mesh_arrays` (no gpu) gather what a frame draws, for the tests.
Scene setting: ``scene.relight.relit_preview``.
"""
from __future__ import annotations

import numpy as np

from ..core.display.relit import MAX_LAMPS, pack_uniforms
from . import draw_handlers, ids

cache = {"handle": None, "shader": None, "batches": {}, "textures": {}, "failed": None,
         "last_texture_key": None}


# image node extension -> GPUTexture extend mode
_EXTEND = {"REPEAT": "REPEAT", "EXTEND": "EXTEND", "CLIP": "CLAMP_TO_BORDER",
           "MIRROR": "MIRRORED_REPEAT"}


def material_inputs(mat):
    """{"t": T's image, "uv": its UV map name ("" the active one), "lamps": [(lamp name, map
    image, scale (3,))], "filter": whether T is sampled linearly, "extend": the GPUTexture
    extend mode of its extension} of relit material ``mat`` (write.py's nodes), or None."""
    from .write import MAP_PREFIX, T_NODE
    nt = mat.node_tree
    t = nt.nodes.get(T_NODE) if nt is not None else None
    if t is None or t.image is None:
        return None
    uv = ""
    # the preview samples as the T node does (the maps' nodes copy its settings)
    use_filter = t.interpolation != "Closest"
    extend = _EXTEND.get(t.extension, "REPEAT")
    if t.inputs["Vector"].is_linked:
        src = t.inputs["Vector"].links[0].from_node
        if src.bl_idname == "ShaderNodeUVMap":
            uv = src.uv_map
    lamps = []
    for node in nt.nodes:
        if not node.name.startswith(MAP_PREFIX) or node.image is None:
            continue
        name = node.name[len(MAP_PREFIX):]
        scale = np.ones(3)
        i_node = nt.nodes.get(f"I {name}")
        if i_node is not None:
            scale *= float(i_node.outputs[0].default_value)
        c_node = nt.nodes.get(f"C {name}")
        if c_node is not None:
            scale *= np.array([float(c_node.inputs[k].default_value) for k in range(3)])
        lamps.append((name, node.image, scale))
    return {"t": t.image, "uv": uv, "lamps": lamps[:MAX_LAMPS], "filter": use_filter,
            "extend": extend}


def lamp_places(key):
    """{lamp name: (world position (3,), radius)} from the lamp groups' driven values."""
    from .sphere_nodes import lamp_groups
    out = {}
    for name, ng in lamp_groups(key).items():
        pos = next((n for n in ng.nodes if n.bl_idname == "ShaderNodeCombineXYZ"), None)
        rad = next((n for n in ng.nodes if n.bl_idname == "ShaderNodeValue"), None)
        if pos is None or rad is None:
            continue
        out[name] = (np.array([float(pos.inputs[k].default_value) for k in range(3)]),
                     float(rad.outputs[0].default_value))
    return out


def moving_spheres(scene, key):
    """[(centres (m, 3), radii (m,), hull (centre, radius) or None)] in world space of the
    scene's shown moving objects (their sphere groups: own frame, carried by the transform, the
    radii times the mean scale, as the groups evaluate them)."""
    from .sphere_nodes import group_spheres, sphere_groups
    out = []
    for name, ng in sorted(sphere_groups(key).items()):
        obj = scene.objects.get(name)
        if obj is None or not obj.visible_get():
            continue
        c, r, hull = group_spheres(ng)
        m = np.array(obj.matrix_world, float)
        s = float(np.mean(obj.matrix_world.to_scale()))
        h = None if hull is None else (m[:3, :3] @ hull[0] + m[:3, 3], hull[1] * s)
        out.append((c @ m[:3, :3].T + m[:3, 3], r * s, h))
    return out


def relit_slots(scene, key, view=None):
    """[(object, slot index, material)] of the scene's shown meshes' relit material slots
    (``view``: a 3D View space, whose local view counts)."""
    out = []
    for obj in scene.objects:
        if obj.type != "MESH" or not (obj.visible_get(viewport=view) if view is not None
                                      else obj.visible_get()):
            continue
        for i, slot in enumerate(obj.material_slots):
            if slot.material is not None and ids.ours(slot.material, key):
                out.append((obj, i, slot.material))
    return out


def frame_data(scene, view=None):
    """One frame's draws: [(object name, slot index, material name, pack_uniforms dict)], or []
    when the scene has no relit material.  A material without a map is not drawn (Solid
    shading shows through); a lamp without its lamp group (no place to shadow from) is drawn
    unshadowed (radius -1)."""
    key = ids.scene_key(scene)
    if key is None:
        return []
    places = lamp_places(key)
    objects = moving_spheres(scene, key)
    out = []
    for obj, i, mat in relit_slots(scene, key, view):
        inputs = material_inputs(mat)
        if inputs is None or not inputs["lamps"]:
            continue
        lamps = [places.get(name, (np.zeros(3), -1.0)) for name, _, _ in inputs["lamps"]]
        scales = [s for _, _, s in inputs["lamps"]]
        out.append((obj.name, i, mat.name, pack_uniforms(lamps, scales, objects)))
    return out


def batch_key(obj, slot, uv_name):
    """What the triangles of ``obj``'s slot ``slot`` drawn with UV map ``uv_name`` depend on:
    a change of it makes the batch again (its transform, its geometry: draw_handlers)."""
    return (obj.name, slot, tuple(round(x, 6) for row in obj.matrix_world for x in row),
            draw_handlers.geometry_key(obj), uv_name)


def mesh_arrays(obj, slot, uv_name, depsgraph):
    """(positions (3 t, 3), uvs (3 t, 2)) float32 of ``obj``'s evaluated triangles of material
    slot ``slot``, world space, with UV map ``uv_name`` ("" the active render one)."""
    ev = obj.evaluated_get(depsgraph)
    me = ev.to_mesh()
    try:
        me.calc_loop_triangles()
        nt = len(me.loop_triangles)
        co = np.empty(len(me.vertices) * 3, np.float32)
        me.vertices.foreach_get("co", co)
        verts = np.empty(nt * 3, np.int32)
        me.loop_triangles.foreach_get("vertices", verts)
        loops = np.empty(nt * 3, np.int32)
        me.loop_triangles.foreach_get("loops", loops)
        mats = np.empty(nt, np.int32)
        me.loop_triangles.foreach_get("material_index", mats)
        layers = me.uv_layers
        layer = layers.get(uv_name) if uv_name else None
        if layer is None:
            layer = next((u for u in layers if u.active_render), layers.active)
        uv = np.zeros(len(me.loops) * 2, np.float32)
        if layer is not None:
            layer.data.foreach_get("uv", uv)
    finally:
        ev.to_mesh_clear()
    keep = np.repeat(mats == slot, 3)
    m = np.array(ev.matrix_world, float)
    pos = co.reshape(-1, 3)[verts[keep]].astype(np.float64) @ m[:3, :3].T + m[:3, 3]
    return pos.astype(np.float32), uv.reshape(-1, 2)[loops[keep]]


# -- gpu (only reached with a UI) ---------------------------------------------------------------

def _pixels(img):
    px = np.empty(img.size[0] * img.size[1] * img.channels, np.float32)
    img.pixels.foreach_get(px)
    px = px.reshape(img.size[1], img.size[0], img.channels)
    if img.channels == 4:
        return px
    out = np.ones(px.shape[:2] + (4,), np.float32)
    out[..., :min(3, img.channels)] = px[..., :3]
    return out


def _textures(inputs):
    """(T texture, maps array texture) of a material's images, cached by the images' identity
    (an Update writes new images), sampled as the material's image nodes interpolate them."""
    import gpu
    from .images import CONTENT
    key = tuple((img.name, img.get(CONTENT), tuple(img.size))
                for img in [inputs["t"], *(im for _, im, _ in inputs["lamps"])])
    key += (inputs["filter"], inputs["extend"])
    cache["last_texture_key"] = key
    if key in cache["textures"]:
        return cache["textures"][key]
    t = _pixels(inputs["t"])
    h, w = t.shape[:2]
    layers = [_pixels(img) for _, img, _ in inputs["lamps"]] or [np.zeros((h, w, 4), np.float32)]
    shape = layers[0].shape
    stack = np.stack([x if x.shape == shape else np.zeros(shape, np.float32) for x in layers])
    t_tex = gpu.types.GPUTexture((w, h), format="RGBA32F", data=draw_handlers.float_buffer(t))
    m_tex = gpu.types.GPUTexture((shape[1], shape[0]), layers=len(stack), format="RGBA32F",
                                 data=draw_handlers.float_buffer(stack))
    for tex in (t_tex, m_tex):
        if hasattr(tex, "filter_mode"):     # Blender 5.0+ (4.5's keep their default sampling)
            tex.filter_mode(inputs["filter"])
            tex.extend_mode(inputs["extend"])
    cache["textures"][key] = (t_tex, m_tex)
    return t_tex, m_tex


def _set_uniforms(shader, u):
    for name, count in (("lamps", len(u["lamps"])), ("lamp_scale", len(u["lamp_scale"])),
                        ("spheres", len(u["spheres"])), ("hulls", len(u["hulls"])),
                        ("bounds", len(u["bounds"]))):
        shader.uniform_vector_float(shader.uniform_from_name(name),
                                    draw_handlers.float_buffer(u[name]), 4, count)
    ends = np.asarray(u["object_end"], np.int32)
    shader.uniform_vector_int(shader.uniform_from_name("object_end"),
                              draw_handlers.int_buffer(ends), 1, ends.size)
    shader.uniform_int("n_lamps", int(u["n_lamps"]))
    shader.uniform_int("n_objects", int(u["n_objects"]))


def draw_frame(context=None):
    """One frame of the handler in ``context`` (bpy.context: the region being drawn)."""
    import bpy
    import gpu
    from gpu_extras.batch import batch_for_shader

    from . import relit_shader
    context = bpy.context if context is None else context
    scene, space = context.scene, context.space_data
    settings = getattr(scene, "relight", None) if scene is not None else None
    if (settings is None or not getattr(settings, "relit_preview", False)
            or context.region_data is None or getattr(space, "shading", None) is None
            or space.shading.type != "SOLID"):
        return
    draws = frame_data(scene, space)
    if not draws:
        return
    if cache["shader"] is None:
        cache["shader"] = gpu.shader.create_from_info(relit_shader.create_info())
    shader = cache["shader"]
    depsgraph = context.evaluated_depsgraph_get()
    gpu.state.depth_test_set("LESS_EQUAL")
    used, used_textures = set(), set()
    try:
        shader.bind()
        shader.uniform_float("ModelViewProjectionMatrix", context.region_data.perspective_matrix)
        for name, slot, mat_name, u in draws:
            obj, mat = scene.objects[name], bpy.data.materials[mat_name]
            inputs = material_inputs(mat)
            bkey = batch_key(obj, slot, inputs["uv"])
            batch = cache["batches"].get((name, slot))
            if batch is None or batch[0] != bkey:
                pos, uv = mesh_arrays(obj, slot, inputs["uv"], depsgraph)
                # a slot no face uses (the relit copy is on every slot of its material) draws
                # nothing: an empty array has no attribute length for batch_for_shader
                batch = (bkey, batch_for_shader(shader, "TRIS",
                                                {"pos": draw_handlers.vertex_array(pos),
                                                 "uv": draw_handlers.vertex_array(uv)})
                         if len(pos) else None)
                cache["batches"][(name, slot)] = batch
            used.add((name, slot))
            if batch[1] is None:
                continue
            t_tex, m_tex = _textures(inputs)
            used_textures.add(cache["last_texture_key"])
            shader.uniform_sampler("t_image", t_tex)
            shader.uniform_sampler("maps", m_tex)
            _set_uniforms(shader, u)
            batch[1].draw(shader)
    finally:
        gpu.state.depth_test_set("NONE")
    # what no longer draws (a deleted object, images an Update replaced) is let go
    for k in [k for k in cache["batches"] if k not in used]:
        del cache["batches"][k]
    for k in [k for k in cache["textures"] if k not in used_textures]:
        del cache["textures"][k]


def retry():
    """Draw again after a failure (the setting toggled): from new batches and textures."""
    draw_handlers.retry(cache, batches={}, textures={})


def failure():
    """Why the preview stopped (one line), or None."""
    return cache["failed"]


def is_registered():
    return cache["handle"] is not None


def register_draw():
    """Install the draw handler; False (and nothing done) in background mode."""
    return draw_handlers.install(cache, draw_handlers.guarded(cache, draw_frame, "the relit viewport preview"))


def unregister_draw():
    """Remove the draw handler (if any) and drop the gpu objects."""
    draw_handlers.remove(cache, shader=None, batches={}, textures={})
