"""Polygon lights (core/lights.py, kind POLYGON): a virtual emissive mesh's faces, lit like any
light.  Truth: the closed-form view factor of a differential area to a parallel rectangle at
one of its corners (Howell's catalogue, C-11), independent of the code's polygon form factor."""
import math

import numpy as np
import pytest

from relight_addon.core.geometry.raycast import make_occluder
from relight_addon.core.lights import POLYGON, Lights, light_irradiance
from relight_addon.core.scene import SceneData


def corner_view_factor(a, b, h):
    """Differential area to a parallel a x b rectangle at height h, under one of its corners."""
    x, y = a / h, b / h
    sx, sy = math.sqrt(1 + x * x), math.sqrt(1 + y * y)
    return (x / sx * math.atan(y / sx) + y / sy * math.atan(x / sy)) / (2 * math.pi)


def _ceiling_rectangle(a, b, h, facing_down=True):
    """A rectangle [0, a] x [0, b] at height h as two triangles (a, b, c, c), emitting down."""
    p = np.array([[0, 0, h], [a, 0, h], [a, b, h], [0, b, h]], float)
    tris = np.array([p[[0, 1, 2, 2]], p[[0, 2, 3, 3]]])
    if facing_down:                        # counter-clockwise seen from below
        tris = tris[:, [0, 2, 1, 3]][:, [0, 1, 2, 2]]
    return tris


@pytest.mark.parametrize("a,b,h", [(1.0, 0.5, 1.0), (0.3, 0.3, 2.0), (2.0, 1.0, 0.25)])
def test_polygon_light_matches_the_rectangle_view_factor(a, b, h):
    tris = _ceiling_rectangle(a, b, h)
    lights = Lights.polygons(0, tris, np.ones((2, 3)) * 3.0)
    assert np.allclose(lights.emit_axis, [0, 0, -1])
    unocc, occ = light_irradiance(lights, np.zeros((1, 3)), np.array([[0, 0, 1.0]]), rays=64)
    want = 3.0 * corner_view_factor(a, b, h)
    assert unocc[0, :, 0].sum() == pytest.approx(want, rel=1e-6)
    assert occ[0, :, 0].sum() == pytest.approx(want, rel=1e-6)   # no occluder: unoccluded
    # behind the light (above it), a face that emits downwards gives nothing
    back, _ = light_irradiance(lights, np.array([[0.1, 0.1, h + 0.5]]), np.array([[0, 0, -1.0]]))
    assert np.all(back == 0)


def test_polygon_light_samples_cover_the_face_uniformly():
    """Half the light hidden by a panel just below it: what is seen is the other half's view
    factor, so the samples over the two triangles must spread by area and be weighted by the
    kernel.  Two corners' points see the hidden half at different angles."""
    a, b, h = 1.0, 0.6, 0.8
    tris = _ceiling_rectangle(a, b, h)
    lights = Lights.polygons(0, tris, np.ones((2, 3)))
    z = h - 1e-3                                   # a panel over x in [0, a / 2]
    panel = np.array([[[-1, -1, z], [a / 2, -1, z], [a / 2, 2, z]],
                      [[-1, -1, z], [a / 2, 2, z], [-1, 2, z]]])
    occ = make_occluder(panel)
    pts = np.array([[0.0, 0.0, 0.0], [a, 0.0, 0.0]])
    _, got = light_irradiance(lights, pts, np.tile([0, 0, 1.0], (2, 1)), occluder=occ, rays=512)
    got = got[:, :, 0].sum(axis=1)
    # from the corner under x = 0 the visible half [a/2, a] is the difference of two rectangles
    near = corner_view_factor(a, b, h) - corner_view_factor(a / 2, b, h)
    far = corner_view_factor(a / 2, b, h)           # from under x = a: the half next to it
    assert got[0] == pytest.approx(near, rel=0.03)
    assert got[1] == pytest.approx(far, rel=0.03)


def test_lamps_as_polygons_keeps_the_power_and_drops_the_patches():
    floor = np.array([[[0, 0, 0], [4, 0, 0], [4, 4, 0], [0, 4, 0]]], float)
    lamp = _ceiling_rectangle(0.5, 0.4, 2.0)
    two_sided = np.concatenate([lamp, lamp[:, [0, 2, 1, 3]][:, [0, 1, 2, 2]]])
    corners = np.concatenate([floor, two_sided])
    n = len(corners)
    data = SceneData(corners=corners, rho=[0.5, 0.5, 0.5],
                     emission=np.r_[[[0, 0, 0]], np.tile([2.0, 1.0, 0.5], (4, 1))],
                     lamp=np.r_[-1, [0] * 4], lamp_names=["Panel"],
                     occluder=np.r_[True, [False] * 4])
    new = data.lamps_as_polygons([0])
    assert new.n_patches == 1 and n == 5 and np.all(new.lamp == -1)
    L = new.lights
    assert len(L) == 4 and np.all(L.kind == POLYGON) and np.all(L.lamp == 0)
    area = 0.5 * np.linalg.norm(np.cross(L.corners[:, 2] - L.corners[:, 0],
                                         L.corners[:, 3] - L.corners[:, 1]), axis=1)
    # 0.2 m^2, both sides
    assert (area[:, None] * L.intensity).sum(0) == pytest.approx([0.8, 0.4, 0.2])
    # two rows face down, two up; each row bounds its face
    assert sorted(np.round(L.emit_axis[:, 2]).tolist()) == [-1, -1, 1, 1]
    assert np.all(np.linalg.norm(L.corners - L.position[:, None], axis=2) <= L.radius[:, None]
                  + 1e-12)
    # the floor under the panel gets its light from the front rows only
    unocc, _ = light_irradiance(L, np.array([[0.25, 0.2, 0.0]]), np.array([[0, 0, 1.0]]))
    want = 2.0 * 4 * corner_view_factor(0.25, 0.2, 2.0)
    assert unocc[0, :, 0].sum() == pytest.approx(want, rel=1e-6)
