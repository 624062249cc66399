"""A user's own edits of a relit file (issue 44: 1, 6, 7, 8), through the operators, on the test
room of ``test_precompute_operator`` at draft.

Truth: the relit formula on the written images (T x sum_k I_k M_k, the drivers' values), the
photo (at the photo's powers the relit room is the photo), the user's data as it was, and how
many times the room was solved (a rename, a deletion or a duplicate of a lamp needs no solve).
"""
import importlib
import os
import sys

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from test_data_safety import _module, _pack_all  # noqa: E402
from test_precompute_operator import _pixels, build_scene  # noqa: E402
from test_virtual_lamps import relit_colour  # noqa: E402


@pytest.fixture
def room(monkeypatch):
    """The test room precomputed at draft; ``solves`` counts the room's solves since."""
    _module("operators")
    build_scene()
    _pack_all()
    bpy.context.scene.relight.preset = "draft"
    assert bpy.ops.relight.precompute(preset="draft") == {"FINISHED"}
    pipeline = _module("relight_addon.blender.pipeline")
    solves = []
    solve = pipeline.solve
    monkeypatch.setattr(pipeline, "solve", lambda *a, **k: solves.append(1) or solve(*a, **k))
    return solves


def _floor():
    """The floor's relit colour: T x sum_k I_k M_k from its material's images and drivers."""
    bpy.context.view_layer.update()
    return relit_colour("Floor")


def _photo_floor():
    from relight_addon.core.texture.colour import srgb_to_linear
    return srgb_to_linear(_pixels(bpy.data.images["Floor_mat_img"])[..., :3].astype(np.float64))


def _status():
    return _module("relight_addon.blender.state").status(bpy.context.scene)


def test_a_renamed_photographed_lamp_stays_that_lamp(room):
    """Renamed, the lamp of the photo keeps its map (it does not become a virtual lamp: the room
    came out 3.8x too bright); renamed and off, its light goes."""
    photo = _photo_floor()
    np.testing.assert_allclose(_floor(), photo, rtol=5e-3, atol=1e-4)
    bpy.data.objects["LampA"].name = "Desk lamp"
    bpy.data.objects["Desk lamp"].data.name = "Desk lamp"
    assert bpy.ops.relight.update() == {"FINISHED"}
    assert room == [], "a rename solved the room again"
    st = _status()
    assert list(st["lamps"]) == ["LampA", "LampB"] and not list(st["virtual"])
    np.testing.assert_allclose(_floor(), photo, rtol=5e-3, atol=1e-4)
    bpy.data.objects["Desk lamp"].data.energy = 0.0
    assert bpy.ops.relight.update() == {"FINISHED"}
    off = _floor()
    assert room == [] and off.mean() < 0.9 * photo.mean()
    nt = bpy.data.objects["Floor"].material_slots[0].material.node_tree
    b_only = _pixels(nt.nodes["T"].image)[..., :3] * _pixels(nt.nodes["M LampB"].image)[..., :3]
    np.testing.assert_allclose(off, b_only, rtol=1e-5)


def test_a_deleted_photographed_lamp_is_a_lamp_switched_off(room):
    """Deleted, the lamp of the photo is off and the panel says so; its light is not handed to
    the other lamp (no new solve), and undoing the deletion (the light back) relights it."""
    photo = _photo_floor()
    light = bpy.data.objects["LampA"]
    data = light.data
    bpy.data.objects.remove(light)
    assert bpy.ops.relight.update() == {"FINISHED"}
    assert room == [], "deleting a lamp solved the room again"
    st = _status()
    assert list(st["gone"]) == ["LampA"]
    assert any("LampA" in w and "deleted" in w for w in st["warnings"])
    lines = _module("panels.main").lamp_lines(bpy.context.scene)
    assert any("LampA" in head and "deleted" in head for head, _, _ in lines)
    nt = bpy.data.objects["Floor"].material_slots[0].material.node_tree
    assert nt.nodes["I LampA"].outputs[0].default_value == 0.0
    b_only = _pixels(nt.nodes["T"].image)[..., :3] * _pixels(nt.nodes["M LampB"].image)[..., :3]
    np.testing.assert_allclose(_floor(), b_only, rtol=1e-5)
    assert _floor().mean() < 0.9 * photo.mean()
    # the light comes back (as an undo would bring it): it is the lamp of the photo again
    back = bpy.data.objects.new("LampA", data)
    back["relight_uid"] = st["lamp_records"][0]["uid"]
    back.location = (-1.0, 0.0, 2.9)
    bpy.context.scene.collection.objects.link(back)
    assert bpy.ops.relight.update() == {"FINISHED"}
    assert room == [] and not list(_status()["gone"])
    np.testing.assert_allclose(_floor(), photo, rtol=5e-3, atol=1e-4)


