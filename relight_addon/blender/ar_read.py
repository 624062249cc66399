# SPDX-License-Identifier: GPL-3.0-or-later
"""Read the user's AR scene (the contract of issue 45), or say in one sentence what is wrong.

* The photo: the active camera's background image (``camera.data.background_images``, as
  camera-matching tools such as fSpy leave it); the camera is perspective and matches it.
* The environment: the World's Environment Texture (equirectangular, HDR or LDR) feeding the
  Background its output shows, times that Background's Strength; a Mapping node rotating it
  about z is followed.
* Receivers: objects with the role 'receiver' (proxies of photographed surfaces: a ground
  plane, a table top, a wall); each must be seen by the camera.
* Virtual objects: the role 'virtual'; each needs faces and must not go through a receiver.

Nothing is written here: :func:`read` returns an :class:`ARInput` or raises PipelineError.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass, field

import numpy as np

from ..core.ar.placement import crosses
from ..core.ar.view import CameraModel, seen
from . import ids
from .pipeline import PipelineError
from .roles import object_role, raw_property
from .sphere_nodes import object_triangles

AR_SPHERES = 16          # per object unless relight_spheres is set: each adds node groups per light
MAX_ENV_WIDTH = 1024     # wider maps are averaged down first (the bundled HDRIs' width)
GEOMETRY = {"MESH", "CURVE", "SURFACE", "FONT", "META"}
ASPECT_TOLERANCE = 0.01  # photo vs render aspect: relative difference above which we warn


@dataclass
class ObjectInput:
    """A virtual object: its triangles (t, 3, 3) in its own frame and the sphere count."""
    obj: object
    triangles: np.ndarray
    spheres: int


@dataclass
class ARInput:
    scene: object
    camera: object
    model: CameraModel
    photo: object
    world: object
    env_node: object
    env_image: object
    env_pixels: np.ndarray          # (H, W, 4) float32, bottom row first, rotated to world axes
    env_hash: str
    receivers: list
    receiver_triangles: np.ndarray  # (t, 3, 3) world
    objects: list
    view_size: tuple                # (w, h) of the receiver-view maps
    warnings: list = field(default_factory=list)


def camera_model(scene, cam, depsgraph=None) -> CameraModel:
    """The camera's CameraModel (its evaluated transform when ``depsgraph`` is given)."""
    r = scene.render
    d = cam.data
    ev = cam.evaluated_get(depsgraph) if depsgraph is not None else cam
    return CameraModel(np.array(ev.matrix_world, float), float(d.lens), float(d.sensor_width),
                       float(d.sensor_height), d.sensor_fit, float(d.shift_x), float(d.shift_y),
                       (int(r.resolution_x), int(r.resolution_y)),
                       (float(r.pixel_aspect_x), float(r.pixel_aspect_y)))


def background_photo(cam):
    """The camera's background image (the first shown one with an image), or None."""
    bgs = [bg for bg in cam.data.background_images if bg.source == "IMAGE" and bg.image]
    shown = [bg for bg in bgs if bg.show_background_image]
    return (shown or bgs or [None])[0]


