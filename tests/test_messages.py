"""Messages that must not mislead (issue 44: 2, 9), through the operators on the test room of
``helpers.room`` at draft: what each says is checked against what is true of the
scene (where the lamps are, what the objects are, what is missing)."""

import pytest

bpy = pytest.importorskip("bpy")

from helpers.blender import addon_module, relit_state  # noqa: E402


def _warnings():
    st = addon_module("relight_addon.blender.state").status(bpy.context.scene) or {}
    return list(st.get("warnings", ()))


def _mesh(name, verts, faces, location=(0, 0, 0)):
    me = bpy.data.meshes.new(name)
    me.from_pydata(verts, [], faces)
    obj = bpy.data.objects.new(name, me)
    obj.location = location
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.view_layer.update()
    return obj


def test_triangles_do_not_put_every_lamp_against_a_surface(test_room):
    """A triangle (or an n-gon, split in triangles) anywhere made every lamp 'inside or
    touching a surface': its quad's second half has no area."""
    _mesh("Tri", [(0, 0, 0.5), (0.3, 0, 0.5), (0, 0.3, 0.5)], [(0, 1, 2)])
    _mesh("Ngon", [(1.5, 1.5, 0.2), (1.8, 1.5, 0.2), (1.9, 1.7, 0.2), (1.7, 1.9, 0.2),
                   (1.5, 1.8, 0.2)], [(0, 1, 2, 3, 4)])
    assert bpy.ops.relight.precompute(preset="draft") == {"FINISHED"}
    assert not [w for w in _warnings() if "touching a surface" in w or "mm from a" in w]


def test_a_lamp_against_a_surface_is_named(test_room):
    """The true case still says so: a lamp 2 mm under the ceiling."""
    bpy.data.objects["LampA"].location.z = 2.998
    assert bpy.ops.relight.precompute(preset="draft") == {"FINISHED"}
    assert [w for w in _warnings() if "'LampA'" in w and "mm from a surface" in w]
    assert not [w for w in _warnings() if "'LampB'" in w and "surface" in w]


def test_a_small_scene_is_judged_at_its_own_scale(test_room):
    """The room at 1e-4 scale gives the result of scale 1: no lamp is '0 mm from a surface'."""
    for obj in bpy.data.objects:
        obj.location = [c * 1e-4 for c in obj.location]
        obj.scale = [s * 1e-4 for s in obj.scale]
    for light in bpy.data.lights:
        light.size *= 1e-4
        light.energy *= 1e-8
    bpy.context.view_layer.update()
    assert bpy.ops.relight.precompute(preset="draft") == {"FINISHED"}
    assert not [w for w in _warnings() if "surface" in w and "Lamp" in w]


def test_a_text_object_is_no_duplicate(test_room):
    cu = bpy.data.curves.new("Label", "FONT")
    cu.body = "Relight"
    obj = bpy.data.objects.new("Label", cu)
    obj.location = (0, 1.9, 1.5)
    obj.rotation_euler = (1.5708, 0, 0)
    bpy.context.scene.collection.objects.link(obj)
    assert bpy.ops.relight.precompute(preset="draft") == {"FINISHED"}
    assert not [w for w in _warnings() if "same place" in w]


def test_a_lamp_inside_a_closed_box_is_named(test_room):
    """A point lamp inside the room's closed box lights only the box's inside: the warning names
    the lamp and the box (the photo cannot show its light)."""
    light = bpy.data.lights.new("Inside", "POINT")
    light.energy = 60.0
    light.shadow_soft_size = 0.05
    obj = bpy.data.objects.new("Inside", light)
    obj.location = (0.7, 0.6, 0.4)
    bpy.context.scene.collection.objects.link(obj)
    assert bpy.ops.relight.precompute(preset="draft") == {"FINISHED"}
    said = [w for w in _warnings() if "inside the closed object" in w]
    assert len(said) == 1 and "'Inside'" in said[0] and "'Box'" in said[0]


def test_the_room_itself_encloses_no_lamp(test_room):
    """The room the camera is in is closed too: its lamps are not 'inside a closed object'."""
    assert bpy.ops.relight.precompute(preset="draft") == {"FINISHED"}
    assert not [w for w in _warnings() if "inside the closed object" in w]


def test_no_uv_map_names_the_reason_and_the_fix(test_room):
    """Every mesh without UVs: the error says so and suggests Unwrap Missing UVs (not only 'no
    face uses an image texture')."""
    for obj in bpy.data.objects:
        if obj.type == "MESH":
            while obj.data.uv_layers:
                obj.data.uv_layers.remove(obj.data.uv_layers[0])
            obj.data.update()               # (the API does not tag the mesh for evaluation)
    before = relit_state()
    with pytest.raises(RuntimeError, match="No UV map on object .*Unwrap Missing UVs"):
        bpy.ops.relight.precompute(preset="draft")
    assert relit_state() == before