def test_a_duplicated_lamp_is_a_new_virtual_lamp(room):
    """Shift D copies the lamp's identity with its custom properties: the copy is a new lamp
    (virtual: not in the photo), the original keeps its map."""
    src = bpy.data.objects["LampA"]
    copy = src.copy()
    copy.data = src.data.copy()
    copy.location.x += 0.5
    bpy.context.scene.collection.objects.link(copy)
    assert copy.get("relight_uid") == src.get("relight_uid")
    assert bpy.ops.relight.update() == {"FINISHED"}
    assert room == []
    st = _status()
    assert list(st["lamps"])[:2] == ["LampA", "LampB"] and list(st["virtual"]) == [copy.name]
    assert copy["relight_uid"] != src["relight_uid"]


def test_a_relit_material_deleted_by_hand_gives_the_original_back(room, tmp_path):
    """The user deletes a relit material: Restore puts their own material back in the emptied
    slot, and it survives save and reopen (it had 0 users)."""
    relit = bpy.data.objects["Box"].material_slots[0].material
    assert relit.name == "Box_mat.relight"
    bpy.data.materials.remove(relit)
    assert bpy.data.objects["Box"].material_slots[0].material is None
    blend = str(tmp_path / "deleted.blend")
    bpy.ops.wm.save_as_mainfile(filepath=blend)
    bpy.ops.wm.open_mainfile(filepath=blend)
    assert bpy.data.materials.get("Box_mat") is not None
    assert bpy.ops.relight.restore_originals() == {"FINISHED"}
    assert bpy.data.objects["Box"].material_slots[0].material.name == "Box_mat"
    assert bpy.ops.relight.clear() == {"FINISHED"}
    assert not bpy.data.materials["Box_mat"].use_fake_user      # the user's own flag again


def test_restore_then_save_keeps_the_relit_materials(room, tmp_path):
    """After Restore the relit materials have no user; a save keeps them (Restore's tooltip says
    they are kept), and Show Relit or Update brings them back after reopening, with no solve."""
    assert bpy.ops.relight.restore_originals() == {"FINISHED"}
    blend = str(tmp_path / "restored.blend")
    bpy.ops.wm.save_as_mainfile(filepath=blend)
    bpy.ops.wm.open_mainfile(filepath=blend)
    assert bpy.data.materials.get("Floor_mat.relight") is not None
    assert bpy.data.objects["Floor"].material_slots[0].material.name == "Floor_mat"
    assert bpy.ops.relight.show_relit() == {"FINISHED"}
    assert bpy.data.objects["Floor"].material_slots[0].material.name == "Floor_mat.relight"
    assert bpy.ops.relight.restore_originals() == {"FINISHED"}
    assert bpy.ops.relight.update() == {"FINISHED"}
    assert bpy.data.objects["Floor"].material_slots[0].material.name == "Floor_mat.relight"
    assert room == []


def test_two_scenes_sharing_objects_keep_their_own_results(room):
    """A Linked Copy shares the objects: Precompute and Clear in the second scene leave the
    first scene's relit materials and status, and Update there shows them again."""
    first = bpy.context.scene
    mats_first = sorted(m.name for m in bpy.data.materials
                        if m.get("relight_scene") == first["relight_id"])
    bpy.ops.scene.new(type="LINK_COPY")
    second = next(s for s in bpy.data.scenes if s != first)
    bpy.context.window.scene = second
    assert bpy.ops.relight.precompute(preset="draft") == {"FINISHED"}
    assert sorted(m.name for m in bpy.data.materials
                  if m.get("relight_scene") == first["relight_id"]) == mats_first
    st = _module("relight_addon.blender.state").status(second)
    assert any("also in scene" in w for w in st["warnings"])
    assert bpy.ops.relight.clear() == {"FINISHED"}
    assert sorted(m.name for m in bpy.data.materials
                  if m.get("relight_scene") == first["relight_id"]) == mats_first
    assert "relight_status" in first
    bpy.context.window.scene = first
    assert bpy.ops.relight.update() == {"FINISHED"}
    assert bpy.data.objects["Floor"].material_slots[0].material.get("relight_scene") == \
        first["relight_id"]


