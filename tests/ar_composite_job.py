"""One render of the AR composite's evaluation, in a fresh bpy process (tests/ar_composite.py
starts it): ``python ar_composite_job.py '<json>'``.

kinds: ``photo`` (the set without the object: a 16-bit PNG at ``photo``, and the object's coverage
mask),
``truth`` (the set with the object), ``catcher`` (the user's alternative: the object over the
photo with Cycles' shadow catcher on the set), ``ours`` (the photo as the camera's background,
roles, ``bpy.ops.relight.ar_setup()``, the scene's render; optionally saved, and rendered
again after a move of the object), ``chain`` (``ours``, then the object moved to ``move``
and rendered, a second object ``second`` added and ``relight.update()``, rendered, saved to
``save``), ``reopen`` (the saved file opened and rendered: no add-on code runs before the
render).  ``placements`` (truth, catcher): the objects' triangles given as spheres
({"radius", "centre"}) instead of the scene's object.  Writes ``<out>.npz``: image (H, W, 3)
linear float32 top row first, seconds (the render's wall time), cpu (its process CPU time),
and what the kind adds.
"""
import json
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, HERE)
sys.path.insert(0, ROOT)

import bpy  # noqa: E402
import numpy as np  # noqa: E402

import ar_composite_scenes as S  # noqa: E402


def _engine(sc, engine, samples, denoise, args=None):
    sc.render.engine = engine
    if engine == "CYCLES":
        sc.cycles.device = "CPU"
        sc.cycles.samples = samples
        sc.cycles.use_adaptive_sampling = False
        sc.cycles.use_denoising = bool(denoise)
        sc.cycles.seed = 0
    else:
        sc.eevee.taa_render_samples = samples
        if args and "eevee_raytracing" in args:             # an experiment's switch (not the default)
            sc.eevee.use_raytracing = bool(args["eevee_raytracing"])


def _render(sc, path):
    """Render to an EXR; (image (H, W, 3) linear top row first, wall s, CPU s)."""
    sc.render.image_settings.file_format = "OPEN_EXR"
    sc.render.image_settings.color_depth = "32"
    sc.render.filepath = path
    t, c = time.perf_counter(), time.process_time()
    bpy.ops.render.render(write_still=True)
    wall, cpu = time.perf_counter() - t, time.process_time() - c
    img = bpy.data.images.load(path, check_existing=False)
    w, h = img.size
    px = np.empty(w * h * 4, np.float32)
    img.pixels.foreach_get(px)
    bpy.data.images.remove(img)
    os.remove(path)
    return px.reshape(h, w, 4)[::-1, :, :3].copy(), wall, cpu


def _sphere(spec, n_lat=24, n_lon=48):
    return S.ar_scenes.uv_sphere(radius=spec["radius"], centre=spec["centre"], n_lat=n_lat,
                                 n_lon=n_lon)


def _mask(sc, args, tri=None):
    """(H, W) coverage of the object (or the triangles ``tri``) in the frame: its triangles
    projected by the camera (bpy_extras.world_to_camera_view), rasterised 4x finer and averaged
    down."""
    import cv2
    from bpy_extras.object_utils import world_to_camera_view
    from mathutils import Vector
    w, h = args["res"]
    k = 4
    if tri is None:
        tri = S.object_triangles(args["object"], args["scene"])
    tri = tri.reshape(-1, 3)
    uv = np.array([world_to_camera_view(sc, sc.camera, Vector(p))[:2] for p in tri])
    img = np.zeros((h * k, w * k), np.uint8)
    pts = np.stack([uv[:, 0] * w * k, (1 - uv[:, 1]) * h * k], 1).reshape(-1, 3, 2)
    for t in pts:
        cv2.fillConvexPoly(img, np.round(t * 16).astype(np.int32), 1, lineType=cv2.LINE_8,
                           shift=4)
    return img.reshape(h, k, w, k).mean(axis=(1, 3)).astype(np.float32)


def _photo_setup(sc, args):
    """The user's AR scene: the photo as the camera's background image, the set's objects as
    receivers, the object added as virtual."""
    img = bpy.data.images.load(args["photo"])
    bg = sc.camera.data.background_images.new()
    bg.image = img
    sc.camera.data.show_background_images = True
    for o in S.set_objects():
        o["relight_role"] = "receiver"
    ob = S.add_object(args["object"], args["scene"])
    ob["relight_role"] = "virtual"
    if args.get("spheres"):
        ob["relight_spheres"] = int(args["spheres"])
    return ob


