"""Gather entries spread over their source's children by form factor (radiosity.source_split),
checked against pyviewfactor's exact double contour integral."""
import numpy as np
import pytest

from relight_addon.core.radiosity.hierarchy import Hierarchy
from relight_addon.core.radiosity.links import LeafGather
from relight_addon.core.radiosity.source_split import split_sources
from relight_addon.core.scene import SceneData

from helpers.formfactors import pvf_ff


def _room_corner():
    """A 0.3 m floor square 0.4 m from a 2 x 2 m wall, facing each other's half-space."""
    floor = np.array([[0.2, 0.4, 0.0], [0.5, 0.4, 0.0], [0.5, 0.7, 0.0], [0.2, 0.7, 0.0]])  # +z
    wall = np.array([[0.0, 1.1, 0.0], [2.0, 1.1, 0.0], [2.0, 1.1, 2.0], [0.0, 1.1, 2.0]])  # -y
    corners = np.stack([floor, wall])
    return SceneData(corners, np.full((2, 3), 0.5), np.zeros((2, 3)), np.full(2, -1), [])


def test_split_entries_carry_each_childs_own_form_factor():
    pytest.importorskip("pyviewfactor")
    scene = _room_corner()
    h = Hierarchy(scene)
    kids = h.split(np.array([1]))                       # the wall's four children ...
    h.split(np.arange(kids[0], kids[0] + 4))            # ... and their sixteen
    F = pvf_ff(scene.corners[0], scene.corners[1])
    near = np.zeros(h.n, bool)
    near[0] = True
    gather = LeafGather(np.array([0]), np.array([1]), np.array([F]), np.array([0.8 * F]), near)
    assert split_sources(h, gather, m=4, near=0.0, levels=2) == 5
    assert sorted(gather.source) == list(range(h.n - 16, h.n))
    assert gather.F.sum() == pytest.approx(F, rel=1e-3)         # the parts add up
    assert np.allclose(gather.FV, 0.8 * gather.F)                # visibility kept
    truth = np.array([pvf_ff(scene.corners[0], h.corners[s]) for s in gather.source])
    print("shares", np.round(gather.F / F, 4), "truth", np.round(truth / F, 4))
    # by area every grandchild would get 1/16; their own form factors are 0.008-0.23 of F
    assert np.ptp(truth / F) > 0.1
    assert np.allclose(gather.F, truth, rtol=0.01, atol=1e-4 * F)


def test_far_sources_and_leaf_sources_are_left_alone():
    scene = _room_corner()
    h = Hierarchy(scene)
    h.split(np.array([1]))
    gather = LeafGather(np.array([0, 0]), np.array([1, 3]), np.array([0.1, 0.01]),
                        np.array([0.1, 0.01]), np.ones(h.n, bool))
    # the wall's radius (1.4 m) is under 10 x its distance to the floor square: not split
    assert split_sources(h, gather, m=2, near=10.0, levels=3) == 0
    # element 3 is a leaf (a child of the wall): never split
    assert split_sources(h, gather, m=2, near=0.0, levels=3) == 1
    assert 3 in gather.source and 1 not in gather.source
