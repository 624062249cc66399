"""No silent collapse (issue 9): when the model cannot explain the photo, the status bar and the
panel say so and name the lamp or surface, and the user's powers are kept.  Through the
operators, on the room of helpers.room and the office of scenes.office."""

import pytest

bpy = pytest.importorskip("bpy")

from helpers.blender import addon, pixels  # noqa: E402
from helpers.room import LAMPS, build_scene  # noqa: E402


def _warnings():
    return list(bpy.context.scene["relight_status"]["warnings"])


def _maps_peak(lamp):
    return max(float(pixels(im)[..., :3].max()) for im in bpy.data.images
               if im.get("relight_generated") and im.name.endswith(f".relight.{lamp}"))


def test_every_lamp_lights_the_random_photo_room_at_medium():
    """The suite's own room of random textures at medium: both lamps keep their power ratio
    and light the room (the old fit set every map of one lamp to 0)."""
    addon()
    build_scene()
    assert bpy.ops.relight.precompute(preset="medium") == {"FINISHED"}
    st = bpy.context.scene["relight_status"]
    scale = list(st["exitance_scale"])
    assert scale[0] == pytest.approx(scale[1], rel=1e-6)           # the user's ratio kept
    for lamp in LAMPS:
        assert _maps_peak(lamp) > 0.05, lamp


def test_a_lamp_touching_a_wall_and_a_lamp_inside_a_box_are_named():
    addon()
    build_scene()
    # LampA 1 mm under the ceiling (z = 3)
    bpy.data.objects["LampA"].location.z = 3.0 - 0.001
    # a third lamp inside a closed box
    me = bpy.data.meshes.new("Crate")
    v = [(x, y, z) for z in (0.1, 0.6) for y in (-1.5, -1.0) for x in (1.0, 1.5)]   # closed, off the floor
    me.from_pydata(v, [], [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2),
                           (1, 3, 7, 5)])
    crate = bpy.data.objects.new("Crate", me)
    bpy.context.scene.collection.objects.link(crate)
    hidden = bpy.data.lights.new("Hidden", "POINT")
    hidden.energy = 100.0
    hidden.shadow_soft_size = 0.05
    obj = bpy.data.objects.new("Hidden", hidden)
    obj.location = (1.25, -1.25, 0.35)
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.view_layer.update()
    assert bpy.ops.relight.precompute(preset="draft") == {"FINISHED"}
    w = _warnings()
    assert any("'LampA'" in x and "mm from a surface" in x for x in w), w
    assert any("'Hidden'" in x and "lights none" in x for x in w), w
    assert not any("'LampB'" in x for x in w), w


def test_an_overexposed_wall_is_named():
    addon()
    build_scene()
    img = bpy.data.images["WallXp_mat_img"]
    px = pixels(img).copy()
    px[..., :3] = 1.0                                       # blown out: white
    img.pixels.foreach_set(px.ravel())
    img.update()
    assert bpy.ops.relight.precompute(preset="draft") == {"FINISHED"}
    w = _warnings()
    assert any("'WallXp'" in x and "brighter in the photo" in x for x in w), w
    assert not any("'Floor'" in x and "brighter" in x for x in w), w
