"""Which object closes a point in: every direction from it meets that object first.

A closed object (a box, a lamp shade) has an inside the photo never shows; the room the camera
stands in is closed too, and is not such an object.  Rays leave the point in ENCLOSURE_RAYS
directions spread over the sphere; when they all hit something and at least ENCLOSED_SHARE of
them hit one object first (the others may meet a face lying on one of its own: a box's bottom
on the floor), that object closes the point in.
"""
from __future__ import annotations

import numpy as np

ENCLOSURE_RAYS = 64
ENCLOSED_SHARE = 0.75


def sphere_directions(n):
    """``n`` unit directions spread evenly over the sphere (a Fibonacci lattice)."""
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    r = np.sqrt(np.maximum(1.0 - z * z, 0.0))
    phi = np.pi * (3.0 - np.sqrt(5.0)) * i
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def enclosing_group(scene, occluder, point):
    """The patch group (object) closing ``point`` in, or None."""
    if occluder is None or getattr(occluder, "patch_of_triangle", None) is None:
        return None
    d = sphere_directions(ENCLOSURE_RAYS)
    _, prim = occluder.first_hit(np.broadcast_to(np.asarray(point, float), d.shape).copy(), d)
    if np.any(prim < 0):
        return None
    groups, counts = np.unique(np.asarray(scene.group)[occluder.patch_of_triangle[prim]],
                               return_counts=True)
    best = int(np.argmax(counts))
    return int(groups[best]) if counts[best] >= ENCLOSED_SHARE * len(prim) else None
