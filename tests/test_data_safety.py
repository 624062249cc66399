"""Nothing lost, nothing silent (issue 8): every check goes through the operators, and what is
checked is the user's data (materials, images, slots, lights), not only our output.

The room of ``helpers.room`` (six textured walls, a box, two area lights) unless a
test needs another scene; the lamp-off-in-the-photo test uses the office of ``scenes.office``
with Cycles bakes as photo and truth.
"""
import json
import os
import subprocess
import sys

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

HERE = os.path.dirname(os.path.abspath(__file__))
from blendstate import user_state  # noqa: E402
from helpers.blender import addon, addon_module, pack_all, pixels  # noqa: E402
from helpers.room import LAMPS, TEX, build_scene, textured_material  # noqa: E402

ROOT = os.path.dirname(HERE)


def _relit_objects():
    return sorted(o.name for o in bpy.data.objects
                  if any(s.material is not None and s.material.get("relight_generated")
                         for s in o.material_slots))


def _expect_error(match):
    """bpy.ops raises RuntimeError carrying the operator's ERROR report: one sentence, no
    Python traceback."""
    return pytest.raises(RuntimeError, match=match)


# -- 1. save, reopen in a fresh process, Restore, Precompute again, Update -------------------

FRESH = r"""
import json, sys
sys.path[:0] = [ROOT, HERE]
import bpy
from blendstate import user_state
from scenes.addon import register_repo_addon
register_repo_addon()
bpy.ops.wm.open_mainfile(filepath=BLEND)
out = {"relit_on_open": sorted(o.name for o in bpy.data.objects if any(
    s.material is not None and s.material.get("relight_generated") for s in o.material_slots))}
# Precompute on the relit scene: the reader reads through the relit materials.
out["precompute_on_relit"] = sorted(bpy.ops.relight.precompute(preset="draft"))
out["restore"] = sorted(bpy.ops.relight.restore_originals())
out["after_restore"] = user_state(bpy)
out["precompute"] = sorted(bpy.ops.relight.precompute(preset="draft"))
out["relit_after"] = sorted(o.name for o in bpy.data.objects if any(
    s.material is not None and s.material.get("relight_generated") for s in o.material_slots))
out["fingerprint"] = bpy.context.scene["relight_status"]["run"]
bpy.context.scene.relight.preset = "draft"
out["update"] = sorted(bpy.ops.relight.update())
out["fingerprint_after_update"] = bpy.context.scene["relight_status"]["run"]
print("RELIGHT_FRESH_JSON " + json.dumps(out))
"""


def test_save_reopen_fresh_process_restore_precompute_update(tmp_path):
    addon()
    build_scene()
    pack_all()
    before = user_state(bpy)
    assert bpy.ops.relight.precompute(preset="draft") == {"FINISHED"}
    relit = _relit_objects()
    assert len(relit) == 7
    blend = str(tmp_path / "relit.blend")
    bpy.ops.wm.save_as_mainfile(filepath=blend, copy=True)
    code = FRESH.replace("ROOT", repr(ROOT)).replace("HERE", repr(HERE)).replace("BLEND", repr(blend))
    proc = subprocess.run([sys.executable, "-c", code], cwd=str(tmp_path), capture_output=True,
                          text=True, timeout=300)
    line = next((ln for ln in proc.stdout.splitlines() if ln.startswith("RELIGHT_FRESH_JSON ")), None)
    assert proc.returncode == 0 and line, (proc.stdout[-3000:], proc.stderr[-3000:])
    out = json.loads(line.split(" ", 1)[1])
    assert out["relit_on_open"] == relit
    assert out["precompute_on_relit"] == ["FINISHED"]
    assert out["restore"] == ["FINISHED"]
    # Restore in the reopened file gives the user's data back exactly as before Precompute
    assert out["after_restore"] == json.loads(json.dumps(before))
    assert out["precompute"] == ["FINISHED"] and out["relit_after"] == relit
    assert out["update"] == ["FINISHED"]
    assert out["fingerprint_after_update"] == out["fingerprint"]      # nothing changed: no rerun


