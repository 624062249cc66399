"""Virtual objects (issue 11, first part): a mesh whose Relight Role is "virtual" is not in the
photo; Update puts its shadows and reflections into the maps of the relit surfaces.

The photographed office of scenes.office (24 texels per surface, 512-sample Cycles bakes: the
photo without the object, seed 0; the truth with a grey 0.6 m box on the floor, seed 1).  The
relit colour is read from the written images and the drivers, as a render shows it.
"""
import os
import sys

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
from helpers.blender import add_point, grey_box  # noqa: E402
from helpers.office import (LUM, SAMPLES, SIZE, map_images, photographed_office, relit_office)  # noqa: E402


def test_a_virtual_box_casts_its_shadow_on_the_relit_floor():
    from relight_addon.core.texture.colour import delta_e_2000, linear_rgb_to_lab
    from scenes.bake import bake_lighting

    lamp = ("Virtual", (3.0, 1.2, 1.4), 100.0)
    truths = {}

    def with_the_box(info, power):
        box = grey_box((3.6, 1.0, 0.3))
        truth = bake_lighting(power, samples=SAMPLES, seed=1, texture_size=SIZE,
                              objects=info.objects)
        # and with a virtual point lamp beside it, added after the box (the lamps kept keep
        # their maps; the new one's gets the box's change alone: virtual.add_lamps_beside_objects)
        v = add_point(*lamp)
        truths["lamp"] = bake_lighting(dict(power, Virtual=lamp[2]), samples=SAMPLES, seed=1,
                                       texture_size=SIZE, objects=info.objects)
        bpy.data.objects.remove(v)
        bpy.data.objects.remove(box)
        return truth
    info, power, truth, photo = photographed_office(with_the_box)
    assert bpy.ops.relight.precompute(preset="medium") == {"FINISHED"}
    ignoring = relit_office(info)
    box = grey_box((3.6, 1.0, 0.3))
    box.relight_role = "virtual"
    bpy.context.view_layer.update()
    assert bpy.ops.relight.update() == {"FINISHED"}
    assert not box.material_slots[0].material.get("relight_generated")    # not relit
    with_box = relit_office(info)
    names = info.objects
    want = np.concatenate([np.asarray(truth[n], np.float64).reshape(-1, 3) for n in names])
    ph = np.concatenate([np.asarray(photo[n], np.float64).reshape(-1, 3) for n in names])
    white = np.percentile(want @ LUM, 99)
    # the box's cast shadow: darker than the photo, but not the floor hidden under the box
    shadow = (want @ LUM < 0.8 * ph @ LUM) & (want @ LUM > 0.05 * ph @ LUM)
    visible = want @ LUM > 0.05 * ph @ LUM
    assert shadow.sum() >= 10

    def de(got):
        g = np.concatenate([got[n].reshape(-1, 3) for n in names])
        return delta_e_2000(linear_rgb_to_lab(np.clip(g / white, 0, None)),
                            linear_rgb_to_lab(np.clip(want / white, 0, None)))
    d_with, d_without = de(with_box), de(ignoring)
    print(f"virtual box: overall {d_with[visible].mean():.2f} (ignoring it "
          f"{d_without[visible].mean():.2f}), its shadow {d_with[shadow].mean():.2f} "
          f"(ignoring it {d_without[shadow].mean():.2f})")
    assert d_with[visible].mean() <= 1.5
    assert d_with[shadow].mean() < 0.5 * d_without[shadow].mean()
    # the virtual lamp beside the box: the room as Cycles lights it with both there
    want_box = want
    v = add_point(*lamp)
    assert bpy.ops.relight.update() == {"FINISHED"}
    want = np.concatenate([np.asarray(truths["lamp"][n], np.float64).reshape(-1, 3)
                           for n in names])
    d_lamp = de(relit_office(info))
    near = shadow | (np.abs(want - want_box) @ LUM > 0.05 * want_box @ LUM)   # its light
    print(f"beside the box, a virtual lamp: overall {d_lamp[visible].mean():.2f}, its shadow "
          f"and light {d_lamp[near & visible].mean():.2f}")
    assert d_lamp[visible].mean() <= 1.5
    assert d_lamp[near & visible].mean() <= 2.0
    bpy.data.objects.remove(v)
    want = want_box
    # moving it away and updating takes its shadow away again
    box.relight_role = "ignored"
    bpy.context.view_layer.update()
    assert bpy.ops.relight.update() == {"FINISHED"}
    back = de(relit_office(info))
    assert abs(back[shadow].mean() - d_without[shadow].mean()) < 0.25 * d_without[shadow].mean()


