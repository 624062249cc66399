"""A virtual emissive mesh (issue 11): a glowing panel added after Precompute with Relight Role
"virtual" is a lamp that is not in the photo.  Update gives it a map with the room's shadows
and interreflections; its light is added to the relit room, following the emission Strength.

Truth: the demo office of helpers.office (24 texels, 512-sample Cycles bakes), baked with
the true albedo and the panel alone (real lamps off), before the room is "photographed".
"""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from helpers.blender import pixels  # noqa: E402
from helpers.office import (SAMPLES, SIZE, office_delta_e, photographed_office, relit_office)  # noqa: E402

STRENGTH = 12.0            # Emission strength (radiance) of the panel


def _panel():
    """A 0.6 x 0.4 m emissive panel 2.3 m up, facing down (an Emission-only material)."""
    bpy.ops.mesh.primitive_plane_add(size=1.0, location=(3.6, 1.2, 2.3))
    obj = bpy.context.active_object
    obj.name = "Panel"
    obj.scale = (0.6, 0.4, 1.0)
    obj.rotation_euler = (np.pi, 0.0, 0.0)           # the plane's normal points down
    mat = bpy.data.materials.new("PanelGlow")
    mat.use_nodes = True            # Blender 4.5: a new material has no node tree before this
    nt = mat.node_tree
    for n in list(nt.nodes):
        nt.nodes.remove(n)
    emit = nt.nodes.new("ShaderNodeEmission")
    emit.inputs["Strength"].default_value = STRENGTH
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    nt.links.new(emit.outputs[0], out.inputs["Surface"])
    obj.data.materials.append(mat)
    bpy.context.view_layer.update()
    return obj


def test_virtual_emissive_panel_against_cycles(count_solves):
    from scenes.bake import bake_lighting

    def panel_alone(info, power):
        panel = _panel()
        truth = bake_lighting({**{k: 0.0 for k in power}, "Panel": STRENGTH}, samples=SAMPLES,
                              seed=1, texture_size=SIZE, objects=info.objects)
        bpy.data.materials.remove(panel.material_slots[0].material)
        bpy.data.objects.remove(panel)
        return truth
    info, power, truth, _ = photographed_office(panel_alone)
    assert bpy.ops.relight.precompute(preset="medium") == {"FINISHED"}

    def textures():
        return {n: float(pixels(bpy.data.objects[n].material_slots[0].material.node_tree
                                 .nodes["T"].image)[..., :3].mean()) for n in info.objects}
    before = textures()
    solves = count_solves()
    panel = _panel()
    panel.relight_role = "virtual"
    assert bpy.ops.relight.update() == {"FINISHED"}
    # a small emissive mesh is polygon lights: added to the solved room like a light
    assert solves == [], "Update solved the room again for a virtual emissive mesh"
    # the photo never saw the panel: the room it is explained by, and so the shadow-free
    # textures, stay (measured while the panel was read as an occluder: Wall South +3.8 %)
    after = textures()
    for n in info.objects:
        assert after[n] == pytest.approx(before[n], rel=0.015), n
    name = "Panel/PanelGlow"
    mat = bpy.data.objects["Floor"].material_slots[0].material
    assert f"M {name}" in mat.node_tree.nodes                  # its own map
    assert panel.material_slots[0].material.name == "PanelGlow"  # the panel is not relit
    st = bpy.context.scene["relight_status"]
    assert name in list(st["lamps"])
    for k in power:                                           # the real lamps off
        bpy.data.lights[k].energy = 0.0
    got = relit_office(info)
    d = office_delta_e(info, got, truth)
    for n in info.objects:
        g, w = np.mean(got[n]), float(np.mean(np.asarray(truth[n], np.float64)))
        print(f"  {n}: relit {g:.4f} truth {w:.4f} ({100 * (g / max(w, 1e-12) - 1):+.1f} %)")
    # the panel adds light where the truth has it: the floor under it is lit
    floor_got = float(np.mean(got["Floor"]))
    floor_want = float(np.mean(np.asarray(truth["Floor"], np.float64)))
    print(f"virtual emissive panel, real lamps off: {d:.2f} CIEDE2000; floor mean "
          f"{floor_got:.4f} vs truth {floor_want:.4f}")
    # Measured: 1.93 as polygon lights (2.07 as lamp patches of a new solve; 2.40 while the
    # panel, which the photo never saw, was an occluder of the room the photo is explained by),
    # every surface 1-17 % too bright, the ceiling +10 %: the panel's back lights it from
    # 0.5 m, and the ceiling's irradiance in the photo (bounced light only) is modelled 6 % low
    # at medium relative to the walls (+5 % at high), so its reflectance is the least known
    # one; an area light facing up there shows the same (+13 %).  The same panel emitting from
    # its front only: 1.25, as an area light in its place (1.24).
    assert floor_got == pytest.approx(floor_want, rel=0.1)
    assert d <= 2.1
    # its light follows the material's emission Strength through a driver (keyframable)
    glow = bpy.data.materials["PanelGlow"]
    glow.node_tree.nodes["Emission"].inputs["Strength"].default_value = 2 * STRENGTH
    bpy.context.view_layer.update()
    doubled = relit_office(info)
    assert float(np.mean(doubled["Floor"])) == pytest.approx(2 * floor_got, rel=1e-6)
    glow.node_tree.nodes["Emission"].inputs["Strength"].default_value = STRENGTH
    bpy.context.view_layer.update()
    # with the real lamps back on, the photo's light is there again and the panel's is added
    for k, p in power.items():
        bpy.data.lights[k].energy = p
    both = relit_office(info)
    assert np.mean(both["Floor"]) > floor_got
    # moving the panel makes its map again on the kept room; deleting it removes its map
    floor_map = mat.node_tree.nodes[f"M {name}"].image
    at_first = pixels(floor_map).copy()
    panel.location = (1.2, 2.6, 2.3)
    bpy.context.view_layer.update()
    assert bpy.ops.relight.update() == {"FINISHED"}
    assert solves == []
    mat = bpy.data.objects["Floor"].material_slots[0].material     # Update writes it again
    moved = pixels(mat.node_tree.nodes[f"M {name}"].image)
    assert np.abs(moved - at_first).max() > 0.1 * np.abs(at_first).max()
    glow_mat = panel.material_slots[0].material
    bpy.data.objects.remove(panel)
    bpy.data.materials.remove(glow_mat)
    bpy.context.view_layer.update()
    assert bpy.ops.relight.update() == {"FINISHED"}
    assert solves == []
    mat = bpy.data.objects["Floor"].material_slots[0].material
    assert f"M {name}" not in mat.node_tree.nodes
    assert name not in list(bpy.context.scene["relight_status"]["lamps"])