def _catcher(sc, args):
    """The shadow catcher composite: the set catches the object's shadow; the render
    (film transparent) over the photo x the Shadow Catcher pass, in the compositor."""
    for o in S.set_objects():
        o.is_shadow_catcher = True
    sc.render.film_transparent = True
    layer = bpy.context.view_layer
    layer.cycles.use_pass_shadow_catcher = True
    ng = bpy.data.node_groups.new("catcher", "CompositorNodeTree")
    ng.interface.new_socket("Image", in_out="OUTPUT", socket_type="NodeSocketColor")
    rl = ng.nodes.new("CompositorNodeRLayers")
    photo = ng.nodes.new("CompositorNodeImage")
    photo.image = bpy.data.images.load(args["photo"])
    scale = ng.nodes.new("CompositorNodeScale")
    scale.inputs["Type"].default_value = "Render Size"
    ng.links.new(photo.outputs["Image"], scale.inputs["Image"])
    shadowed = ng.nodes.new("ShaderNodeVectorMath")
    shadowed.operation = "MULTIPLY"
    ng.links.new(scale.outputs["Image"], shadowed.inputs[0])
    ng.links.new(rl.outputs["Shadow Catcher"], shadowed.inputs[1])
    keep = ng.nodes.new("ShaderNodeMath")
    keep.operation = "SUBTRACT"
    keep.inputs[0].default_value = 1.0
    ng.links.new(rl.outputs["Alpha"], keep.inputs[1])
    under = ng.nodes.new("ShaderNodeVectorMath")
    under.operation = "SCALE"
    ng.links.new(shadowed.outputs[0], under.inputs[0])
    ng.links.new(keep.outputs[0], under.inputs["Scale"])
    add = ng.nodes.new("ShaderNodeVectorMath")
    add.operation = "ADD"
    ng.links.new(rl.outputs["Image"], add.inputs[0])
    ng.links.new(under.outputs[0], add.inputs[1])
    ng.links.new(add.outputs[0], ng.nodes.new("NodeGroupOutput").inputs[0])
    sc.compositing_node_group = ng


def main():
    args = json.loads(sys.argv[-1])
    bpy.ops.wm.read_factory_settings(use_empty=True)
    kind = args["kind"]
    out = {}
    if kind == "reopen":
        bpy.ops.wm.open_mainfile(filepath=args["save"])
        sc = bpy.context.scene
        _engine(sc, args.get("engine", "CYCLES"), args["samples"], args.get("denoise", True))
        out["image"], out["seconds"], out["cpu"] = _render(sc, args["out"] + ".exr")
        np.savez(args["out"] + ".npz", **out)
        return
    placed = args.get("placements")
    S.build(args["scene"], args["object"], args["hdri"],
            with_object=kind in ("truth", "catcher") and not placed, res=tuple(args["res"]))
    sc = bpy.context.scene
    if placed and kind in ("truth", "catcher"):
        tris = [_sphere(p) for p in placed]
        for tri in tris:
            S.add_object(args["object"], args["scene"], tri=tri)
        out["mask"] = _mask(sc, args, np.concatenate(tris))
    _engine(sc, args.get("engine", "CYCLES"), args["samples"], args.get("denoise", True), args)
    tmp = args["out"] + ".exr"
    if kind == "photo":
        sc.render.image_settings.file_format = "PNG"
        sc.render.image_settings.color_depth = "16"
        sc.render.filepath = args["photo"]
        bpy.ops.render.render(write_still=True)
        out["mask"] = _mask(sc, args)
    elif kind in ("truth", "catcher"):
        if kind == "catcher":
            _catcher(sc, args)
        out["image"], out["seconds"], out["cpu"] = _render(sc, tmp)
    elif kind in ("ours", "chain"):
        from scenes.addon import register_repo_addon
        register_repo_addon()
        ob = _photo_setup(sc, args)
        t = time.perf_counter()
        result = bpy.ops.relight.ar_setup()
        out["setup_seconds"] = time.perf_counter() - t
        assert result == {"FINISHED"}, result
        out["image"], out["seconds"], out["cpu"] = _render(sc, tmp)
        if kind == "ours" and args.get("save"):
            bpy.ops.wm.save_as_mainfile(filepath=args["save"])
        if args.get("move"):
            ob.location = args["move"]
            bpy.context.view_layer.update()
            out["moved"], _, _ = _render(sc, tmp)
        if kind == "chain":
            second = S.add_object(args["object"], args["scene"],
                                  tri=_sphere(args["second"], 8, 16))
            second["relight_role"] = "virtual"
            second["relight_spheres"] = 8
            bpy.context.view_layer.update()
            t = time.perf_counter()
            result = bpy.ops.relight.update()
            out["update_seconds"] = time.perf_counter() - t
            assert result == {"FINISHED"}, result
            out["second"], _, _ = _render(sc, tmp)
            bpy.ops.wm.save_as_mainfile(filepath=args["save"])
    np.savez(args["out"] + ".npz", **out)


if __name__ == "__main__":
    main()
