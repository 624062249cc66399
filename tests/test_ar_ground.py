"""The ground under AR mode's objects (core/ar/ground.py), which EEVEE's World projects the
photo onto below the horizon: on a set of a floor, a table top and a wall, against the
rectangles the set was built from."""
from __future__ import annotations

import numpy as np

from relight_addon.core.ar.ground import ground_plane


def _quad(corners):
    a, b, c, d = (np.array(p, float) for p in corners)
    return np.array([[a, b, c], [a, c, d]])


FLOOR = _quad([(-2, -1, 0), (3, -1, 0), (3, 4, 0), (-2, 4, 0)])          # 25 m^2 at z = 0
TABLE = _quad([(0, 0, 0.75), (1.2, 0, 0.75), (1.2, 0.8, 0.75), (0, 0.8, 0.75)])
WALL = _quad([(-2, 4, 0), (3, 4, 0), (3, 4, 2.5), (-2, 4, 2.5)])           # faces -y
UNDERSIDE = TABLE[:, ::-1] - np.array([0, 0, 0.03])                        # faces down


def test_the_floor_under_an_object_on_the_floor():
    tri = np.concatenate([FLOOR, TABLE, WALL, UNDERSIDE])
    height, (x0, x1, y0, y1) = ground_plane(tri, 0.3)
    assert height == 0.0 and (x0, x1, y0, y1) == (-2.0, 3.0, -1.0, 4.0)


def test_the_level_under_the_object_else_the_largest():
    """An object over the table top sees the top below it; one beside the table the floor;
    without a point, the level of the most area (the floor)."""
    tri = np.concatenate([FLOOR, TABLE, WALL, UNDERSIDE])
    height, (x0, x1, y0, y1) = ground_plane(tri, 1.0, at=(0.6, 0.4))
    assert abs(height - 0.75) < 1e-12 and (x0, x1, y0, y1) == (0.0, 1.2, 0.0, 0.8)
    assert ground_plane(tri, 1.0, at=(2.0, 2.0))[0] == 0.0
    assert ground_plane(tri, 1.0)[0] == 0.0
    assert ground_plane(tri, 0.5, at=(0.6, 0.4))[0] == 0.0      # under the table: the floor


def test_a_floor_facing_down_is_a_ground():
    """A receiver's shading does not depend on its side: a floor made facing down is as
    good a ground."""
    height, bounds = ground_plane(FLOOR[:, ::-1], 0.3)
    assert height == 0.0 and bounds == (-2.0, 3.0, -1.0, 4.0)


def test_nothing_level_under_the_object():
    assert ground_plane(WALL, 1.0) is None
    assert ground_plane(FLOOR, -0.1) is None                 # the object under the floor
    assert ground_plane(np.zeros((0, 3, 3)), 1.0) is None
    assert ground_plane(np.zeros((2, 3, 3)), 1.0) is None    # degenerate triangles


def test_a_tilted_floor_is_not_a_ground():
    """A ramp of 30 degrees (normal z = 0.87) is no horizontal ground: the projection assumes
    a level one."""
    c, s = np.cos(np.radians(30)), np.sin(np.radians(30))
    ramp = _quad([(0, 0, 0), (1, 0, 0), (1, c, s), (0, c, s)])
    assert ground_plane(ramp, 2.0) is None
