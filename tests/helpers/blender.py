"""Blender-side test helpers: the add-on registered from this checkout, images' pixels, a relit
material's colour as a render shows it (T x sum_k I_k M_k from its images and drivers' present
values), a point light, a grey box, and what Relight made."""
import importlib

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from scenes.addon import PACKAGE as PKG, register_repo_addon  # noqa: E402
from scenes.materials import grey_diffuse  # noqa: E402

__all__ = ("PKG", "addon", "addon_module", "pixels", "pack_all", "relit_colour", "relit_now",
           "relit_state", "add_point", "grey_box")


def addon():
    """Register the add-on from this checkout (once a session: factory settings keep it)."""
    return register_repo_addon()


def addon_module(name):
    """The add-on's module ``name`` (dotted, below the package), the add-on registered."""
    addon()
    return importlib.import_module(f"{PKG}.{name}")


def pixels(img):
    """An image's pixels as a float32 (height, width, channels) array, bottom row first."""
    buf = np.empty(len(img.pixels), np.float32)
    img.pixels.foreach_get(buf)
    return buf.reshape(img.size[1], img.size[0], -1)


def pack_all():
    """Pack every image with pixels (a file saved then holds them)."""
    for im in bpy.data.images:
        if im.packed_file is None and len(im.pixels):
            im.pack()


def relit_colour(name):
    """T x sum_k I_k M_k of object ``name``'s (first) relit material: its images times its
    drivers' present values, as a render shows it (drivers evaluated at the last update)."""
    nt = bpy.data.objects[name].material_slots[0].material.node_tree
    t = pixels(nt.nodes["T"].image)[..., :3].astype(np.float64)
    total = 0.0
    for node in nt.nodes:
        if node.name.startswith("M "):
            total = total + nt.nodes[f"I {node.name[2:]}"].outputs[0].default_value * \
                pixels(node.image)[..., :3]
    return t * total


def relit_now(name):
    """``relit_colour(name)`` after the view layer updated (drivers follow the lamps)."""
    bpy.context.view_layer.update()
    return relit_colour(name)


def relit_state():
    """(material names per mesh slot, Relight's images, whether a status is stored)."""
    return ({o.name: [s.material.name if s.material else "" for s in o.material_slots]
             for o in bpy.data.objects if o.type == "MESH"},
            sorted(im.name for im in bpy.data.images if im.get("relight_generated")),
            "relight_status" in bpy.context.scene)


def add_point(name, location, energy):
    """A point light of radius 0.1 m (the scene's lamps are read as they are)."""
    light = bpy.data.lights.new(name, "POINT")
    light.energy = energy
    light.shadow_soft_size = 0.1
    obj = bpy.data.objects.new(name, light)
    obj.location = location
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.view_layer.update()
    return obj


def grey_box(location, size=0.6):
    """A grey diffuse cube named VBox (no role set)."""
    bpy.ops.mesh.primitive_cube_add(size=size, location=location)
    box = bpy.context.active_object
    box.name = "VBox"
    box.data.materials.append(grey_diffuse(bpy))
    return box


def run_cancelled_at(solve, fraction, timeout=120):
    """Start an operators.precompute.SolveJob and press Esc (``cancel``) once its progress
    reaches ``fraction``; wait for its thread.  Returns the fractions it reported."""
    seen = []
    report = solve.progress

    def progress(f, message):
        seen.append(f)
        if f >= fraction:
            solve.cancel()
        return report(f, message)
    solve.progress = progress
    solve.start()
    assert solve.join(timeout=timeout)
    return seen
