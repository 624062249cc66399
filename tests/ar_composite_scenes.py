"""The AR composite's test scenes, built in a bpy process (tests and benchmarks/bench_ar_composite.py).

A scene is a photographed set (receivers: a ground plane, a table top on a floor, or a corner of
a floor and two walls; each with a grey, slightly mottled Principled material) under one of the
bundled HDRIs (the World's Environment Texture), seen by a camera at 400 x 300; an object of
tests/ar_scenes.py (a sphere, Suzanne, a chair, a torus; diffuse colours, the torus glossy) is
either in it (the truth) or not (the photo).  :func:`build` makes it in the current file;
:func:`photo_setup` turns the scene without the object into what a user of AR mode has: the
photo as the camera's background image, the object added with the role 'virtual', the
receivers with the role 'receiver'.
"""
from __future__ import annotations

import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
if HERE not in sys.path:
    sys.path.insert(0, HERE)

import ar_scenes  # noqa: E402

RES = (400, 300)
# per scene: camera location, the point it looks at, focal length (mm)
CAMERAS = {"ground": ((0.4, -3.2, 1.7), (0.0, 0.2, 0.25), 35.0),
           "table": ((0.5, -2.6, 2.0), (0.0, 0.1, 0.85), 35.0),
           "corner": ((1.9, -2.4, 1.5), (-0.1, 0.2, 0.35), 30.0)}
TABLE_HEIGHT = 0.75
GROUND_ALBEDO = 0.45      # the set's grey (mottled +-20 %)
GROUND_RADIANCE = 0.25    # linear: what the set's ground shows, as a photo exposed for it
# object: (its placement offset in the scene, its Principled inputs)
MATERIALS = {"sphere": {"Base Color": (0.70, 0.25, 0.20), "Roughness": 0.5},
             "Suzanne": {"Base Color": (0.75, 0.62, 0.30), "Roughness": 0.45},
             "chair": {"Base Color": (0.45, 0.30, 0.18), "Roughness": 0.6},
             "torus": {"Base Color": (0.80, 0.80, 0.85), "Roughness": 0.15,
                       "Metallic": 1.0}}


def _bpy():
    import bpy
    return bpy


def _mesh(name, tri, smooth=True, uvs=None):
    """A mesh object from triangles (t, 3, 3), vertices welded (smooth shading works)."""
    bpy = _bpy()
    v = np.asarray(tri, float).reshape(-1, 3)
    key = np.round(v, 6)
    uniq, inv = np.unique(key, axis=0, return_inverse=True)
    me = bpy.data.meshes.new(name)
    me.from_pydata(uniq.tolist(), [], inv.reshape(-1, 3).tolist())
    if uvs is not None:
        layer = me.uv_layers.new(name="UVMap")
        layer.data.foreach_set("uv", np.asarray(uvs, np.float32).reshape(-1))
    me.validate()
    me.update()
    for p in me.polygons:
        p.use_smooth = smooth
    ob = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(ob)
    return ob


def _principled(name, values):
    bpy = _bpy()
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    for k, val in values.items():
        bsdf.inputs[k].default_value = (*val, 1.0) if isinstance(val, tuple) else val
    return mat


def _zenith_irradiance(image):
    """E(up) of an equirectangular image (its pixels' cosine-weighted sum over the upper
    hemisphere, exact solid angles)."""
    w, h = image.size
    px = np.empty(w * h * image.channels, np.float32)
    image.pixels.foreach_get(px)
    rgb = px.reshape(h, w, image.channels)[::-1, :, :3].astype(np.float64)   # top row first
    lat = np.pi / 2 - np.pi * (np.arange(h) + 0.5) / h
    omega = (2 * np.pi / w) * (np.sin(np.pi / 2 - np.pi * np.arange(h) / h)
                               - np.sin(np.pi / 2 - np.pi * (np.arange(h) + 1) / h))
    lum = np.maximum(rgb, 0) @ np.array([0.2126, 0.7152, 0.0722])
    return float((lum * (np.maximum(np.sin(lat), 0) * omega)[:, None]).sum())


def _ground_material(name, base=GROUND_ALBEDO):
    """Grey with a mild noise mottling (a photo has texture: the projection must be exact)."""
    mat = _principled(name, {"Roughness": 0.9})
    nt = mat.node_tree
    noise = nt.nodes.new("ShaderNodeTexNoise")
    noise.inputs["Scale"].default_value = 6.0
    ramp = nt.nodes.new("ShaderNodeMapRange")
    ramp.inputs["To Min"].default_value = base * 0.8
    ramp.inputs["To Max"].default_value = base * 1.2
    nt.links.new(noise.outputs["Fac"], ramp.inputs["Value"])
    nt.links.new(ramp.outputs["Result"], nt.nodes["Principled BSDF"].inputs["Base Color"])
    return mat


