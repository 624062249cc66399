# SPDX-License-Identifier: GPL-3.0-or-later
"""The capture tools' side of the bridge: Blender cameras (K both ways, poses, keys),
background photos, images in and out.

Conventions: arrays handed to and from the core are in OpenCV's image order (row 0 at the top)
and linear RGB float32; ``Image.pixels`` is bottom row first, so rows are flipped here and only
here.  Matrices go through ``mathutils.Matrix`` (a plain list of rows assigned to
``matrix_world`` is read as columns).
"""
from __future__ import annotations

import os

import bpy
import mathutils
import numpy as np

from ..core.capture import CaptureError
from ..core.capture.calibration import BlenderCamera, blender_camera, camera_matrix
from .read import image_texels


# ------------------------------------------------------------------------------------------
# Cameras
# ------------------------------------------------------------------------------------------

def render_size(scene) -> tuple:
    r = scene.render
    return (int(r.resolution_x * r.resolution_percentage / 100),
            int(r.resolution_y * r.resolution_percentage / 100))


def camera_of(cam_obj, scene, size=None) -> BlenderCamera:
    """The camera's intrinsics at the render size, or at ``size`` (w, h) of a photo with the
    render's aspect ratio."""
    c = cam_obj.data
    if c.type != "PERSP":
        raise CaptureError(f"Camera '{cam_obj.name}' is not a perspective camera")
    w, h = render_size(scene) if size is None else (int(size[0]), int(size[1]))
    r = scene.render
    return BlenderCamera(c.lens, c.sensor_width, c.sensor_height, c.sensor_fit, c.shift_x,
                         c.shift_y, w, h, r.pixel_aspect_x, r.pixel_aspect_y)


def camera_K(cam_obj, scene, size=None) -> np.ndarray:
    return camera_matrix(camera_of(cam_obj, scene, size))


def frame_matches(scene, size, tolerance=0.01) -> bool:
    """Whether a photo of ``size`` (w, h) has the render frame's shape (pixel aspect included)."""
    w, h = render_size(scene)
    r = scene.render
    frame = (w * r.pixel_aspect_x) / (h * r.pixel_aspect_y)
    photo = (size[0] * r.pixel_aspect_x) / (size[1] * r.pixel_aspect_y)
    return abs(photo / frame - 1.0) <= tolerance


def set_intrinsics(cam_obj, scene, K, image_size) -> BlenderCamera:
    """Lens, sensor fit, shift, the scene's resolution and pixel aspect so that the camera's
    K at ``image_size`` is ``K``; the camera's sensor width is kept."""
    cam = blender_camera(K, image_size[0], image_size[1], cam_obj.data.sensor_width,
                         cam_obj.data.sensor_height)
    c = cam_obj.data
    c.type = "PERSP"
    c.sensor_fit = cam.sensor_fit
    c.lens = cam.lens
    c.shift_x = cam.shift_x
    c.shift_y = cam.shift_y
    r = scene.render
    r.resolution_x, r.resolution_y = cam.width, cam.height
    r.resolution_percentage = 100
    r.pixel_aspect_x, r.pixel_aspect_y = cam.pixel_aspect_x, cam.pixel_aspect_y
    return cam


def matrix_of(obj) -> np.ndarray:
    return np.array(obj.matrix_world, np.float64)


def set_matrix_world(obj, m):
    obj.matrix_world = mathutils.Matrix(np.asarray(m, np.float64).tolist())


def key_path(obj, matrices, frames):
    """One location and rotation key per frame (Blender keeps consecutive Euler angles
    compatible when a matrix is set); interpolation linear between the per-frame keys."""
    rot_path = {"QUATERNION": "rotation_quaternion", "AXIS_ANGLE": "rotation_axis_angle"} \
        .get(obj.rotation_mode, "rotation_euler")
    for m, f in zip(matrices, frames):         # frames of a sequence, not elements
        set_matrix_world(obj, m)
        obj.keyframe_insert("location", frame=int(f))
        obj.keyframe_insert(rot_path, frame=int(f))
    ad = obj.animation_data
    action = ad.action if ad is not None else None
    for fc in fcurves(obj, action):
        if fc.data_path in ("location", rot_path):
            for kp in fc.keyframe_points:      # keys of this object's two channels
                kp.interpolation = "LINEAR"


