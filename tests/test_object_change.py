"""What a virtual object changes in a solved room (core/relight/object_change.py), against
closed-form form factors.

A closed room where every face emits 1 and reflects 0.5 (radiosity exactly 2 everywhere, every
face a lamp patch), solved without the object; a 1 x 1 m panel facing down 1 m above the floor
is then inserted.  Seen from a floor leaf, the panel shows its own radiosity where the room (a
lamp) was: the leaf's indirect irradiance gains F B_panel and its direct light loses F x 2, F the
leaf's form factor to the panel (the exact point-to-polygon value averaged over the leaf;
checked against pyviewfactor in test_formfactor.py).  The cone rays estimate both.
"""
import numpy as np

from relight_addon.core.geometry.formfactor import point_to_polygon
from relight_addon.core.radiosity.precompute import solve_radiosity
from relight_addon.core.relight.object_change import (ObjectsOnlyOccluder, VirtualObjects,
                                                      _leaf_lookup, leaf_change,
                                                      object_radiosity)
from relight_addon.core.scene import SceneData, bilinear_point, quads_from_boxes
from scenes.testscenes import flip, subdivide_quads

B_PANEL = 3.0
B_ROOM = 2.0               # 1 / (1 - 0.5)
B_BACK = 0.5               # the panel's back, seen from the ceiling


def _room_and_panel():
    room = flip(quads_from_boxes([2.0, 2.0, 1.5], [4.0, 4.0, 3.0]))
    room = np.concatenate([subdivide_quads(room[0], 4), room[1:]])      # floor 4 x 4
    panel = quads_from_boxes([2.0, 2.0, 1.0], [1.0, 1.0, 0.02])[:1]     # bottom face: down
    corners = np.concatenate([room, panel])
    n = len(corners)
    emission = np.ones((n, 3))
    emission[-1] = 0.0
    lamp = np.zeros(n, int)
    lamp[-1] = -1
    virtual = np.zeros(n, bool)
    virtual[-1] = True
    return SceneData(corners, 0.5, emission, lamp, ["room"], group=np.arange(n),
                     virtual=virtual)


def test_a_panel_over_the_floor_changes_each_leaf_by_its_form_factor():
    full = _room_and_panel()
    room = full.without_virtual()
    sol = solve_radiosity(room, "medium", seed=0)
    assert np.allclose(sol.basis, B_ROOM)
    panel = VirtualObjects.of(full.virtual_last(), slice(room.n_patches, full.n_patches))
    B_obj = np.stack([np.full((1, 1, 3), B_PANEL), np.full((1, 1, 3), B_BACK)])
    d_dir, d_ind = leaf_change(panel, B_obj, sol, sol.context["occluder"], _leaf_lookup(sol),
                               sol.context["scale"], seed=0, rays=2048)
    h = sol.hierarchy
    floor = np.flatnonzero(h.patch[sol.leaves] < 16)
    g = (np.arange(8) + 0.5) / 8
    u, v = [a.ravel() for a in np.meshgrid(g, g)]
    pts = bilinear_point(h.corners[sol.leaves[floor]][:, None], u[None], v[None]).reshape(-1, 3)
    F = point_to_polygon(pts, np.tile([0.0, 0.0, 1.0], (len(pts), 1)),
                         np.repeat(panel.corners, len(pts), axis=0),
                         np.repeat(panel.normal, len(pts), axis=0)).reshape(len(floor), -1)
    F = F.mean(axis=1)
    seen = F > 0.02
    assert seen.sum() >= 8
    gained = d_ind[0, floor, 0] / (F * B_PANEL)
    lost = -d_dir[0, floor, 0] / (F * B_ROOM)
    print(f"{seen.sum()} floor leaves see the panel (F {F[seen].min():.3f}-{F[seen].max():.3f}): "
          f"gain / F B_panel {gained[seen].min():.3f}-{gained[seen].max():.3f}, "
          f"loss / F B_room {lost[seen].min():.3f}-{lost[seen].max():.3f}")
    assert np.abs(gained[seen] - 1.0).mean() < 0.03 and np.abs(gained[seen] - 1.0).max() < 0.1
    assert np.abs(lost[seen] - 1.0).mean() < 0.03 and np.abs(lost[seen] - 1.0).max() < 0.1
    # the ceiling sees the panel's back where it saw the floor
    up = np.flatnonzero(h.normal[sol.leaves][:, 2] < -0.5)
    assert len(up) == 1
    c = h.corners[sol.leaves[up[0]]]
    g = (np.arange(16) + 0.5) / 16
    u, v = [a.ravel() for a in np.meshgrid(g, g)]
    pts = bilinear_point(c[None], u, v)
    F_up = point_to_polygon(pts, np.tile([0.0, 0.0, -1.0], (len(pts), 1)),
                            np.repeat(panel.corners[:, ::-1], len(pts), axis=0),
                            np.repeat(-panel.normal, len(pts), axis=0)).mean()
    print(f"ceiling: F to the panel's back {F_up:.4f}, gain {d_ind[0, up[0], 0]:.4f} vs "
          f"{F_up * B_BACK:.4f}, loss {-d_dir[0, up[0], 0]:.4f} vs {F_up * B_ROOM:.4f}")
    assert abs(d_ind[0, up[0], 0] / (F_up * B_BACK) - 1) < 0.05
    assert abs(-d_dir[0, up[0], 0] / (F_up * B_ROOM) - 1) < 0.05