@pytest.mark.slow
def test_update_adds_moves_and_deletes_a_virtual_object_on_the_kept_room(count_solves):
    """Update inserts, moves and deletes a virtual object without solving the room again (the
    last result of the room alone is kept); what it writes is what a Precompute from scratch
    writes for the same scene, and deleting the object gives the room's maps back exactly."""
    info, *_ = photographed_office(lambda info, power: None)
    assert bpy.ops.relight.precompute(preset="medium") == {"FINISHED"}
    room = map_images(info)
    assert room
    solves = count_solves()

    box = grey_box((2.7, 3.2, 0.3))
    box.relight_role = "virtual"
    bpy.context.view_layer.update()
    assert bpy.ops.relight.update() == {"FINISHED"}
    first = map_images(info)
    changed = [n for n in room if not np.array_equal(room[n], first[n])]
    assert changed, "the box changed no map"
    box.location.x += 0.4
    bpy.context.view_layer.update()
    assert bpy.ops.relight.update() == {"FINISHED"}
    moved = map_images(info)
    assert solves == [], "Update solved the room again for a virtual object"
    assert any(not np.array_equal(first[n], moved[n]) for n in changed)

    assert bpy.ops.relight.precompute(preset="medium") == {"FINISHED"}      # from scratch
    scratch = map_images(info)
    assert solves == [1]
    for n in room:
        assert np.allclose(moved[n], scratch[n], rtol=1e-4, atol=1e-6), n

    bpy.data.objects.remove(box)
    bpy.context.view_layer.update()
    assert bpy.ops.relight.update() == {"FINISHED"}
    assert solves == [1]
    gone = map_images(info)
    for n in room:
        assert np.array_equal(gone[n], room[n]), n


REOPEN = r"""
import json, sys
sys.path[:0] = [ROOT, HERE]
import numpy as np
import bpy
from scenes.addon import register_repo_addon
register_repo_addon()
bpy.ops.wm.open_mainfile(filepath=BLEND)
from helpers.office import map_images
scene = bpy.context.scene
out = {"objects_saved": bool(scene["relight_status"].get("objects"))}
z = np.load(MAPS)
saved = {n: z["with_" + str(i)] for i, n in enumerate(z["names"])}
room = {n: z["room_" + str(i)] for i, n in enumerate(z["names"])}
names = [str(n) for n in z["names"]]
now = {n: a for n, a in map_images(None).items()}
out["reopened_as_saved"] = all(np.array_equal(now[n], saved[n]) for n in names)
box = bpy.data.objects["VBox"]
box.location.x += 0.4
bpy.context.view_layer.update()
out["move"] = sorted(bpy.ops.relight.update())
moved = map_images(None)
out["moved_changed"] = sorted(n for n in names if not np.array_equal(moved[n], saved[n]))
bpy.data.objects.remove(box)
bpy.context.view_layer.update()
out["delete"] = sorted(bpy.ops.relight.update())
gone = map_images(None)
out["room_back"] = max(float(np.abs(gone[n] - room[n]).max()) for n in names)
print("RELIGHT_REOPEN_JSON " + json.dumps(out))
"""


def test_an_exact_object_undoes_and_survives_save_and_reopen(tmp_path):
    """Undo after the Update that inserted a virtual object gives the room's maps back, redo
    its shadow; saved and reopened in a fresh process (no result in memory), moving it and
    Update recomputes its shadow, and deleting it and Update gives the room's maps back."""
    import json
    import subprocess
    info, *_ = photographed_office(lambda info, power: None)
    assert bpy.ops.relight.precompute(preset="medium") == {"FINISHED"}
    room = map_images(info)
    bpy.ops.ed.undo_push(message="precomputed")
    box = grey_box((2.7, 3.2, 0.3))
    box.relight_role = "virtual"
    bpy.context.view_layer.update()
    bpy.ops.ed.undo_push(message="box added")
    assert bpy.ops.relight.update() == {"FINISHED"}
    bpy.ops.ed.undo_push(message="updated")
    with_box = map_images(info)
    assert any(not np.array_equal(room[n], with_box[n]) for n in room)
    bpy.ops.ed.undo()
    assert all(np.array_equal(room[n], a) for n, a in map_images(info).items())
    bpy.ops.ed.redo()
    assert all(np.array_equal(with_box[n], a) for n, a in map_images(info).items())

    names = sorted(room)
    maps = str(tmp_path / "maps.npz")
    np.savez(maps, names=np.array(names), **{f"with_{i}": with_box[n] for i, n in enumerate(names)},
             **{f"room_{i}": room[n] for i, n in enumerate(names)})
    blend = str(tmp_path / "exact_object.blend")
    bpy.ops.wm.save_as_mainfile(filepath=blend, copy=True)
    code = (REOPEN.replace("ROOT", repr(ROOT)).replace("HERE", repr(HERE))
            .replace("BLEND", repr(blend)).replace("MAPS", repr(maps)))
    proc = subprocess.run([sys.executable, "-c", code], cwd=str(tmp_path), capture_output=True,
                          text=True, timeout=600)
    line = next((ln for ln in proc.stdout.splitlines() if ln.startswith("RELIGHT_REOPEN_JSON ")),
                None)
    assert proc.returncode == 0 and line, (proc.stdout[-3000:], proc.stderr[-3000:])
    out = json.loads(line.split(" ", 1)[1])
    print(out)
    assert out["objects_saved"] and out["reopened_as_saved"]
    assert out["move"] == ["FINISHED"] and out["delete"] == ["FINISHED"]
    assert any(n.startswith("Floor") for n in out["moved_changed"])
    assert out["room_back"] <= 1e-5