# -- 2. lamps at zero power ------------------------------------------------------------------

def test_update_after_setting_a_lamp_to_zero_keeps_its_maps():
    """Only a power changed: Update is up to date and every lamp keeps its map and driver."""
    addon()
    build_scene()
    bpy.context.scene.relight.preset = "draft"
    assert bpy.ops.relight.precompute(preset="draft") == {"FINISHED"}
    t_image = bpy.data.images["Floor_mat_img.relight.T"].as_pointer()
    bpy.data.lights["LampA"].energy = 0.0
    assert bpy.ops.relight.update() == {"FINISHED"}
    assert bpy.data.images["Floor_mat_img.relight.T"].as_pointer() == t_image
    mat = bpy.data.materials["Floor_mat.relight"]
    assert {n.name for n in mat.node_tree.nodes if n.name.startswith("M ")} == \
        {f"M {k}" for k in LAMPS}
    bpy.context.view_layer.update()
    assert mat.node_tree.nodes["I LampA"].outputs[0].default_value == 0.0


def test_lamp_off_in_the_photo_gets_a_map_that_switches_it_on():
    """Office photographed with lamp B off (Cycles bake, lamp A only): Precompute with B at 0 W
    gives B a map at a reference power and a driver; raising B to its power predicts the Cycles
    truth with both lamps on (independent bakes), far better than the photo itself."""
    from relight_addon.core.texture.colour import delta_e_2000, linear_rgb_to_lab
    from scenes.bake import bake_lighting
    from scenes.office import build_office
    sys.path.insert(0, ROOT)
    from demo.office import make_photographed
    addon()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    info = build_office(seed=0, n_lamps=2, texture_size=24)
    power = dict(info.lamp_powers)
    a, b = sorted(power)
    only = {k: {j: (v if j == k else 0.0) for j, v in power.items()} for k in power}
    photo = bake_lighting(only[a], samples=512, seed=0, texture_size=24)
    truth_b = bake_lighting(only[b], samples=512, seed=1, texture_size=24)
    truth_a = bake_lighting(only[a], samples=512, seed=1, texture_size=24)
    make_photographed(bpy, info, photo)
    bpy.data.lights[b].energy = 0.0
    assert bpy.ops.relight.precompute(preset="medium") == {"FINISHED"}
    light_b = bpy.data.lights[b]
    assert light_b["relight_power0"] == 1.0                         # reference power (no keys)
    light_b.energy = power[b]
    bpy.context.view_layer.update()
    got, want, before = [], [], []
    for obj in info.objects:
        mat = bpy.data.objects[obj].material_slots[0].material
        nt = mat.node_tree
        intensity = {k: nt.nodes[f"I {k}"].outputs[0].default_value for k in power}
        assert intensity[a] == pytest.approx(1.0) and intensity[b] == pytest.approx(power[b])
        t = pixels(nt.nodes["T"].image)[..., :3].astype(np.float64)
        relit = t * sum(intensity[k] * pixels(nt.nodes[f"M {k}"].image)[..., :3] for k in power)
        got.append(relit.reshape(-1, 3))
        want.append((truth_a[obj] + truth_b[obj]).reshape(-1, 3))
        before.append(np.asarray(photo[obj], np.float64).reshape(-1, 3))
    got, want, before = (np.concatenate(x) for x in (got, want, before))
    assert np.isfinite(got).all()
    white = np.percentile(want @ [0.2126, 0.7152, 0.0722], 99)

    def de(x):
        return delta_e_2000(linear_rgb_to_lab(np.clip(x / white, 0, None)),
                            linear_rgb_to_lab(np.clip(want / white, 0, None))).mean()

    err, unchanged = de(got), de(before)
    print(f"lamp off in the photo, switched on: CIEDE2000 {err:.2f} (photo unchanged {unchanged:.2f})")
    assert err < 3.0 and err < 0.3 * unchanged, (err, unchanged)