def test_a_panel_in_a_furnace_reflects_the_room_on_both_sides():
    """Both sides of an open panel see only the room (radiosity 2): each reflects rho x 2."""
    full = _room_and_panel()
    room = full.without_virtual()
    sol = solve_radiosity(room, "draft", seed=0)
    panel = VirtualObjects.of(full.virtual_last(), slice(room.n_patches, full.n_patches))
    B = object_radiosity(panel, sol, sol.context["occluder"], _leaf_lookup(sol),
                         sol.context["scale"], rays=8, seed=0)
    assert B.shape == (2, 1, 1, 3)
    assert np.allclose(B, 0.5 * B_ROOM, rtol=1e-9)


def test_objects_only_occluder_counts_what_the_room_leaves_free():
    """Blocked = the objects block the segment and the room does not."""
    class Fixed:
        def __init__(self, blocked):
            self.blocked = np.asarray(blocked, bool)

        def segments_occluded(self, origins, ends):
            return self.blocked[np.asarray(origins)[:, 0].astype(int)]
    o = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]])
    room, objects = Fixed([False, True, False, True]), Fixed([False, False, True, True])
    got = ObjectsOnlyOccluder(room, objects).segments_occluded(o, o + 1)
    assert got.tolist() == [False, False, True, False]
    assert ObjectsOnlyOccluder(None, objects).segments_occluded(o, o + 1).tolist() == \
        [False, False, True, True]


def test_an_object_takes_away_only_the_lamp_light_the_leaves_had():
    """light_change reads the leaves' light as the solve lit it.  A proxy's leaves are lit
    against the full mesh (shadowfree.proxy_lamp_view); here a floor under a point light,
    solved with a lamp view in which a sheet blocks the light: a panel put between the lamp
    and the floor takes nothing away.  Lit against the floor's own occluder (which has no
    sheet), the same panel took away the light of its shadow, which the leaves never had."""
    from relight_addon.core.geometry.raycast import make_occluder
    from relight_addon.core.lights import POINT, Lights
    from relight_addon.core.radiosity.presets import get_preset
    from relight_addon.core.relight.object_change import light_change
    floor = subdivide_quads(np.array([[0.0, 0, 0], [4, 0, 0], [4, 4, 0], [0, 4, 0]]), 4)
    m = np.eye(4)
    m[:3, 3] = [2.0, 2.0, 2.0]
    lights = Lights.make(POINT, 0, m, np.full(3, 100.0))
    n = len(floor)
    room = SceneData(floor, 0.5, np.zeros((n, 3)), np.full(n, -1), ["lamp"], lights=lights)
    assert np.allclose(room.area_normal()[1], [0, 0, 1])              # facing the lamp
    sheet = np.array([[[0.0, 0, 1.5], [4, 0, 1.5], [4, 4, 1.5]], [[0, 0, 1.5], [4, 4, 1.5],
                                                                   [0, 4, 1.5]]])
    panel = quads_from_boxes([2.0, 2.0, 1.0], [1.0, 1.0, 0.02])[:1]
    full = SceneData(np.concatenate([floor, panel]), 0.5, np.zeros((n + 1, 3)),
                     np.full(n + 1, -1), ["lamp"], lights=lights,
                     virtual=np.arange(n + 1) == n)
    objects = VirtualObjects.of(full.virtual_last(), slice(n, n + 1))
    q = get_preset("draft")
    changes = {}
    for view, light_occluder in (("own", None), ("sheet", make_occluder(sheet))):
        sol = solve_radiosity(room, q, seed=0, light_occluder=light_occluder)
        lit = sol.light_occ[0, :, 0]
        d = light_change(objects, sol, sol.context["occluder"], sol.context["scale"], q, 0)
        changes[view] = (lit.max(), d[0, :, 0].min(), np.abs(d).max())
    lit, lost, _ = changes["own"]
    assert lit > 1.0 and lost < -0.5 * lit            # the panel shadows the floor's middle
    lit, _, moved = changes["sheet"]
    assert lit == 0.0 and moved == 0.0
