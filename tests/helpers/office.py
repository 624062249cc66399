"""The demo office for the virtual lamp and object tests: photographed by a Cycles bake (both
real lamps, seed 0), Cycles truth per lamp, and the CIEDE2000 of a relit result against it."""
import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from .blender import addon, relit_colour  # noqa: E402

SIZE = 24                                   # texels a side of the office's textures
SAMPLES = 512                               # Cycles samples of its bakes
LUM = np.array([0.2126, 0.7152, 0.0722])    # Rec. 709 luminance
VIRTUAL = (3.8, 1.0, 1.6)                   # where the tests put a virtual lamp


def photographed_office(true_albedo_bakes):
    """The test office: its photo (both real lamps, seed 0), then ``true_albedo_bakes(info,
    power)`` (Cycles truth baked on the true albedo, before the room is "photographed"), then
    the photographed room with the medium preset set.  Returns (info, power, truth, photo)."""
    from scenes.bake import bake_lighting
    from scenes.office import build_office
    from demo.office import make_photographed
    addon()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    info = build_office(seed=0, n_lamps=2, texture_size=SIZE)
    power = dict(info.lamp_powers)
    photo = bake_lighting(power, samples=SAMPLES, seed=0, texture_size=SIZE)
    truth = true_albedo_bakes(info, power)
    make_photographed(bpy, info, photo)
    bpy.context.scene.relight.preset = "medium"
    return info, power, truth, photo


def relit_office(info):
    """{object: relit colour} from the relit materials' images and their drivers' values."""
    bpy.context.view_layer.update()
    return {name: relit_colour(name) for name in info.objects}


def office_delta_e(info, got, want):
    """Mean CIEDE2000 of ``got`` against ``want`` ({object: linear RGB}) over the lit texels,
    both scaled by the truth's 99th-percentile white."""
    from relight_addon.core.texture.colour import delta_e_2000, linear_rgb_to_lab

    g = np.concatenate([got[n].reshape(-1, 3) for n in info.objects])
    w = np.concatenate([np.asarray(want[n], np.float64).reshape(-1, 3) for n in info.objects])
    lit = w @ LUM > 0
    white = np.percentile(w[lit] @ LUM, 99)
    d = delta_e_2000(linear_rgb_to_lab(np.clip(g[lit] / white, 0, None)),
                     linear_rgb_to_lab(np.clip(w[lit] / white, 0, None)))
    return float(d.mean())


def map_images(info):
    """The relit materials' map images of the office's surfaces (every mesh when ``info`` is
    None), as float arrays by name."""
    out = {}
    names = info.objects if info is not None else \
        [o.name for o in bpy.data.objects if o.type == "MESH"]
    for name in names:
        for slot in bpy.data.objects[name].material_slots:
            for node in slot.material.node_tree.nodes:
                image = getattr(node, "image", None)
                if image is not None and ".relight." in image.name:
                    px = np.empty(len(image.pixels), np.float32)
                    image.pixels.foreach_get(px)
                    out[image.name] = px
    return out
