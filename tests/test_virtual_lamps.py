"""Virtual lamps (issue 11, seed 000 §4.4.1): lights added after Precompute get their own map on
every relit surface through Update, against Cycles truth, through the operators.

The photographed office of scenes.office (24 texels per surface, 512-sample bakes: the photo
with both real lamps, seed 0; the truth per lamp, seed 1, and of the virtual light alone, seed 1,
all with the true albedo).  The relit colour is read from the written images and the drivers'
values, as a render would show it.
"""
import os
import subprocess
import sys

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
from helpers.blender import add_point, pixels  # noqa: E402
from helpers.office import (SAMPLES, SIZE, VIRTUAL, office_delta_e, photographed_office,
                            relit_office)  # noqa: E402


def _office():
    from scenes.bake import bake_lighting

    def bakes(info, power):
        truth = {k: bake_lighting({j: (v if j == k else 0.0) for j, v in power.items()},
                                  samples=SAMPLES, seed=1, texture_size=SIZE) for k in power}
        # the virtual light's truth
        v = add_point("Virtual", VIRTUAL, 150.0)
        truth["Virtual"] = bake_lighting({**{k: 0.0 for k in power}, "Virtual": 150.0},
                                         samples=SAMPLES, seed=1, texture_size=SIZE)
        bpy.data.objects.remove(v)
        return truth
    return photographed_office(bakes)[:3]


@pytest.fixture(scope="module")
def office():
    return _office()


def test_virtual_point_lamp_against_cycles(office):
    """A point light added after Precompute: Update gives it a map and a driver in a fraction of
    a second; real lamps off, the relit room matches the Cycles bake of the virtual light alone
    within 2.0 CIEDE2000, real lamps on within 1.5 (the issue's targets)."""
    import time
    info, power, truth = office
    assert bpy.ops.relight.precompute(preset="medium") == {"FINISHED"}
    v = add_point("Virtual", VIRTUAL, 150.0)
    t0 = time.perf_counter()
    assert bpy.ops.relight.update() == {"FINISHED"}
    seconds = time.perf_counter() - t0
    st = bpy.context.scene["relight_status"]
    assert list(st["virtual"]) == ["Virtual"] and "Virtual" in list(st["lamps"])
    truth_v = truth["Virtual"]
    for k in power:                                              # real lamps off
        bpy.data.lights[k].energy = 0.0
    off = office_delta_e(info, relit_office(info), truth_v)
    for k, p in power.items():
        bpy.data.lights[k].energy = p
    on = office_delta_e(info, relit_office(info), {n: truth_v[n] + sum(truth[k][n] for k in power)
                                  for n in info.objects})
    print(f"virtual point lamp: real lamps off {off:.2f}, on {on:.2f} CIEDE2000; Update {seconds:.2f} s")
    assert off <= 2.0 and on <= 1.5, (off, on)
    assert seconds < 5.0, seconds          # the write dominates; the core part is ~0.1 s
    # moving it and pressing Update recomputes it; deleting it removes its map
    v.location.x -= 1.0
    bpy.context.view_layer.update()
    before = pixels(bpy.data.images["Floor photo.relight.Virtual"]).copy()
    assert bpy.ops.relight.update() == {"FINISHED"}
    assert not np.allclose(pixels(bpy.data.images["Floor photo.relight.Virtual"]), before)
    bpy.data.objects.remove(v)
    bpy.context.view_layer.update()
    assert bpy.ops.relight.update() == {"FINISHED"}
    assert "Floor photo.relight.Virtual" not in bpy.data.images
    assert list(bpy.context.scene["relight_status"]["virtual"]) == []


def test_virtual_lamp_in_place_of_a_real_one(office):
    """The seed's own test: a virtual area light where real lamp A is, at A's power: with A
    switched off and the virtual one on, the room looks as with A alone (the truth of A)."""
    info, power, truth = office
    assert bpy.ops.relight.precompute(preset="medium") == {"FINISHED"}
    a = bpy.data.objects["Lamp A"]
    light = a.data.copy()
    light.name = "Twin"
    twin = bpy.data.objects.new("Twin", light)
    twin.matrix_world = a.matrix_world.copy()
    twin.location.z -= 0.005                     # not coincident with the real lamp
    bpy.context.scene.collection.objects.link(twin)
    bpy.context.view_layer.update()
    assert bpy.ops.relight.update() == {"FINISHED"}
    for k in power:
        bpy.data.lights[k].energy = 0.0
    bpy.data.lights["Lamp A"].energy = 0.0
    d = office_delta_e(info, relit_office(info), truth["Lamp A"])
    for k, p in power.items():
        bpy.data.lights[k].energy = p
    bpy.data.objects.remove(twin)
    bpy.context.view_layer.update()
    print(f"virtual twin of lamp A vs A alone: {d:.2f} CIEDE2000")
    assert d <= 2.0, d


REOPEN = r"""
import json, sys
sys.path[:0] = [ROOT, HERE]
import bpy
from scenes.addon import register_repo_addon
register_repo_addon()
bpy.ops.wm.open_mainfile(filepath=BLEND)
scene = bpy.context.scene
out = {"virtual_before": list(scene["relight_status"]["virtual"])}
bpy.data.objects["Virtual"].location.x += 0.5
bpy.context.view_layer.update()
out["update"] = sorted(bpy.ops.relight.update())
out["virtual_after"] = list(scene["relight_status"]["virtual"])
out["lamps"] = list(scene["relight_status"]["lamps"])
out["maps"] = sorted(im.name for im in bpy.data.images if im.name.endswith(".relight.Virtual"))
print("RELIGHT_REOPEN_JSON " + json.dumps(out))
"""


def test_virtual_lamp_survives_save_and_reopen(office, tmp_path):
    """Saved and reopened in a fresh process (no result in memory): the virtual lamp stays
    virtual, and Update after moving it recomputes the room with it off in the photo."""
    import json
    info, power, truth = office
    assert bpy.ops.relight.precompute(preset="medium") == {"FINISHED"}
    v = add_point("Virtual", VIRTUAL, 150.0)
    assert bpy.ops.relight.update() == {"FINISHED"}
    for im in bpy.data.images:
        if im.packed_file is None and len(im.pixels):
            im.pack()
    blend = str(tmp_path / "virtual.blend")
    bpy.ops.wm.save_as_mainfile(filepath=blend, copy=True)
    bpy.data.objects.remove(v)
    code = REOPEN.replace("ROOT", repr(ROOT)).replace("HERE", repr(HERE)).replace("BLEND", repr(blend))
    proc = subprocess.run([sys.executable, "-c", code], cwd=str(tmp_path), capture_output=True,
                          text=True, timeout=600)
    line = next((ln for ln in proc.stdout.splitlines() if ln.startswith("RELIGHT_REOPEN_JSON ")), None)
    assert proc.returncode == 0 and line, (proc.stdout[-3000:], proc.stderr[-3000:])
    out = json.loads(line.split(" ", 1)[1])
    assert out["virtual_before"] == ["Virtual"] and out["virtual_after"] == ["Virtual"]
    assert out["update"] == ["FINISHED"] and "Virtual" in out["lamps"]
    assert len(out["maps"]) == len(info.objects)