def test_lamp_keyframed_from_zero_uses_its_highest_key_as_reference():
    addon()
    build_scene()
    light = bpy.data.lights["LampB"]
    light.energy = 0.0
    light.keyframe_insert("energy", frame=1)
    light.energy = 80.0
    light.keyframe_insert("energy", frame=10)
    bpy.context.scene.frame_set(1)
    assert light.energy == 0.0
    assert bpy.ops.relight.precompute(preset="draft") == {"FINISHED"}
    assert light["relight_power0"] == 80.0
    fc = bpy.data.materials["Floor_mat.relight"].node_tree.animation_data.drivers.find(
        'nodes["I LampB"].outputs[0].default_value')
    assert fc.driver.expression == "p / 80.0"
    bpy.context.scene.frame_set(10)
    assert bpy.data.materials["Floor_mat.relight"].node_tree.nodes["I LampB"].outputs[0] \
        .default_value == pytest.approx(1.0)
    assert np.abs(pixels(bpy.data.images["Floor_mat_img.relight.LampB"])[..., :3]).max() > 0


# -- 3, 4, 7. what the reader finds reaches the user ----------------------------------------

def test_reader_warnings_reach_the_status_and_the_panel():
    addon()
    build_scene()
    # an image-textured object without a UV map, a missing image, a lamp that is off
    me = bpy.data.meshes.new("NoUV")
    me.from_pydata([(0, 0, 1), (0.3, 0, 1), (0.3, 0.3, 1), (0, 0.3, 1)], [], [(0, 1, 2, 3)])
    me.materials.append(textured_material("NoUV_mat", 20))
    obj = bpy.data.objects.new("NoUV", me)
    bpy.context.scene.collection.objects.link(obj)
    missing = bpy.data.images.new("no_such_photo.png", 4, 4)
    missing.source = "FILE"
    missing.filepath = os.path.join(ROOT, "no_such_photo.png")
    bpy.data.materials["WallYp_mat"].node_tree.nodes["Image Texture"].image = missing
    bulb = bpy.data.lights.new("Bulb", "POINT")
    bulb.energy = 0.0
    bpy.context.scene.collection.objects.link(bpy.data.objects.new("Bulb", bulb))
    bpy.context.view_layer.update()
    assert bpy.ops.relight.precompute(preset="draft") == {"FINISHED"}
    warnings = list(bpy.context.scene["relight_status"]["warnings"])
    assert any("No UV map on object 'NoUV'" in w for w in warnings), warnings
    assert any("no_such_photo.png" in w and "no pixels" in w for w in warnings), warnings
    assert any("'Bulb'" in w and "off" in w for w in warnings), warnings
    panel = addon_module("panels.main")
    lines = panel.warning_lines(bpy.context.scene)
    assert any("NoUV" in t for t in lines)


@pytest.mark.parametrize("value", [float("nan"), float("inf")])
def test_non_finite_vertices_are_skipped_with_a_warning(value):
    """(An infinite vertex once gave "The scene has no lamps" with two lamps present.)"""
    addon()
    build_scene()
    me = bpy.data.objects["Box"].data
    me.vertices[0].co = (value, 0.0, 0.0)
    assert bpy.ops.relight.precompute(preset="draft") == {"FINISHED"}
    warnings = list(bpy.context.scene["relight_status"]["warnings"])
    assert any("'Box'" in w and "non-finite" in w for w in warnings), warnings
    for im in bpy.data.images:
        if im.get("relight_generated"):
            assert np.isfinite(pixels(im)).all(), im.name


def test_bad_input_is_one_sentence_without_traceback():
    addon()
    build_scene()
    for o in list(bpy.data.objects):
        if o.type == "MESH":
            for v in o.data.vertices:
                v.co = (float("inf"), 0.0, 0.0)
    with _expect_error("no usable faces|no lamps|image texture") as err:
        bpy.ops.relight.precompute(preset="draft")
    assert "Traceback" not in str(err.value) and "Error:" not in str(err.value).split("\n")[-1][:6]


