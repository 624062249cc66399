# SPDX-License-Identifier: GPL-3.0-or-later
"""Planar bilinear patches, the one shape of the core: four corners ``(a, b, c, d)``
counter-clockwise seen from the front, a triangle as ``(a, b, c, c)`` (core/scene.py says why).
Below everything that reads patches: the scene, the lights, form factors and sampling."""
from __future__ import annotations

import numpy as np

from ..numerics import nonzero


def bilinear_point(corners: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Points of bilinear patches.  corners (..., 4, 3), u and v broadcast to (...,)."""
    u = np.asarray(u)[..., None]
    v = np.asarray(v)[..., None]
    a, b, c, d = (corners[..., i, :] for i in range(4))
    return (1 - u) * (1 - v) * a + u * (1 - v) * b + u * v * c + (1 - u) * v * d


def quad_area_normal(corners: np.ndarray):
    """Area and unit normal of planar bilinear patches (triangles repeat a corner).

    Uses the diagonals: for a planar quad, area = |(c - a) x (d - b)| / 2, exact for triangles
    ``(a, b, c, c)`` too.
    """
    cross = np.cross(corners[..., 2, :] - corners[..., 0, :], corners[..., 3, :] - corners[..., 1, :])
    twice = np.linalg.norm(cross, axis=-1)
    normal = cross / nonzero(twice)[..., None]
    return 0.5 * twice, normal


def reverse_winding(corners):
    """The same patches facing the other way: (a, b, c, d) -> (a, d, c, b), triangles
    (a, b, c, c) -> (a, c, b, b) (the repeated corner stays last).  Works on (p, 4, ...)."""
    out = corners[:, [0, 3, 2, 1]]
    tri = np.all(corners[:, 2] == corners[:, 3], axis=tuple(range(1, corners.ndim - 1)))
    out[tri] = corners[tri][:, [0, 2, 1, 1]]
    return out