def fcurves(obj, action):
    """F-curves of ``obj`` in ``action`` (Blender 4.4+ layered actions, or the legacy list)."""
    if action is None:
        return []
    legacy = getattr(action, "fcurves", None)
    if legacy is not None and len(legacy):
        return list(legacy)
    out = []
    slot = getattr(obj.animation_data, "action_slot", None)
    for layer in getattr(action, "layers", ()):
        for strip in layer.strips:
            bag = strip.channelbag(slot) if slot is not None else None
            if bag is not None:
                out += list(bag.fcurves)
    return out


def board_bounds(obj):
    """Local bounding box (min, max) of a board object (its evaluated geometry)."""
    if obj.type != "MESH":
        raise CaptureError(f"The board object '{obj.name}' is not a mesh")
    bb = np.array([tuple(c) for c in obj.bound_box], np.float64)
    lo, hi = bb.min(axis=0), bb.max(axis=0)
    if not np.all(np.isfinite(bb)) or (hi - lo)[0] <= 0 or (hi - lo)[1] <= 0:
        raise CaptureError(f"The board object '{obj.name}' has no extent in its local X and Y")
    if (hi - lo)[2] > 1e-3 * max((hi - lo)[:2]):
        raise CaptureError(f"The board object '{obj.name}' is not a flat plane in its local XY")
    return lo, hi


# ------------------------------------------------------------------------------------------
# Photos and images
# ------------------------------------------------------------------------------------------

def camera_photo(cam_obj):
    """The first enabled background image of a camera that has an image, or None."""
    for bg in cam_obj.data.background_images:
        if bg.source == "IMAGE" and bg.image is not None and getattr(bg, "show_background_image", True):
            return bg.image
    return None


def set_camera_photo(cam_obj, path):
    """The photo at ``path`` becomes the camera's background image (one slot, reused)."""
    img = bpy.data.images.load(path, check_existing=True)
    c = cam_obj.data
    bg = next((b for b in c.background_images if b.source == "IMAGE"), None)
    if bg is None:
        bg = c.background_images.new()
    bg.source = "IMAGE"
    bg.image = img
    c.show_background_images = True
    return img


def photo_pixels(image) -> np.ndarray:
    """Linear RGB (H, W, 3) float32, top row first, of a Blender image (sRGB bytes decoded)."""
    rgb = image_texels(image)
    if rgb is None:
        raise CaptureError(f"Image '{image.name}' has no pixels (missing file "
                           f"'{image.filepath}'?)")
    return np.ascontiguousarray(rgb[::-1])



def posed_views(scene, selected=()):
    """The projection's views: the selected cameras (each must have a photo), else every camera
    of the scene with one (the others skipped, by name); raises CaptureError where a photo is
    not the render frame's shape or no camera has a photo."""
    from ..core.capture.projection import View
    chosen = [o for o in selected if o.type == "CAMERA"]
    cameras = chosen or sorted((o for o in scene.objects if o.type == "CAMERA"),
                               key=lambda o: o.name)
    views, skipped = [], []
    for cam in cameras:
        img = camera_photo(cam)
        if img is None:
            if chosen:
                raise CaptureError(f"Camera '{cam.name}' has no photo (an enabled background "
                                   f"image)")
            skipped.append(cam.name)
            continue
        rgb = photo_pixels(img)
        size = (rgb.shape[1], rgb.shape[0])
        if not frame_matches(scene, size):
            w, h = render_size(scene)
            raise CaptureError(f"The photo of '{cam.name}' ({size[0]} x {size[1]}) does not "
                               f"have the render frame's shape ({w} x {h})")
        m = matrix_of(cam)
        m[:3, :3] /= np.linalg.norm(m[:3, :3], axis=0)
        T = np.linalg.inv(m @ np.diag([1.0, -1.0, -1.0, 1.0]))          # world -> OpenCV camera
        views.append(View(cam.name, camera_K(cam, scene, size), T[:3, :3], T[:3, 3], rgb))
    if not views:
        raise CaptureError("No camera of the scene has a photo as background image")
    return views, skipped