def test_a_damaged_or_foreign_kept_solution_is_not_used(room, tmp_path):
    """The kept solution is verified: another run's, or a damaged one, is ignored (Update then
    solves again), never read into a wrong result."""
    state = _module("relight_addon.blender.state")
    blend = str(tmp_path / "kept.blend")
    bpy.ops.wm.save_as_mainfile(filepath=blend)
    bpy.ops.wm.open_mainfile(filepath=blend)
    scene = bpy.context.scene
    assert state.has_kept(scene)
    scene["_relight_kept_stream"] = b"\x80\x05garbage"
    assert state.last_result(scene) is None
    bpy.ops.wm.open_mainfile(filepath=blend)
    scene = bpy.context.scene
    st = dict(scene["relight_status"])
    st["run"] = "another run"
    scene["relight_status"] = st
    assert state.last_result(scene) is None and not state.has_kept(scene)
    bpy.ops.wm.open_mainfile(filepath=blend)
    v = bpy.data.lights.new("V", "POINT")
    v.energy = 50.0
    obj = bpy.data.objects.new("V", v)
    obj.location = (0.0, 0.0, 2.0)
    bpy.context.scene.collection.objects.link(obj)
    assert bpy.ops.relight.update() == {"FINISHED"}
    assert room == []                       # the file's own solution: a virtual lamp, no solve


def test_the_preference_leaves_the_solution_out_of_the_file(room, tmp_path):
    prefs = _module("preferences")
    state = _module("relight_addon.blender.state")
    sizes = {}
    for keep in (True, False):
        state.attach(lambda keep=keep: prefs.DEFAULT_KEEP_LIMIT_MB * 2**20 if keep else 0)
        try:
            blend = str(tmp_path / f"keep_{keep}.blend")
            bpy.ops.wm.save_as_mainfile(filepath=blend, copy=True, compress=False)
            sizes[keep] = os.path.getsize(blend)
        finally:
            state.attach(prefs.keep_limit_bytes)
    bpy.ops.wm.open_mainfile(filepath=str(tmp_path / "keep_False.blend"))
    assert not state.has_kept(bpy.context.scene)
    bpy.ops.wm.open_mainfile(filepath=str(tmp_path / "keep_True.blend"))
    assert state.has_kept(bpy.context.scene)
    kept_mb = bpy.context.scene["relight_status"]["kept_mb"]
    assert kept_mb > 0
    assert abs((sizes[True] - sizes[False]) / 2**20 - kept_mb) < 0.05 * kept_mb + 0.05


class _Layout:
    """Records what a panel's draw() puts in the sidebar (background mode has no UI)."""

    def __init__(self, log):
        self.log = log
        self.scale_y = 1.0
        self.enabled = True

    def label(self, text="", icon='NONE'):
        self.log.append(("label", text))

    def prop(self, data, name, text=None, **_):
        assert hasattr(data, name), name
        self.log.append(("prop", name))

    def operator(self, idname, text=None, icon='NONE', **_):
        module, name = idname.split(".")
        assert hasattr(getattr(bpy.ops, module), name), idname
        self.log.append(("operator", idname))
        return type("Props", (), {})()

    def column(self, **_):
        return self

    row = box = column


def test_the_panels_draw_at_every_stage(room, tmp_path):
    """Each sub-panel draws (no exception, only existing operators and properties) before a
    precompute, after it, with a virtual object selected and after a lamp was deleted; no line
    is longer than a sidebar holds."""
    from types import SimpleNamespace
    panels = _module("panels.main")

    def draw_all():
        log = []
        ctx = SimpleNamespace(scene=bpy.context.scene, active_object=bpy.data.objects["Box"],
                              region=None, preferences=bpy.context.preferences)
        for cls in panels.classes:
            panel = SimpleNamespace(layout=_Layout(log))
            if hasattr(cls, "draw_header"):
                cls.draw_header(panel, ctx)
            cls.draw(panel, ctx)
        return log
    log = draw_all()
    assert ("operator", "relight.precompute") in log
    assert all(len(t) <= 70 for kind, t in log if kind == "label"), log
    bpy.data.objects["Box"].relight_role = "virtual"
    bpy.data.objects.remove(bpy.data.objects["LampB"])
    assert bpy.ops.relight.update() == {"FINISHED"}
    log = draw_all()
    assert any("deleted" in t for kind, t in log if kind == "label")
    assert ("prop", "relight_shadows") in log
    assert all(len(t) <= 70 for kind, t in log if kind == "label"), log
