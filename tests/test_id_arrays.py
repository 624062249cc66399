"""Arrays the bridge reads back from ID properties are its own copies.

``np.asarray`` of an ID property array shares the property's memory (the buffer protocol, on
both Blender lines), and Blender frees that memory when the property is set again or its ID is
removed.  AR mode's Update read the first object's fitted spheres from its shadow group that
way, removed the group and wrote a new one from them: the spheres came from freed memory, and
on Blender 5.2 the next render's shadow changed from run to run (CIEDE2000 3.6-8.6 against a
bound of 4.0 in test_ar_composite's chain; the stored spheres read back as zeros).  The readers
now copy (blender/ids.py ``array``): what they return shares no memory with the property and
keeps its values after the ID is gone.
"""
import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from helpers.blender import addon_module  # noqa: E402

SPHERES = [0.1, -0.2, 0.3, 0.05, 0.4, 0.5, -0.6, 0.07]      # x, y, z, radius per sphere
HULL = [0.2, 0.1, 0.3, 0.4]


def _group(**props):
    ng = bpy.data.node_groups.new("Relight test group", "ShaderNodeTree")
    for k, v in props.items():
        ng[k] = v
    return ng


def _kept_after_removal(ng, arrays, expected):
    """The arrays share no memory with ``ng``'s array properties and keep their values once
    ``ng`` is removed and its memory handed out again."""
    views = [np.asarray(ng[k]) for k in ng.keys() if not isinstance(ng[k], str)]
    for a in arrays:
        assert not any(np.shares_memory(a, v) for v in views)
    bpy.data.node_groups.remove(ng)
    for _ in range(20):                      # hand the freed memory out again
        bpy.data.node_groups.remove(_group(x=[0.0] * len(SPHERES)))
    for a, e in zip(arrays, expected):
        assert np.allclose(a, e)


def test_the_premise_np_asarray_shares_an_id_property_s_memory():
    ng = _group(a=[1.0, 2.0, 3.0])
    view = np.asarray(ng["a"], float)
    ng["a"][0] = 9.0
    assert view[0] == 9.0                    # a view, not a copy: why ids.array copies
    ids = addon_module("relight_addon.blender.ids")
    copy = ids.array(ng["a"])
    ng["a"][1] = 7.0
    assert list(copy) == [9.0, 2.0, 3.0]
    bpy.data.node_groups.remove(ng)


def test_sphere_groups_give_copies():
    sn = addon_module("relight_addon.blender.sphere_nodes")
    ng = _group(**{sn.SPHERES_KEY: SPHERES, sn.HULL_KEY: HULL, sn.BOUND_KEY: HULL})
    centres, radii, hull = sn.group_spheres(ng)
    centre, radius = sn.group_bound(ng)
    a = np.reshape(SPHERES, (-1, 4))
    _kept_after_removal(ng, [centres, radii, hull[0], centre],
                        [a[:, :3], a[:, 3], HULL[:3], HULL[:3]])
    assert radius == HULL[3] and hull[1] == HULL[3]


def test_ar_shadow_groups_and_lights_give_copies():
    ar = addon_module("relight_addon.blender.ar")
    ar_write = addon_module("relight_addon.blender.ar_write")
    ng = _group(relight_ar_spheres=SPHERES, relight_ar_hull=HULL)
    centres, radii, hull, _ = ar._group_fit(ng)
    a = np.reshape(SPHERES, (-1, 4))
    _kept_after_removal(ng, [centres, radii, hull[0]], [a[:, :3], a[:, 3], HULL[:3]])
    # the lights stored in the scene's AR state (ID property groups)
    ng = _group(lights=[{"direction": [0.0, 0.6, 0.8], "solid_angle": 0.01, "half_angle": 0.05,
                         "radiance": [5.0, 4.0, 3.0], "share": 0.5}])
    (d, _, _, radiance, _), = ar_write.light_terms(ng["lights"])
    views = [np.asarray(ng["lights"][0][k]) for k in ("direction", "radiance")]
    assert not any(np.shares_memory(x, v) for x in (d, radiance) for v in views)
    bpy.data.node_groups.remove(ng)
    assert np.allclose(radiance, [5.0, 4.0, 3.0]) and np.allclose(d, [0.0, 0.6, 0.8])