def new_float_image(name, rgb, colorspace="Linear Rec.709"):
    """A packed float image from (H, W, 3) linear RGB, top row first."""
    rgb = np.nan_to_num(np.asarray(rgb, np.float32), nan=0.0, posinf=0.0, neginf=0.0)
    h, w = rgb.shape[:2]
    img = bpy.data.images.new(name, w, h, alpha=False, float_buffer=True)
    img.colorspace_settings.name = colorspace
    rgba = np.ones((h, w, 4), np.float32)
    rgba[..., :3] = rgb[::-1]
    img.pixels.foreach_set(rgba.ravel())
    img.pack()
    return img


def write_exr(path, rgb):
    """A 32-bit float RGB OpenEXR of (H, W, 3) linear values, top row first (no view
    transform: the values are written as they are)."""
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise CaptureError(f"The folder of '{path}' does not exist")
    rgb = np.nan_to_num(np.asarray(rgb, np.float32), nan=0.0, posinf=0.0, neginf=0.0)
    h, w = rgb.shape[:2]
    tmp_scene = bpy.data.scenes.new("relight_tmp_exr")
    img = bpy.data.images.new("relight_tmp_exr", w, h, alpha=False, float_buffer=True)
    try:
        s = tmp_scene.render.image_settings
        s.file_format = "OPEN_EXR"
        s.color_mode = "RGB"
        s.color_depth = "32"
        s.exr_codec = "ZIP"
        img.colorspace_settings.name = "Linear Rec.709"
        rgba = np.ones((h, w, 4), np.float32)
        rgba[..., :3] = rgb[::-1]
        img.pixels.foreach_set(rgba.ravel())
        img.save_render(os.path.abspath(path), scene=tmp_scene)
    finally:
        bpy.data.images.remove(img)
        bpy.data.scenes.remove(tmp_scene)


def read_float_image(path) -> np.ndarray:
    """(H, W, 3) float32 linear, top row first, of an image file Blender reads (EXR, HDR)."""
    img = bpy.data.images.load(os.path.abspath(path), check_existing=False)
    try:
        return photo_pixels(img)
    finally:
        bpy.data.images.remove(img)


def set_world_environment(scene, path):
    """The World's colour becomes an Environment Texture of the equirect file ``path`` (a new
    World when the scene has none; the previous Background colour input is relinked)."""
    world = scene.world
    if world is None:
        world = bpy.data.worlds.new("World")
        scene.world = world
    if world.node_tree is None:
        world.use_nodes = True
    nt = world.node_tree
    bg = next((n for n in nt.nodes if n.bl_idname == "ShaderNodeBackground"), None)
    if bg is None:
        bg = nt.nodes.new("ShaderNodeBackground")
        out = next((n for n in nt.nodes if n.bl_idname == "ShaderNodeOutputWorld"), None) \
            or nt.nodes.new("ShaderNodeOutputWorld")
        nt.links.new(bg.outputs["Background"], out.inputs["Surface"])
    env = nt.nodes.new("ShaderNodeTexEnvironment")
    env.image = bpy.data.images.load(os.path.abspath(path), check_existing=False)
    env.location = (bg.location[0] - 300, bg.location[1])
    nt.links.new(env.outputs["Color"], bg.inputs["Color"])
    return env


# ------------------------------------------------------------------------------------------
# Meshes
# ------------------------------------------------------------------------------------------

MESH_LIKE = {"MESH", "CURVE", "SURFACE", "FONT", "META"}