def test_nan_and_inf_texels_in_a_float_photo_are_sanitised():
    addon()
    build_scene()
    old = bpy.data.images["Floor_mat_img"]
    img = bpy.data.images.new("Floor_float", TEX, TEX, float_buffer=True)
    px = np.full((TEX, TEX, 4), 0.4, np.float32)
    px[3, 4, :3] = np.nan
    px[7, 1, 0] = np.inf
    px[9, 9, 1] = -2.0
    img.pixels.foreach_set(px.ravel())
    bpy.data.materials["Floor_mat"].node_tree.nodes["Image Texture"].image = img
    assert old.name != img.name
    assert bpy.ops.relight.precompute(preset="draft") == {"FINISHED"}
    warnings = list(bpy.context.scene["relight_status"]["warnings"])
    assert any("'Floor_float'" in w and "3 texel(s)" in w for w in warnings), warnings
    for name in ("Floor_float.relight.T", "Floor_float.relight.LampA"):
        assert np.isfinite(pixels(bpy.data.images[name])).all()
    # the user's image is untouched
    got = pixels(img)
    assert np.isnan(got[3, 4, 0]) and np.isinf(got[7, 1, 0]) and got[9, 9, 1] == -2.0


# -- 5. UV maps, duplicates, overrides, instances, Clear -------------------------------------

def test_unwrapped_object_is_relit_through_the_new_uv_map():
    """A material whose UV Map node names "UVMap" on a mesh without UVs: Unwrap Missing UVs
    writes "RelightUV", and the relit copy's UV Map node follows it, so a Cycles EMIT bake of
    the relit floor (through the material's own UVs) equals T x sum_k M_k texel by texel."""
    addon()
    build_scene()
    floor = bpy.data.objects["Floor"]
    floor.data.uv_layers.remove(floor.data.uv_layers["UVMap"])
    for o in bpy.context.view_layer.objects:
        o.select_set(o.name == "Floor")
    assert bpy.ops.relight.unwrap_missing() == {"FINISHED"}
    assert [l.name for l in floor.data.uv_layers] == ["RelightUV"]
    assert bpy.ops.relight.precompute(preset="draft") == {"FINISHED"}
    mat = floor.material_slots[0].material
    nt = mat.node_tree
    uv_nodes = [n for n in nt.nodes if n.bl_idname == "ShaderNodeUVMap"]
    assert uv_nodes and all(n.uv_map == "RelightUV" for n in uv_nodes)
    assert bpy.data.materials["Floor_mat"].node_tree.nodes["UV Map"].uv_map == "UVMap"  # untouched
    # EMIT bake of the relit floor into a fresh image over the same UVs
    for n in nt.nodes:
        if n.bl_idname == "ShaderNodeTexImage":
            n.interpolation = "Closest"
    target = bpy.data.images.new("emit_bake", TEX, TEX, float_buffer=True)
    node = nt.nodes.new("ShaderNodeTexImage")
    node.image = target
    nt.nodes.active = node
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.samples = 1
    scene.cycles.use_denoising = False
    for o in bpy.context.view_layer.objects:
        o.select_set(o.name == "Floor")
    bpy.context.view_layer.objects.active = floor
    bpy.ops.object.bake(type="EMIT", margin=0)
    got = pixels(target)[..., :3]
    t = pixels(nt.nodes["T"].image)[..., :3]
    want = t * sum(pixels(nt.nodes[f"M {k}"].image)[..., :3] for k in LAMPS)
    cover = got.sum(axis=-1) > 0
    assert cover.mean() > 0.3
    assert np.abs(got[cover] - want[cover]).max() < 1e-3 * max(want.max(), 1e-6) + 1e-4


