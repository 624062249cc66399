"""Closed objects (issue 44: 2, 3), through the operators on the test room of
``helpers.room`` at draft: a box modelled inside out is relit as the same box with
outward normals (its faces turned to the side the photo shows), and a lamp inside a closed box
lights the box's inside only, which the photo does not show.

Truth: the same scene with the box's normals outward (what Cycles renders either way: its
diffuse faces are two-sided) and physics (light inside a closed box does not reach its
outside)."""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from helpers.blender import addon_module, relit_now  # noqa: E402
from helpers.room import build_scene  # noqa: E402


def _room(inside_out=False):
    import bmesh
    addon_module("operators")
    build_scene()
    if inside_out:
        me = bpy.data.objects["Box"].data
        bm = bmesh.new()
        bm.from_mesh(me)
        bmesh.ops.reverse_faces(bm, faces=bm.faces[:])
        bm.to_mesh(me)
        bm.free()
        me.update()
    bpy.context.view_layer.update()


def _box_and_floor():
    assert bpy.ops.relight.precompute(preset="draft") == {"FINISHED"}
    return {n: relit_now(n) for n in ("Box", "Floor", "WallXn")}


def test_a_box_modelled_inside_out_is_relit_as_the_box():
    """Inward normals relit the box at 0.189 against 0.301 (photo 0.360): its three faces the
    camera does not see stayed turned to its inside."""
    _room()
    outward = _box_and_floor()
    _room(inside_out=True)
    inward = _box_and_floor()
    for name in outward:
        np.testing.assert_allclose(inward[name], outward[name], rtol=0.02, atol=1e-3)
    # and each lamp still lights it: switching one off darkens the box
    bpy.data.lights["LampA"].energy = 0.0
    assert relit_now("Box").mean() < 0.8 * inward["Box"].mean()


def test_a_lamp_inside_a_closed_box_does_not_light_its_outside():
    """A point lamp inside the box: switching it off dropped the box from 0.366 to 0.189 (its
    faces were turned to the lit inside), then, with the faces kept to their outside, from
    0.356 to 0.304 (the floor's elements across the box's bottom edge carried the inside's
    light out).  Physics: light inside a closed box never reaches its outside, so the box and
    the floor are the same with the lamp on, off, or absent; the warning names the lamp and
    the box."""
    _room()
    without = _box_and_floor()
    light = bpy.data.lights.new("Inside", "POINT")
    light.energy = 60.0
    light.shadow_soft_size = 0.05
    obj = bpy.data.objects.new("Inside", light)
    obj.location = (0.7, 0.6, 0.4)
    bpy.context.scene.collection.objects.link(obj)
    with_lamp = _box_and_floor()
    light.energy = 0.0
    off = {n: relit_now(n) for n in with_lamp}
    for n in with_lamp:               # (Box, Floor, a wall)
        on_, off_, none_ = with_lamp[n].mean(), off[n].mean(), without[n].mean()
        assert off_ == pytest.approx(on_, rel=0.01), (n, on_, off_)
        assert off_ == pytest.approx(none_, rel=0.03), (n, off_, none_)
    # a virtual lamp put in the box after the precompute (Update) lights none of it either
    virtual = bpy.data.lights.new("InsideToo", "POINT")
    virtual.energy = 200.0
    vobj = bpy.data.objects.new("InsideToo", virtual)
    vobj.location = (0.5, 0.5, 0.3)
    bpy.context.scene.collection.objects.link(vobj)
    bpy.context.view_layer.update()
    assert bpy.ops.relight.update() == {"FINISHED"}
    for n in with_lamp:
        assert relit_now(n).mean() == pytest.approx(off[n].mean(), rel=0.01), n
    st = addon_module("relight_addon.blender.state").status(bpy.context.scene)
    assert any("'InsideToo'" in w and "closed object" in w for w in st["warnings"])
    assert any("'Inside'" in w and "'Box'" in w and "closed object" in w for w in st["warnings"])
