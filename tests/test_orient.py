"""Faces turned to their photographed side, and faces lit on both sides (core/relight/orient.py),
against the same scene modelled the right way round."""
import dataclasses

import numpy as np

from relight_addon.core.geometry.raycast import make_occluder
from relight_addon.core.radiosity.precompute import solve_radiosity
from relight_addon.core.relight.orient import orient
from relight_addon.core.scene import SceneData, quads_from_boxes
from scenes.testscenes import flip, subdivide_quads

ROOM = flip(quads_from_boxes([2.0, 1.5, 1.25], [4.0, 3.0, 2.5]))        # inward faces


def _room(outward=(), panel=False):
    """A 4 x 3 x 2.5 room (faces split 2 x 2), a lamp under the ceiling at x = 1 and one at
    x = 3, optionally a thin panel at x = 2 between them (a single quad facing -x)."""
    faces = np.concatenate([subdivide_quads(f, 2) for f in ROOM])
    turn = np.zeros(len(faces), bool)
    turn[list(outward)] = True
    faces[turn] = flip(faces[turn])
    parts = [faces]
    if panel:
        parts.append(np.array([[[2.0, 2.5, 0.0], [2.0, 0.5, 0.0], [2.0, 0.5, 1.8], [2.0, 2.5, 1.8]]]))
    lamps = np.array([[[x - 0.3, 1.2, 2.4], [x - 0.3, 1.8, 2.4], [x + 0.3, 1.8, 2.4],
                       [x + 0.3, 1.2, 2.4]] for x in (1.0, 3.0)])
    corners = np.concatenate(parts + [lamps])
    n = len(corners)
    emission = np.zeros((n, 3))
    emission[-2:] = 20.0
    lamp = np.full(n, -1)
    lamp[-2:] = [0, 1]
    occluder = np.ones(n, bool)
    occluder[-2:] = False
    return SceneData(corners, np.where(lamp[:, None] >= 0, 0.0, 0.6), emission, lamp,
                     ["A", "B"], occluder=occluder, viewpoint=np.array([0.5, 0.5, 1.5]))


def test_outward_shell_is_turned_round_and_solves_like_the_right_one():
    wrong = list(range(0, 24, 3))                      # every third face of the shell
    sc = _room(outward=wrong)
    occ = make_occluder(sc.occluder_triangles())
    o = orient(sc, occ)
    assert sorted(np.flatnonzero(o.flipped).tolist()) == wrong
    assert len(o.back_of) == 0
    right = solve_radiosity(_room(), "draft", seed=1).patch_radiosity()
    fixed = solve_radiosity(o.scene, "draft", seed=1).patch_radiosity()
    np.testing.assert_allclose(fixed[:24], right[:24], rtol=0.03, atol=1e-3 * right.max())


def test_a_panel_lit_from_both_sides_gets_a_back():
    sc = _room(panel=True)
    o = orient(sc, make_occluder(sc.occluder_triangles()))
    panel = 24
    assert not o.flipped[panel]                        # the camera (x = 0.5) sees its -x side
    assert o.back_of.tolist() == [panel]
    back = o.scene.n_patches - 1
    _, nrm = o.scene.area_normal()
    np.testing.assert_allclose(nrm[back], -nrm[panel])
    assert not o.scene.occluder[back] and o.scene.image is None or o.scene.image[back] < 0
    # every per-patch array covers the back (``virtual`` did not: a copy of the scene failed)
    for name in ("rho", "emission", "lamp", "occluder", "group", "virtual"):
        assert len(getattr(o.scene, name)) == o.scene.n_patches, name
    assert dataclasses.replace(o.scene).n_patches == o.scene.n_patches
    # the back reflects lamp B's light (at x = 3): its radiosity is far from zero
    sol = solve_radiosity(o.scene, "draft", seed=2)
    B = sol.patch_radiosity()
    assert B[back].sum() > 0.3 * B[panel].sum()


def test_faces_looked_at_in_chunks_decide_as_at_once(monkeypatch):
    """A scan's faces are looked at CHUNK at a time (its rays at once held 620 MB at 200k
    faces): in chunks of 7 faces, the outward faces and the panel's back come out the same,
    and each face's evidence lands on that face (not another chunk's)."""
    import relight_addon.core.relight.orient as orient_module
    wrong = list(range(0, 24, 3))
    sc = _room(outward=wrong, panel=True)
    occ = make_occluder(sc.occluder_triangles())
    whole = orient(sc, occ)
    faces = np.flatnonzero(sc.lamp < 0)
    lit, camera, _, _ = orient_module.side_evidence(sc, occ, faces)
    monkeypatch.setattr(orient_module, "CHUNK", 7)
    chunked = orient(sc, occ)
    assert np.array_equal(chunked.flipped, whole.flipped)
    assert chunked.back_of.tolist() == whole.back_of.tolist() == [24]
    lit7, camera7, _, _ = orient_module.side_evidence(sc, occ, faces)
    assert np.array_equal(camera7, camera)
    np.testing.assert_allclose(lit7, lit, rtol=0.25, atol=1e-3 * lit.max())


def test_a_box_standing_inside_out_on_the_floor_is_turned_whole_on_every_seed():
    """A 0.4 m box modelled inside out, standing on the floor: its bottom lies where the floor
    is, and the rays from its inside towards the bottom met the floor's coincident face about
    as often as the bottom.  Two of its sides then had 0.88 of their rays on the box, below
    the 0.9 the inside-out test asked for, and stayed turned in on some seeds (the relit box at
    draft read 0.19 for 0.30)."""
    room = _room()
    box = flip(quads_from_boxes([2.0, 0.6, 0.2], [0.4, 0.4, 0.4]))          # inward faces
    n0 = room.n_patches - 2                                               # before the lamps
    corners = np.concatenate([room.corners[:n0], box, room.corners[n0:]])
    lamp = np.concatenate([room.lamp[:n0], np.full(len(box), -1), room.lamp[n0:]])
    emission = np.concatenate([room.emission[:n0], np.zeros((len(box), 3)), room.emission[n0:]])
    occluder = lamp < 0
    group = np.concatenate([np.zeros(n0, np.int32), np.ones(len(box), np.int32),
                            np.full(2, 2, np.int32)])
    sc = SceneData(corners, np.where(lamp[:, None] >= 0, 0.0, 0.6), emission, lamp, ["A", "B"],
                   occluder=occluder, group=group, viewpoint=np.array([0.5, 0.5, 1.5]))
    occ = sc.make_occluder()          # knows each triangle's face: the rays' objects
    for seed in range(6):
        o = orient(sc, occ, seed=seed)
        assert o.flipped[n0:n0 + len(box)].all(), (seed, np.flatnonzero(o.flipped))
        assert not o.flipped[:n0].any(), seed