def test_duplicate_objects_are_named():
    addon()
    build_scene()
    box = bpy.data.objects["Box"]
    dup = box.copy()                                  # shares the mesh, same place
    dup.name = "Box copy"
    bpy.context.scene.collection.objects.link(dup)
    bpy.context.view_layer.update()
    assert bpy.ops.relight.precompute(preset="draft") == {"FINISHED"}
    warnings = list(bpy.context.scene["relight_status"]["warnings"])
    assert any("'Box copy'" in w and "'Box'" in w and "same place" in w for w in warnings) or \
        any("'Box'" in w and "'Box copy'" in w and "same place" in w for w in warnings), warnings


def test_library_override_objects_are_relit_and_restored(tmp_path):
    """A library-override object whose mesh (and material slot) stays linked: its slot is
    switched to the object for the relit material, and Restore switches it back."""
    addon()
    build_scene()
    pack_all()
    lib = str(tmp_path / "lib.blend")
    coll = bpy.data.collections.new("Props")
    bpy.context.scene.collection.children.link(coll)
    box = bpy.data.objects["Box"]
    bpy.context.scene.collection.objects.unlink(box)
    coll.objects.link(box)
    bpy.ops.wm.save_as_mainfile(filepath=lib, copy=True)
    build_scene()
    bpy.data.objects.remove(bpy.data.objects["Box"])
    with bpy.data.libraries.load(lib, link=True) as (src, dst):
        dst.collections = ["Props"]
    linked = dst.collections[0]
    scene = bpy.context.scene
    holder = bpy.data.objects.new("PropsInstance", None)
    holder.instance_type = "COLLECTION"
    holder.instance_collection = linked
    scene.collection.objects.link(holder)
    linked.override_hierarchy_create(scene, bpy.context.view_layer)
    bpy.context.view_layer.update()
    obj = next(o for o in scene.objects if o.name.startswith("Box") and o.override_library)
    assert obj.data.library is not None and obj.material_slots[0].link == "DATA"
    before = user_state(bpy)["slots"][obj.name]
    assert bpy.ops.relight.precompute(preset="draft") == {"FINISHED"}
    slot = obj.material_slots[0]
    assert slot.link == "OBJECT" and slot.material.get("relight_generated")
    assert bpy.ops.relight.restore_originals() == {"FINISHED"}
    assert user_state(bpy)["slots"][obj.name] == before


def test_instances_show_their_source_relit_and_the_warning_says_so():
    addon()
    build_scene()
    box = bpy.data.objects["Box"]
    coll = bpy.data.collections.new("BoxColl")
    coll.objects.link(box)
    bpy.context.scene.collection.objects.unlink(box)    # only instances of it are in the scene
    inst = bpy.data.objects.new("BoxInstance", None)
    inst.instance_type = "COLLECTION"
    inst.instance_collection = coll
    inst.location = (0.0, 0.0, 0.0)
    bpy.context.scene.collection.objects.link(inst)
    bpy.context.view_layer.update()
    assert bpy.ops.relight.precompute(preset="draft") == {"FINISHED"}
    warnings = list(bpy.context.scene["relight_status"]["warnings"])
    assert any("'BoxInstance/Box' is an instance of 'Box'" in w for w in warnings), warnings
    assert not any("not replaced" in w for w in warnings)
    assert box.material_slots[0].material.name == "Box_mat.relight"     # what instances show
    assert bpy.ops.relight.restore_originals() == {"FINISHED"}
    assert box.material_slots[0].material.name == "Box_mat"


def test_clear_forgets_the_status_and_match_lamp_powers_is_disabled():
    addon()
    build_scene()
    assert bpy.ops.relight.precompute(preset="draft") == {"FINISHED"}
    assert bpy.ops.relight.match_lamp_powers.poll()
    assert bpy.ops.relight.clear() == {"FINISHED"}
    scene = bpy.context.scene
    assert "relight_status" not in scene
    energies = {l.name: l.energy for l in bpy.data.lights}
    assert not bpy.ops.relight.match_lamp_powers.poll()
    with pytest.raises(RuntimeError):
        bpy.ops.relight.match_lamp_powers()
    assert {l.name: l.energy for l in bpy.data.lights} == energies
    assert not bpy.ops.relight.clear.poll() and not bpy.ops.relight.restore_originals.poll()


