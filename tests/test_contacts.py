"""Contact lines (radiosity.contacts): where an object stands on a face, the face's elements that
the line crosses are split, so that what straddles lit and buried is small.  Truth: the box's
footprint, known from the scene's construction."""
import numpy as np

from relight_addon.core.radiosity.contacts import contact_segments, split_at_contacts
from relight_addon.core.radiosity.hierarchy import Hierarchy
from scenes.testscenes import clutter_furnace

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
