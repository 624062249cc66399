# SPDX-License-Identifier: GPL-3.0-or-later
"""The ground under the virtual objects, as one horizontal rectangle: what the objects see
below their horizon where a renderer lights them from the environment map alone.

EEVEE lights an object by the World's map (its world probe): below the horizon it sees the
map's own ground, where Cycles (and a real object) see the receivers, which show the photo;
without this, a glossy object standing on a grey floor reflects the map's sunlit field.  So
the EEVEE world shows, below the horizon, the photo projected onto this rectangle
(blender/ar_write.py): a ray from the object's centre in direction d meets it at
centre + t d, t = (height - centre_z) / d_z.
"""
from __future__ import annotations

import numpy as np

UP = 0.95           # a receiver triangle is level when its unit normal's |z| is above this
HEIGHT_STEP = 0.01  # triangles within this of one height (m) are one level (a floor, a top)


def ground_plane(receiver_triangles, below, at=None):
    """(height, (x0, x1, y0, y1)) of the receivers' level triangles (t, 3, 3, world; facing
    up or down: a receiver's shading does not depend on its side) at one height under
    ``below`` (the object's centre), their bounds in x and y: the highest level with a
    triangle under the point ``at`` (x, y) (an object on a table top sees the top below it;
    past the top's edge EEVEE then sees the map's own ground), else the level with the most
    area; None when no receiver lies level under it."""
    tri = np.asarray(receiver_triangles, float).reshape(-1, 3, 3)
    if len(tri) == 0:
        return None
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area = 0.5 * np.linalg.norm(cross, axis=1)
    up = np.zeros(len(tri), bool)
    ok = area > 0
    up[ok] = np.abs(cross[ok, 2]) / (2.0 * area[ok]) > UP
    z = tri[:, :, 2].mean(axis=1)
    keep = up & np.isfinite(z) & (z < float(below))
    if not keep.any():
        return None
    level = np.round(z[keep] / HEIGHT_STEP).astype(np.int64)
    levels, inverse = np.unique(level, return_inverse=True)
    chosen = int(np.argmax(np.bincount(inverse, weights=area[keep])))
    if at is not None:
        under = _covers(tri[keep][:, :, :2], np.asarray(at, float)[:2])
        if under.any():
            chosen = int(inverse[under].max())          # levels sort by height
    on = np.flatnonzero(keep)[inverse == chosen]
    height = float(np.average(z[on], weights=area[on]))
    xy = tri[on][:, :, :2].reshape(-1, 2)
    x0, y0 = xy.min(axis=0)
    x1, y1 = xy.max(axis=0)
    return height, (float(x0), float(x1), float(y0), float(y1))


def _covers(tri2, p):
    """(t,) whether each triangle (t, 3, 2) holds the point p (2,) (edges included)."""
    a, b, c = tri2[:, 0], tri2[:, 1], tri2[:, 2]

    def side(u, v):
        return (v[:, 0] - u[:, 0]) * (p[1] - u[:, 1]) - (v[:, 1] - u[:, 1]) * (p[0] - u[:, 0])
    s1, s2, s3 = side(a, b), side(b, c), side(c, a)
    return ((s1 >= 0) & (s2 >= 0) & (s3 >= 0)) | ((s1 <= 0) & (s2 <= 0) & (s3 <= 0))