# -- 6. results belong to their scene and file ----------------------------------------------

def test_results_belong_to_their_scene_and_file(tmp_path):
    """Two scenes: Clear in one leaves the other's relit data and status; the in-memory result
    (for Update and the overlays) is forgotten when a file is loaded."""
    settings = addon_module("relight_addon.blender.state")
    addon()
    build_scene()
    first = bpy.context.scene
    assert bpy.ops.relight.precompute(preset="draft") == {"FINISHED"}
    bpy.ops.scene.new(type="FULL_COPY")
    second = bpy.context.window.scene if bpy.context.window else bpy.context.scene
    if second == first:
        second = next(s for s in bpy.data.scenes if s != first)
    bpy.context.window.scene = second
    for o in second.objects:
        for s in o.material_slots:
            if s.material is not None and s.material.get("relight_generated"):
                s.material = s.material["relight_original"]
    assert bpy.ops.relight.precompute(preset="draft") == {"FINISHED"}
    assert second.get("relight_id") != first.get("relight_id")
    assert settings.last_result(second) is not None and settings.last_result(first) is not None
    assert bpy.ops.relight.clear() == {"FINISHED"}
    assert "relight_status" not in second and "relight_status" in first
    mats_first = [m for m in bpy.data.materials if m.get("relight_scene") == first["relight_id"]]
    assert len(mats_first) == 7
    assert not [m for m in bpy.data.materials if m.get("relight_scene") == second["relight_id"]]
    blend = str(tmp_path / "two.blend")
    bpy.ops.wm.save_as_mainfile(filepath=blend)
    bpy.ops.wm.open_mainfile(filepath=blend)
    # memory is forgotten; the saved file keeps the first scene's solution for its Update
    for s in bpy.data.scenes:
        assert settings.last_result(s, load=False) is None
    first = next(s for s in bpy.data.scenes if "relight_status" in s)
    kept = settings.last_result(first)
    assert kept is not None and kept.stats["elements"] == first["relight_status"]["elements"]
    assert all(settings.last_result(s) is None for s in bpy.data.scenes if s != first)


# -- conventions -----------------------------------------------------------------------------

def test_every_operator_polls_and_is_named_after_its_class():
    ops = addon_module("operators")
    base = addon_module("operators.base")
    for cls in ops.classes:
        if not issubclass(cls, bpy.types.Operator):
            continue
        assert issubclass(cls, base.RelightOperator), cls.__name__
        module, name = cls.bl_idname.split(".")
        assert cls.__name__ == f"{module.upper()}_OT_{name}", (cls.__name__, cls.bl_idname)


def test_a_running_precompute_disables_another():
    addon()
    build_scene()
    pre = addon_module("operators.precompute")

    class Running:
        state = "running"
        alive = True
        cancelled = False

    pre._ACTIVE["job"] = Running()
    try:
        assert not bpy.ops.relight.precompute.poll()
        assert not bpy.ops.relight.update.poll()
        with pytest.raises(RuntimeError, match="running"):
            bpy.ops.relight.precompute(preset="draft")
    finally:
        pre._ACTIVE["job"] = None
    assert bpy.ops.relight.precompute.poll()


def test_the_role_property_makes_an_occluder():
    addon()
    build_scene()
    read = addon_module("relight_addon.blender.read")
    box = bpy.data.objects["Box"]
    box.relight_role = "occluder"
    data, report = read.read_scene(bpy.context)
    groups = [i for i, (label, _) in enumerate(report.groups) if label == "Box"]
    sel = np.isin(data.group, groups)
    assert sel.any() and np.all(data.rho[sel] == 0) and np.all(data.image[sel] < 0)
    box.relight_role = "ignored"
    data, report = read.read_scene(bpy.context)
    assert "Box" in report.ignored_objects
