"""AR mode's test scene as a user builds it (helpers for test_ar_setup and test_ar_draw): the
ground plane of ar_composite_scenes at 64 x 48, the camera's background photo, the World's
bundled HDRI, the receiver and a coarse virtual sphere; and a snapshot of everything a failed
Set Up must leave as it was."""
from __future__ import annotations

import importlib

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

import ar_composite_scenes as S  # noqa: E402
import ar_truth as T  # noqa: E402
from blendstate import user_state  # noqa: E402
from scenes.addon import PACKAGE, register_repo_addon  # noqa: E402

HDRIS = T.bundled_hdris()
RES = (64, 48)


def ar_module(name):
    """The add-on's bridge module ``name`` (relight_addon.blender.<name>), registered."""
    register_repo_addon()
    return importlib.import_module(f"{PACKAGE}.relight_addon.blender.{name}")


def photo_file(tmp_path):
    """A small photo file (the set's colours: what a receiver shows)."""
    path = str(tmp_path / "photo.png")
    img = bpy.data.images.new("photo_src", *RES)
    px = np.empty((RES[1], RES[0], 4), np.float32)
    px[...] = (0.45, 0.47, 0.5, 1.0)
    px[: RES[1] // 2] = (0.5, 0.6, 0.8, 1.0)
    img.pixels.foreach_set(px.ravel())
    img.filepath_raw = path
    img.file_format = "PNG"
    img.save()
    bpy.data.images.remove(img)
    return path


def build(tmp_path, hdri="sunrise"):
    """The user's AR scene: (scene, the virtual sphere)."""
    register_repo_addon()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    register_repo_addon()
    S.build("ground", "sphere", HDRIS[hdri], with_object=False, res=RES)
    sc = bpy.context.scene
    bg = sc.camera.data.background_images.new()
    bg.image = bpy.data.images.load(photo_file(tmp_path))
    for o in S.set_objects():
        o["relight_role"] = "receiver"
    # a coarse sphere: the fit's cost is the winding number's (cells x triangles)
    ob = S.add_object("sphere", "ground", tri=S.ar_scenes.uv_sphere(n_lat=8, n_lon=16))
    ob["relight_role"] = "virtual"
    ob["relight_spheres"] = 8
    bpy.context.view_layer.update()
    return sc, ob


def _world_state(world):
    """A World's nodes (name, type, target, active), links, drivers and ID properties."""
    tree = world.node_tree
    if tree is None:
        return None, sorted(world.keys())
    nodes = sorted((n.name, n.bl_idname, getattr(n, "target", None),
                    getattr(n, "is_active_output", None)) for n in tree.nodes)
    links = sorted((lk.from_node.name, lk.from_socket.identifier, lk.to_node.name,
                    lk.to_socket.identifier) for lk in tree.links)
    drivers = sorted(fc.data_path for fc in tree.animation_data.drivers) \
        if tree.animation_data else []
    return nodes, links, drivers, sorted(world.keys())


def snapshot():
    """Everything a failed Set Up must leave as it was."""
    sc = bpy.context.scene
    out = {c: sorted(d.name for d in getattr(bpy.data, c))
           for c in ("objects", "meshes", "materials", "images", "node_groups", "worlds",
                     "cameras", "scenes")}
    out["slots"] = {o.name: [s.material.name if s.material else None for s in o.material_slots]
                    for o in bpy.data.objects}
    out["props"] = {o.name: sorted(o.keys()) for o in bpy.data.objects}
    out["scene_props"] = sorted(sc.keys())
    out["settings"] = (sc.render.film_transparent, sc.view_settings.view_transform,
                       getattr(getattr(sc, "compositing_node_group", None), "name", None),
                       [a.name for layer in sc.view_layers for a in layer.aovs])
    out["user"] = user_state(bpy)
    out["world_nodes"] = {w.name: _world_state(w) for w in bpy.data.worlds}
    return out