def _world_output(world):
    tree = world.node_tree if world is not None else None
    if tree is None:
        return None
    outs = [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputWorld"]
    active = [n for n in outs if n.is_active_output]
    return (active or outs or [None])[0]


def environment_node(world):
    """The Environment Texture node whose colour reaches the World's output (through our own
    AR mix, reroutes and a Background node), or None."""
    out = _world_output(world)
    if out is None:
        return None
    seen_nodes, todo = set(), [out]
    while todo:
        node = todo.pop()
        if node.name in seen_nodes:
            continue
        seen_nodes.add(node.name)
        if node.bl_idname == "ShaderNodeTexEnvironment":
            return node
        for sock in node.inputs:
            for link in sock.links:
                todo.append(link.from_node)
    return None


def environment_strength(node):
    """The Strength of the Background node the Environment Texture's colour feeds (through
    reroutes), 1 when it feeds no Background directly."""
    todo = [link.to_node for link in node.outputs["Color"].links]
    while todo:
        n = todo.pop()
        if n.bl_idname == "NodeReroute":
            todo.extend(link.to_node for link in n.outputs[0].links)
        elif n.bl_idname == "ShaderNodeBackground":
            s = n.inputs["Strength"]
            return 1.0 if s.is_linked else float(s.default_value)
    return 1.0


def environment_rotation(node):
    """Rotation (rad) about z of the map by the Mapping node feeding ``node``'s Vector, 0 when
    unlinked; raises PipelineError for anything else than a z rotation."""
    sock = node.inputs["Vector"]
    if not sock.is_linked:
        return 0.0
    src = sock.links[0].from_node
    while src.bl_idname == "NodeReroute" and src.inputs[0].is_linked:
        src = src.inputs[0].links[0].from_node
    why = ("The World's Environment Texture is fed by something else than a Mapping node "
           "rotating it about z: AR mode reads the map as it is stored")
    if src.bl_idname != "ShaderNodeMapping" or src.inputs["Vector"].is_linked and \
            src.inputs["Vector"].links[0].from_node.bl_idname != "ShaderNodeTexCoord":
        raise PipelineError(why)
    rot = src.inputs["Rotation"]
    loc = src.inputs["Location"] if "Location" in src.inputs else None
    scale = src.inputs["Scale"] if "Scale" in src.inputs else None
    if any(s is not None and s.is_linked for s in (rot, loc, scale)):
        raise PipelineError(why)
    rx, ry, rz = (float(v) for v in rot.default_value)
    plain = (abs(rx) < 1e-6 and abs(ry) < 1e-6 and
             (scale is None or np.allclose(scale.default_value, 1.0, atol=1e-6)) and
             (loc is None or src.vector_type in ("VECTOR", "NORMAL") or
              np.allclose(loc.default_value, 0.0, atol=1e-6)))
    if not plain:
        raise PipelineError(why)
    return -rz if src.vector_type == "TEXTURE" else rz


def rotate_environment(pixels, angle):
    """The map (H, W, C) as seen through a Mapping rotation of ``angle`` about z: the
    Environment Texture reads it at R(angle) d, so radiance in direction d is map(R d), a shift
    of the columns by angle / 2 pi of the width (linear between columns)."""
    if abs(angle) < 1e-9:
        return pixels
    w = pixels.shape[1]
    shift = -angle / (2 * np.pi) * w          # u = 0.5 - atan2(y, x) / 2 pi
    k = int(np.floor(shift))
    f = shift - k
    a = np.roll(pixels, -k, axis=1)
    b = np.roll(pixels, -k - 1, axis=1)
    return (a * (1 - f) + b * f).astype(np.float32)


def environment_pixels(image):
    """(H, W, 4) float32 pixels of ``image`` (bottom row first), averaged down to at most
    MAX_ENV_WIDTH columns (exact area means)."""
    from ..core.ar.envmap import resize_equirect
    w, h = image.size
    buf = np.empty(w * h * image.channels, np.float32)
    image.pixels.foreach_get(buf)
    px = buf.reshape(h, w, image.channels)
    if image.channels < 4:
        px = np.concatenate([px[..., :3] if image.channels >= 3 else np.repeat(px[..., :1], 3, 2),
                             np.ones((h, w, 1), np.float32)], axis=2)
    if w > MAX_ENV_WIDTH and np.isfinite(px).all():
        f = int(np.ceil(w / MAX_ENV_WIDTH))
        nh, nw = max(h // f, 4), max(w // f, 8)
        small = resize_equirect(px[::-1, :, :3].astype(np.float64), nh, nw)[::-1]
        px = np.concatenate([small, np.ones(small.shape[:2] + (1,))], 2).astype(np.float32)
    return px


def world_triangles(obj, depsgraph):
    m = np.array(obj.evaluated_get(depsgraph).matrix_world, float)
    t = object_triangles(obj, depsgraph)
    return t @ m[:3, :3].T + m[:3, 3]


def sphere_count(obj):
    """The object's own sphere count (relight_spheres set on it) or AR_SPHERES."""
    from .roles import MAX_SPHERES
    raw = obj.get(ids.SPHERES)
    if raw is None:
        return AR_SPHERES
    return max(1, min(MAX_SPHERES, int(raw_property(obj, ids.SPHERES, AR_SPHERES))))


def role_objects(scene, role):
    return sorted((o for o in scene.objects if o.type in GEOMETRY and not o.hide_render
                   and object_role(o) == role), key=lambda o: o.name)


def read(context, require_objects=True) -> ARInput:
    """The AR scene of ``context.scene`` (see the module docstring); PipelineError on bad
    input (one sentence; nothing is changed).  ``require_objects``: no virtual object is bad
    input (Set Up), else a warning (an Update after the last one was removed)."""
    scene = context.scene
    cam = scene.camera
    if cam is None or cam.type != "CAMERA":
        raise PipelineError("The scene has no camera: AR mode needs the camera that matches "
                            "the photo (fSpy's)")
    if cam.data.type != "PERSP":
        raise PipelineError(f"The camera '{cam.name}' is {cam.data.type.lower()}: AR mode needs "
                            "a perspective camera matching the photo")
    bg = background_photo(cam)
    if bg is None:
        raise PipelineError(f"The camera '{cam.name}' has no background image: add the photo as "
                            "its background image (Camera properties > Background Images), as "
                            "fSpy does")
    photo = bg.image
    if photo.size[0] == 0 or photo.size[1] == 0:
        raise PipelineError(f"The camera's background image '{photo.name}' cannot be read (is "
                            "its file missing?)")
    world = scene.world
    env_node = environment_node(world)
    if env_node is None or env_node.image is None:
        raise PipelineError("The World has no Environment Texture with an image: AR mode lights "
                            "the objects with the World's environment map (an HDRI in an "
                            "Environment Texture node)")
    env_image = env_node.image
    if env_image.size[0] == 0 or env_image.size[1] == 0:
        raise PipelineError(f"The World's environment '{env_image.name}' cannot be read (is its "
                            "file missing?)")
    angle = environment_rotation(env_node)
    pixels = rotate_environment(environment_pixels(env_image), angle)
    strength = environment_strength(env_node)
    if strength != 1.0:
        pixels = pixels * np.float32(strength)
    from ..core.ar.envmap import validate_environment
    try:
        validate_environment(pixels[..., :3], bottom_row_first=True)
    except ValueError as ex:
        raise PipelineError(f"{str(ex).rstrip('.')} (the World's '{env_image.name}')") from None
    env_hash = hashlib.sha1(np.ascontiguousarray(pixels[..., :3]).tobytes()).hexdigest()

    depsgraph = context.evaluated_depsgraph_get()
    model = camera_model(scene, cam, depsgraph)
    receivers = role_objects(scene, "receiver")
    if not receivers:
        raise PipelineError("No object has the role 'receiver': mark the surfaces of the photo "
                            "that receive the shadows (a ground plane, a table top) as receivers "
                            "(Relight > Virtual > Role)")
    recv_tri = {}
    for obj in receivers:
        tri = world_triangles(obj, depsgraph)
        if len(tri) == 0:
            raise PipelineError(f"The receiver '{obj.name}' has no faces: a receiver is a "
                                "surface of the photographed scene")
        if not seen(model, tri):
            raise PipelineError(f"The receiver '{obj.name}' is not seen by the camera "
                                f"'{cam.name}': it cannot show the photo (move it into the "
                                "camera's view or remove its role)")
        recv_tri[obj.name] = tri
    objects = []
    for obj in role_objects(scene, "virtual"):
        tri = object_triangles(obj, depsgraph)
        if len(tri) == 0:
            raise PipelineError(f"The virtual object '{obj.name}' has no faces: it casts no "
                                "shadow (give it a surface, or remove its role)")
        m = np.array(obj.evaluated_get(depsgraph).matrix_world, float)
        verts = tri.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]
        for rname, rtri in recv_tri.items():
            if crosses(verts, rtri):
                raise PipelineError(f"The virtual object '{obj.name}' goes through the receiver "
                                    f"'{rname}': move it onto the surface (a shadow is cast on "
                                    "a surface, not inside the object)")
        objects.append(ObjectInput(obj, tri, sphere_count(obj)))
    warnings = []
    r = scene.render
    render_aspect = r.resolution_x * r.pixel_aspect_x / max(r.resolution_y * r.pixel_aspect_y,
                                                             1e-9)
    photo_aspect = photo.size[0] / photo.size[1]
    if abs(render_aspect / photo_aspect - 1) > ASPECT_TOLERANCE:
        warnings.append(f"The photo is {photo.size[0]} x {photo.size[1]} but the render "
                        f"{r.resolution_x} x {r.resolution_y}: the photo is stretched to the "
                        "camera's frame (set the render resolution to the photo's)")
    if not objects and require_objects:
        raise PipelineError("No object has the role 'virtual': mark the objects inserted into "
                            "the photo as virtual (Relight > Virtual > Role)")
    if not objects:
        warnings.append("No object has the role 'virtual' yet: the receivers show the photo "
                        "(mark the inserted objects as virtual, then Update)")
    from ..core.ar.receiver_view import view_size
    pct = r.resolution_percentage / 100.0
    size = view_size((max(1, int(r.resolution_x * pct)), max(1, int(r.resolution_y * pct))))
    return ARInput(scene, cam, model, photo, world, env_node, env_image, pixels, env_hash,
                   receivers, np.concatenate(list(recv_tri.values())), objects, size, warnings)
