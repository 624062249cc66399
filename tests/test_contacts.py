"""Contact lines (radiosity.contacts): where an object stands on a face, the face's elements that
the line crosses are split, so that what straddles lit and buried is small.  Truth: the box's
footprint, known from the scene's construction."""
import numpy as np
import pytest

from relight_addon.core.radiosity.contacts import contact_segments, split_at_contacts
from relight_addon.core.radiosity.hierarchy import Hierarchy
from relight_addon.core.radiosity.precompute import solve_radiosity
from relight_addon.core.radiosity.presets import PRESETS
from scenes.testscenes import clutter_furnace, hover_furnace

FOOT = (0.25, 0.35)          # clutter_furnace's touching box: x and y in [0.25, 0.35], on z = 0


def _floor(scene):
    _, n = scene.area_normal()
    c = scene.corners.mean(axis=1)
    return int(np.flatnonzero((n[:, 2] > 0.99) & (np.abs(c[:, 2]) < 1e-9) &
                              (scene.corners[:, :, 0].max(axis=1) > 0.9))[0])


def test_a_box_on_the_floor_gives_its_footprint_on_the_floor_only():
    scene = clutter_furnace(0.9, touching=True)
    seg, patch = contact_segments(scene, 1.7)
    floor = _floor(scene)
    assert len(seg) > 0 and np.all(patch == floor)
    # every segment lies on the footprint's outline, and together they cover all four sides
    pts = seg.reshape(-1, 3)
    assert np.allclose(pts[:, 2], 0.0)
    on_x = np.isclose(pts[:, 0], FOOT[0]) | np.isclose(pts[:, 0], FOOT[1])
    on_y = np.isclose(pts[:, 1], FOOT[0]) | np.isclose(pts[:, 1], FOOT[1])
    assert np.all(on_x | on_y)
    length = np.linalg.norm(seg[:, 1] - seg[:, 0], axis=1)
    assert length.sum() >= 4 * 0.1 - 1e-9
    # the room's corners (walls meeting the floor along its border) and the gaps between
    # cubes and panels that do not touch are not contacts
    assert len(contact_segments(clutter_furnace(0.9, touching=False), 1.7)[0]) == 0


def test_split_leaves_no_large_element_across_the_footprint():
    scene = clutter_furnace(0.9, touching=True)
    h = Hierarchy(scene)
    seg, patch = contact_segments(scene, 1.7)
    floor = _floor(scene)
    min_area = 1e-3
    made = split_at_contacts(h, seg, patch, min_area)
    assert made > 0
    leaves = h.leaves()
    on_floor = leaves[h.patch[leaves] == floor]
    c = h.corners[on_floor]
    lo, hi = c[:, :, :2].min(axis=1), c[:, :, :2].max(axis=1)
    # an element crosses the outline when the outline's line passes strictly inside it
    crosses = np.zeros(len(on_floor), bool)
    for axis in (0, 1):
        other = 1 - axis
        for x in FOOT:
            inside_line = (lo[:, axis] < x - 1e-9) & (hi[:, axis] > x + 1e-9)
            overlaps = (lo[:, other] < FOOT[1]) & (hi[:, other] > FOOT[0])
            crosses |= inside_line & overlaps
    assert crosses.any()                            # 0.25 is a dyadic line, 0.35 is not
    assert np.all(h.area[on_floor[crosses]] <= min_area)
    # and only where the outline is: elements away from it keep their size
    far = (hi[:, 0] < 0.2) | (lo[:, 0] > 0.4) | (hi[:, 1] < 0.2) | (lo[:, 1] > 0.4)
    assert np.all(h.area[on_floor[far]] > min_area)


def _boxes_over_the_floor(scene):
    """(x0, x1, y0, y1) of each box whose bottom hovers just above the floor (hover_furnace)."""
    _, n = scene.area_normal()
    c = scene.corners
    low = (n[:, 2] < -0.99) & (np.abs(c[:, :, 2] - 0.001).max(axis=1) < 1e-9)
    return [(c[i, :, 0].min(), c[i, :, 0].max(), c[i, :, 1].min(), c[i, :, 1].max())
            for i in np.flatnonzero(low)]


def test_what_hovers_over_a_face_gives_gap_lines_and_no_contacts():
    """Gap lines (radiosity.contacts): the outlines of the boxes 1 mm above the floor, on the
    floor, and of the box 1 mm off the wall, on the wall; none of them touches (no contact
    line), and the box that stands on the floor of clutter_furnace gives contacts, no gaps."""
    scene = hover_furnace(0.9)
    assert len(contact_segments(scene, 1.7)[0]) == 0
    seg, patch = contact_segments(scene, 1.7, gaps=True)
    floor = _floor(scene)
    wall = int(np.flatnonzero(np.all(np.isclose(scene.corners[:, :, 0], 1.0), axis=1))[0])
    assert set(patch.tolist()) == {floor, wall}
    on_floor = seg[patch == floor]
    boxes = _boxes_over_the_floor(scene)
    assert len(boxes) == 8
    # each floor segment lies on a box's outline, 1 mm up, and every box has its outline
    pts = on_floor.reshape(-1, 3)
    assert np.allclose(pts[:, 2], 0.001)
    found = set()
    for p in pts:
        for k, (x0, x1, y0, y1) in enumerate(boxes):
            on_x = (np.isclose(p[0], x0) or np.isclose(p[0], x1)) and y0 - 1e-9 <= p[1] <= y1 + 1e-9
            on_y = (np.isclose(p[1], y0) or np.isclose(p[1], y1)) and x0 - 1e-9 <= p[0] <= x1 + 1e-9
            if on_x or on_y:
                found.add(k)
                break
        else:
            raise AssertionError(f"{p} is on no box's outline")
    assert found == set(range(8))
    assert np.allclose(seg[patch == wall].reshape(-1, 3)[:, 0], 0.999)
    touching = clutter_furnace(0.9, touching=True)
    assert len(contact_segments(touching, 1.7, gaps=True)[0]) == 0
    assert len(contact_segments(touching, 1.7)[0]) > 0


@pytest.mark.parametrize("rho", [0.5, 0.9])
def test_draft_keeps_a_furnace_with_hovering_clutter_exact(rho):
    """Issue 47: boxes of 1-10 cm 1 mm above the floor and 1 mm apart, thin panels 1 mm apart,
    a box 1 mm off a wall, everything at E = 1 and rho.  A floor element across a box's
    outline gathered at one point, which sees the box's underside or the room: draft's worst
    face was 5.8 % off at rho 0.5 and 38 % at 0.9 (its worst leaf 12 % and 42 %).  With the
    gap lines split 2 levels (Quality.gap_levels) every face and leaf is within 1 % (measured
    < 1e-3 % on seeds 0-3)."""
    for seed in (0, 1):
        sol = solve_radiosity(hover_furnace(rho), PRESETS["draft"], seed=seed)
        faces = np.abs(sol.patch_radiosity()[:, 0] * (1 - rho) - 1.0)
        leaves = np.abs(sol.radiosity()[:, 0] * (1 - rho) - 1.0)
        print(f"draft rho {rho} seed {seed}: worst face {faces.max():.2e}, leaf {leaves.max():.2e}")
        assert faces.max() < 0.01 and leaves.max() < 0.01