def _world_triangles(me, matrix):
    """(triangles (t, 3, 3) world, loop indices (t, 3)) of a mesh's loop triangles."""
    me.calc_loop_triangles()
    nv, nt = len(me.vertices), len(me.loop_triangles)
    co = np.empty(nv * 3, np.float32)
    me.vertices.foreach_get("co", co)
    m = np.array(matrix, np.float64)
    world = co.reshape(nv, 3).astype(np.float64) @ m[:3, :3].T + m[:3, 3]
    tv = np.empty(nt * 3, np.int32)
    me.loop_triangles.foreach_get("vertices", tv)
    tl = np.empty(nt * 3, np.int32)
    me.loop_triangles.foreach_get("loops", tl)
    return world[tv].reshape(nt, 3, 3), tl.reshape(nt, 3)


def uv_layer_name(obj, uv_name=""):
    """The UV map projection writes into: ``uv_name``, else the active render one ("" none)."""
    layers = obj.data.uv_layers
    if uv_name:
        return uv_name if layers.get(uv_name) is not None else ""
    layer = next((u for u in layers if u.active_render), layers.active)
    return layer.name if layer is not None else ""


def mesh_triangles(obj, depsgraph, uv_name):
    """World triangles (t, 3, 3) of an object's evaluated mesh and their UVs (t, 3, 2) from
    the UV map ``uv_name``."""
    ev = obj.evaluated_get(depsgraph)
    me = ev.to_mesh()
    try:
        tris, loops = _world_triangles(me, ev.matrix_world)
        layer = me.uv_layers.get(uv_name)
        if layer is None:
            raise CaptureError(f"'{obj.name}' has no UV map '{uv_name}' after its modifiers")
        buf = np.empty(len(me.loops) * 2, np.float32)
        layer.data.foreach_get("uv", buf)
        return tris, buf.reshape(-1, 2)[loops].astype(np.float64)
    finally:
        ev.to_mesh_clear()


def scene_triangles(depsgraph):
    """World triangles of every renderable mesh-like object and instance (the occluders), and
    the name of the object each belongs to (an instance: its object's name)."""
    parts, names = [], []
    for inst in depsgraph.object_instances:
        ob = inst.object
        owner = inst.parent if inst.is_instance and inst.parent is not None else ob
        if ob.type not in MESH_LIKE or owner.original.hide_render:
            continue
        try:
            me = ob.to_mesh()
        except RuntimeError:
            continue
        if me is None:
            continue
        try:
            if len(me.polygons):
                tris = _world_triangles(me, inst.matrix_world)[0]
                parts.append(tris)
                name = ob.original.name if not inst.is_instance else f"{owner.original.name}/{ob.original.name}"
                names += [name] * len(tris)
        finally:
            ob.to_mesh_clear()
    return (np.concatenate(parts) if parts else np.zeros((0, 3, 3))), names


def image_from_texture(name, rgb):
    """A packed float image (linear) from (h, w, 3) in Blender's row order (row 0 at v = 0)."""
    return new_float_image(name, np.asarray(rgb)[::-1])


def photo_material(obj, image, uv_name):
    """A new material showing ``image`` through ``uv_name`` as a diffuse base colour (what
    Precompute reads), in object-linked slots: the mesh keeps its own materials."""
    mat = bpy.data.materials.new(f"{obj.name} Photo")
    if mat.node_tree is None:
        mat.use_nodes = True
    nt = mat.node_tree
    bsdf = next(n for n in nt.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
    bsdf.inputs["Roughness"].default_value = 1.0
    for key in ("Specular IOR Level", "Specular"):
        if key in bsdf.inputs:
            bsdf.inputs[key].default_value = 0.0
            break
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = image
    tex.location = (-450, 250)
    uvn = nt.nodes.new("ShaderNodeUVMap")
    uvn.uv_map = uv_name
    uvn.location = (-700, 250)
    nt.links.new(uvn.outputs["UV"], tex.inputs["Vector"])
    nt.links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    if not obj.material_slots:
        obj.data.materials.append(None)
    for slot in obj.material_slots:
        slot.link = "OBJECT"
        slot.material = mat
    return mat
