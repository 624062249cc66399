# SPDX-License-Identifier: GPL-3.0-or-later
"""Whether an inserted object goes through a receiver (a surface of the photographed scene).

An object standing on a floor touches it (its lowest vertices lie on the plane); one that
goes through it has vertices on both sides of a receiver face, over that face.  The test: for
every receiver triangle, the object's vertices whose projection along the face's normal falls
inside it; the object crosses the face when some of them lie more than ``tolerance`` below it
and some more than ``tolerance`` above.  (An object wholly under a table top does not cross
it; a finely tessellated object is needed for a face smaller than the object's triangles.)
"""
from __future__ import annotations

import numpy as np

TOLERANCE = 2e-3          # of the object's size: resting on a surface is not going through it


def crosses(object_vertices, receiver_triangles, tolerance=TOLERANCE):
    """Whether the object (its world ``object_vertices`` (n, 3)) goes through any of the
    ``receiver_triangles`` (t, 3, 3)."""
    v = np.asarray(object_vertices, float).reshape(-1, 3)
    tri = np.asarray(receiver_triangles, float).reshape(-1, 3, 3)
    if len(v) == 0 or len(tri) == 0:
        return False
    tol = tolerance * max(float(np.ptp(v, axis=0).max()), 1e-9)
    for a, b, c in tri:
        n = np.cross(b - a, c - a)
        area2 = float(np.linalg.norm(n))
        if area2 <= 0:
            continue
        n = n / area2
        d = (v - a) @ n
        # barycentric coordinates of the projections (Cramer's rule in the face's plane)
        e0, e1 = b - a, c - a
        w = v - a - d[:, None] * n
        d00, d01, d11 = e0 @ e0, e0 @ e1, e1 @ e1
        den = d00 * d11 - d01 * d01
        if den <= 0:
            continue
        s = (d11 * (w @ e0) - d01 * (w @ e1)) / den
        t = (d00 * (w @ e1) - d01 * (w @ e0)) / den
        over = (s >= 0) & (t >= 0) & (s + t <= 1)
        if np.any(over & (d < -tol)) and np.any(over & (d > tol)):
            return True
    return False