def _quad(name, corners, mat):
    ob = _mesh(name, np.array([[corners[0], corners[1], corners[2]],
                               [corners[0], corners[2], corners[3]]]), smooth=False)
    ob.data.materials.append(mat)
    return ob


def receivers(scene):
    """[(name, corners (4, 3))] of the receivers of ``scene``, counter-clockwise seen from their
    front."""
    if scene == "ground":
        return [("Ground", [(-6, -6, 0), (6, -6, 0), (6, 8, 0), (-6, 8, 0)])]
    if scene == "table":
        h = TABLE_HEIGHT
        return [("Floor", [(-6, -6, 0), (6, -6, 0), (6, 8, 0), (-6, 8, 0)]),
                ("Table top", [(-0.6, -0.4, h), (0.6, -0.4, h), (0.6, 0.4, h), (-0.6, 0.4, h)])]
    if scene == "corner":          # walls behind the object (seen from the camera at -y)
        x0, y1 = -0.6, 0.5
        return [("Floor", [(x0, -4, 0), (4, -4, 0), (4, y1, 0), (x0, y1, 0)]),
                ("Wall X", [(x0, -4, 0), (x0, y1, 0), (x0, y1, 2.5), (x0, -4, 2.5)]),
                ("Wall Y", [(x0, y1, 0), (4, y1, 0), (4, y1, 2.5), (x0, y1, 2.5)])]
    raise ValueError(scene)


def object_triangles(obj_name, scene):
    """The object's triangles where it stands in ``scene`` (world coordinates)."""
    tri = ar_scenes.OBJECTS[obj_name]()
    tri = tri - np.array([0.0, 0.0, 0.0])
    if scene == "table":
        tri = tri * 0.5 + [0.0, 0.0, TABLE_HEIGHT]      # half size on the table top
    return tri


def build(scene, obj_name, hdri, with_object=True, res=RES):
    """The scene in the current (empty) file: receivers, a table's legs (table scene), the World
    environment ``hdri`` (a path), the camera, Cycles settings; the object when
    ``with_object``.  Returns the object (or None)."""
    bpy = _bpy()
    sc = bpy.context.scene
    sc.render.resolution_x, sc.render.resolution_y = res
    sc.render.resolution_percentage = 100
    sc.view_settings.view_transform = "Standard"
    sc.render.engine = "CYCLES"
    sc.cycles.device = "CPU"
    world = bpy.data.worlds.new("World")
    sc.world = world
    world.use_nodes = True
    env = world.node_tree.nodes.new("ShaderNodeTexEnvironment")
    env.image = bpy.data.images.load(hdri, check_existing=True)
    world.node_tree.links.new(env.outputs["Color"],
                              world.node_tree.nodes["Background"].inputs["Color"])
    # exposed as a photo is: the ground plane's radiance about GROUND_RADIANCE
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = \
        GROUND_RADIANCE / (GROUND_ALBEDO * _zenith_irradiance(env.image) / np.pi)
    mat = _ground_material("Ground material")
    for name, corners in receivers(scene):
        _quad(name, corners, mat)["ar_set"] = 1
    if scene == "table":
        wood = _principled("Table legs", {"Base Color": (0.3, 0.2, 0.12), "Roughness": 0.7})
        h = TABLE_HEIGHT
        parts = [ar_scenes.box([-0.6, -0.4, h - 0.04], [0.6, 0.4, h - 0.001])]
        for x in (-0.56, 0.52):
            for y in (-0.36, 0.32):
                parts.append(ar_scenes.box([x, y, 0.0], [x + 0.04, y + 0.04, h - 0.04]))
        legs = _mesh("Table frame", np.concatenate(parts), smooth=False)
        legs.data.materials.append(wood)
        legs["ar_set"] = 1
    loc, target, lens = CAMERAS[scene]
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    sc.collection.objects.link(cam)
    cam.data.lens = lens
    cam.location = loc
    from mathutils import Vector
    cam.rotation_euler = (Vector(target) - Vector(loc)).to_track_quat("-Z", "Y").to_euler()
    sc.camera = cam
    if not with_object:
        return None
    return add_object(obj_name, scene)


def set_objects():
    """The photographed set's objects (what AR mode's receivers stand for)."""
    return [o for o in _bpy().data.objects if o.get("ar_set")]


def add_object(obj_name, scene, tri=None):
    """The object (its triangles where it stands in ``scene``, or ``tri``) with its material."""
    tri = object_triangles(obj_name, scene) if tri is None else tri
    uvs = ar_scenes.suzanne_uvs() if obj_name == "Suzanne" else None
    ob = _mesh(obj_name, tri, smooth=obj_name in ("sphere", "Suzanne", "torus"), uvs=uvs)
    ob.data.materials.append(_principled(f"{obj_name} material", MATERIALS[obj_name]))
    return ob
