"""Which object closes a point in: every direction from it meets that object first.

A closed object (a box, a lamp shade) has an inside the photo never shows; the room the camera
stands in is closed too, and is not such an object.  Rays leave the point in ENCLOSURE_RAYS
directions spread over the sphere; when they all hit something and at least ENCLOSED_SHARE of
them hit one object first (the others may meet a face lying on one of its own: a box's bottom
on the floor), that object closes the point in.

A lamp so closed in lights only that object's inside, which no photo shows (the object's
faces are turned to their outside, orient.py): the solve leaves its lights dark
(:func:`dark_inside`), and the diagnosis names it.
"""
from __future__ import annotations

import copy
import dataclasses

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


def lamp_points(scene, lamp):
    """Where lamp ``lamp`` emits from: its light's centre, or its patches' centres."""
    lights = scene.lights
    pts = [lights.position[i] for i in np.flatnonzero(lights.lamp == lamp)
           if lights.kind[i] != 2]                                      # (a sun is outside)
    sel = np.flatnonzero(scene.lamp == lamp)
    if len(sel):
        _, normal = scene.area_normal()
        c = scene.corners[sel].mean(axis=1)
        pts += list(c + 1e-4 * normal[sel])
    return pts


def enclosed_lamps(scene, occluder):
    """{lamp: group of the closed object it is inside} (not the room the camera is in)."""
    from ..geometry.extent import bounding_diagonal
    out = {}
    camera = None
    if scene.viewpoint is not None:
        camera = enclosing_group(scene, occluder, scene.viewpoint)
    for k in range(scene.n_lamps):
        pts = lamp_points(scene, k)
        if not pts:
            continue
        g = enclosing_group(scene, occluder, pts[0])
        if g is not None and g != camera and \
                bounding_diagonal(scene.corners[np.asarray(scene.group) == g]) > 0:
            out[k] = g
    return out


def dark_inside(scene, occluder):
    """``scene`` with the lights of the lamps :func:`enclosed_lamps` finds dimmed to 0 (a copy;
    the lamps themselves, their names and powers in the photo, stay): otherwise the floor's
    elements across a box's contact with it carry the inside's light out (a lamp in the test
    room's box: its outside fell from 0.356 to 0.304 when the lamp was switched off).  A lamp
    made of emitting faces keeps its emission."""
    lights = scene.lights
    if occluder is None or not len(lights):
        return scene
    inside = enclosed_lamps(scene, occluder)
    rows = np.isin(lights.lamp, list(inside))
    if not rows.any():
        return scene
    new = copy.copy(scene)
    new.lights = dataclasses.replace(lights, intensity=np.where(rows[:, None], 0.0,
                                                                lights.intensity))
    return new