def test_a_virtual_lamp_undoes_and_redoes(count_solves):
    """Undo after the Update that inserted a virtual lamp gives the room's materials and maps
    back (no map of it left), redo gives its map back; an Update after the undo starts from
    the room's result again (no new solve) and gives the same maps."""
    from helpers.blender import add_point
    from helpers.office import map_images
    info, *_ = photographed_office(lambda info, power: None)
    assert bpy.ops.relight.precompute(preset="medium") == {"FINISHED"}
    room = map_images(info)
    bpy.ops.ed.undo_push(message="precomputed")
    add_point("Virtual", (3.8, 1.0, 1.6), 150.0)
    bpy.ops.ed.undo_push(message="lamp added")
    assert bpy.ops.relight.update() == {"FINISHED"}
    bpy.ops.ed.undo_push(message="updated")
    with_lamp = map_images(info)
    assert len(with_lamp) > len(room)                 # its own map on every relit surface

    def floor_nodes():
        return bpy.data.objects["Floor"].material_slots[0].material.node_tree.nodes
    assert "M Virtual" in floor_nodes()
    bpy.ops.ed.undo()
    assert "M Virtual" not in floor_nodes()
    assert map_images(info).keys() == room.keys()
    assert all(np.array_equal(room[n], a) for n, a in map_images(info).items())
    assert "Virtual" in bpy.data.objects              # the lamp itself is still there
    bpy.ops.ed.redo()
    assert "M Virtual" in floor_nodes()
    assert all(np.array_equal(with_lamp[n], a) for n, a in map_images(info).items())
    bpy.ops.ed.undo()
    solves = count_solves()
    assert bpy.ops.relight.update() == {"FINISHED"}   # after the undo: the lamp again
    assert solves == []
    got = map_images(info)
    assert "M Virtual" in floor_nodes()
    for n, a in with_lamp.items():
        assert np.allclose(got[n], a, atol=1e-5), n
