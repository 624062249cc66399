"""Soft shadow of a set of spheres: the fraction of a lamp seen past them (seed 002 §4.3.1).

Seen from a receiving point p, the lamp is a spherical cap of half-angle theta_L (a disk of
radius r_L at distance d_L: sin theta_L = r_L / d_L; a sun: its angular radius) and each sphere
(centre c, radius R) a cap of half-angle theta_O (sin theta_O = R / |c - p|), their axes
gamma apart.  The lamp's visible fraction past one sphere is 1 - overlap / Omega_L, with the
caps' overlap approximated as in ambient aperture lighting (Oat and Sander 2007):

    overlap = min(Omega_L, Omega_O) * smoothstep(0, 1, (theta_L + theta_O - gamma)
                                                       / (theta_L + theta_O - |theta_L - theta_O|))

(exact when one cap holds the other or they are apart, a smooth ramp between), Omega = 2 pi
(1 - cos theta).  Spheres farther than the lamp do not shadow it, a receiver inside a sphere
(inside the object, e.g. where it rests on the floor) sees none of it, and the spheres of a set
combine multiplicatively (as the issue and Iwanicki 2013 do) within the part of the lamp the
object's silhouette can hide (see sphere_visibility).  The cosine over the lamp's cap
and the lamp's shape (a rectangle is taken as the disk of the same area) are ignored: the
approximation's error against ray-traced shadows of the real mesh is measured in
benchmarks/bench_sphere_shadow.py.

This module is the numpy twin of the node group that the relit materials evaluate at render time
(blender/sphere_nodes.py): the same operations in the same order, so the two can be compared.
"""
from __future__ import annotations

import numpy as np

EPS_ANGLE = 1e-4          # smallest penumbra width (rad): a point lamp gets a hard edge
SUN_DISTANCE = 1.0e5      # a sun is a disk this far away along its direction (metres)
BOUND_SLACK = 1e-4        # relative growth of the bounding sphere: float32 rounding never culls


def smoothstep(x):
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def lamp_cap(points, lamp_pos, lamp_radius):
    """(unit vectors (n, 3) towards the lamp, distances (n,), half-angles (n,), Omega / 2 pi
    (n,)) of the lamp seen from ``points``.  The half-angle is at least EPS_ANGLE / 2: a point
    lamp is a cap that small (its umbra's edge is EPS_ANGLE wide), which keeps every ratio below
    finite."""
    p = np.asarray(points, float)
    to_l = np.asarray(lamp_pos, float) - p
    d_l = np.maximum(np.linalg.norm(to_l, axis=-1), 1e-12)
    th_l = np.maximum(np.arcsin(np.minimum(lamp_radius / d_l, 1.0)), 0.5 * EPS_ANGLE)
    om_l = 2.0 * np.sin(0.5 * th_l) ** 2                  # 1 - cos, without its cancellation
    return to_l / d_l[..., None], d_l, th_l, om_l


def blocked_part(points, lamp, centre, radius):
    """The part (n,) of the lamp (``lamp_cap``'s tuple) that one sphere hides from ``points``."""
    u, d_l, th_l, om_l = lamp
    to_c = np.asarray(centre, float) - np.asarray(points, float)
    d_c = np.maximum(np.linalg.norm(to_c, axis=-1), 1e-12)
    gamma = np.arccos(np.clip(np.sum(to_c * u, axis=-1) / d_c, -1.0, 1.0))
    s_o = np.minimum(radius / d_c, 1.0)
    th_o = np.arcsin(s_o)
    om_o = s_o * np.tan(0.5 * th_o)                       # 1 - cos, without its cancellation
    ratio = np.minimum(om_o / om_l, 1.0) * (d_c < d_l)    # overlap / Omega_L; none behind the lamp
    a = th_l + th_o                                       # the caps touch at gamma = a ...
    width = 2.0 * np.minimum(th_l, th_o)                  # ... and one holds the other at a - width
    x = np.where(width > 0, (a - gamma) / np.where(width > 0, width, 1.0), 0.0)
    return np.maximum(ratio * smoothstep(x), (d_c < radius).astype(float))   # inside: all


def cap_visibility(points, lamp_pos, lamp_radius, centre, radius):
    """Fraction (n,) of the lamp (a disk of ``lamp_radius`` at ``lamp_pos``, each (3,) or
    (n, 3)) seen from ``points`` (n, 3) past one sphere (``centre`` (3,), ``radius``)."""
    lamp = lamp_cap(points, lamp_pos, lamp_radius)
    return np.clip(1.0 - blocked_part(points, lamp, centre, radius), 0.0, 1.0)


def sphere_visibility(points, lamp_pos, lamp_radius, centres, radii, hull=None):
    """Fraction (n,) of the lamp seen from ``points`` past every sphere.

    Without ``hull``: the product over the spheres.  With ``hull`` = (centre, radius), a sphere
    whose silhouette stands for the object's (spheres.silhouette_sphere): the spheres' blocked
    parts b_i are taken as independent *within the part S of the lamp that the object can hide*
    (S = the hull's blocked part), B = max(S (1 - prod(1 - min(b_i / S, 1))), max b_i).  Near
    and far spheres of a thick object hide the same part of a large lamp; the plain product
    counts it twice (measured: up to +40 % of missing light at 128 spheres).  For a small lamp S
    is 0 or 1 and the rule is the larger of the max and the product.  One pass over the spheres
    (a running product and maximum), as the node groups evaluate it."""
    centres, radii = np.asarray(centres, float), np.asarray(radii, float)
    lamp = lamp_cap(points, lamp_pos, lamp_radius)
    part = None
    if hull is not None:
        part = blocked_part(points, lamp, hull[0], hull[1])
    blocked = (blocked_part(points, lamp, c, r) for c, r in zip(centres, radii))
    return combined_visibility(blocked, len(points), part)


def combined_visibility(blocked, n, part=None):
    """Visible fraction (n,) of a light past all the spheres, from the parts ``blocked`` (an
    iterable of (n,) arrays in [0, 1], one per sphere) that each sphere hides alone: the rule of
    :func:`sphere_visibility` (``part`` = the hull's blocked part S, or None for the plain
    product).  Shared by the lamps' shadows and the shadows under an environment
    (core/ar/env_shadow.py): one implementation."""
    hull = part is not None
    part = np.maximum(part, 1e-6) if hull else 1.0
    product = np.ones(n)
    maximum = np.zeros(n)
    for b in blocked:
        product = product * (1.0 - np.minimum(b / part, 1.0))
        maximum = np.maximum(maximum, b)
    if not hull:
        return np.clip(product, 0.0, 1.0)
    return np.clip(1.0 - np.maximum(part * (1.0 - product), maximum), 0.0, 1.0)


def bounding_sphere(centres, radii):
    """(centre (3,), radius) of a sphere holding every sphere of the set: centred on the middle
    of the centres' bounding box, grown by BOUND_SLACK."""
    c, r = np.asarray(centres, float).reshape(-1, 3), np.asarray(radii, float).reshape(-1)
    mid = 0.5 * (c.min(axis=0) + c.max(axis=0))
    reach = float((np.linalg.norm(c - mid, axis=1) + r).max())
    return mid, reach * (1.0 + BOUND_SLACK) + 1e-9


def may_shadow(points, lamp_pos, lamp_radius, bound):
    """Whether (n,) a sphere of the set inside ``bound`` = (centre, radius) can hide a part of
    the lamp from ``points``: False only where no half-line from the point meets both the
    bound and the lamp's ball, and then every sphere's blocked part is 0 and
    sphere_visibility gives exactly 1 (a sphere hides a part of the lamp only along
    directions that meet the lamp's cap and its own, and those half-lines meet both balls).

    Such points lie in the double cone tangent to both balls with its apex between them, at
    their internal centre of similitude S (the nappe on the bound's side holds the object's
    penumbra, the other the lamp's ball and what sees the object past it):
    |(p - S) x c| < |(p - S) . c| tan beta, c the unit vector from the lamp to the bound's
    centre, sin beta = (R + r) / D, D their distance (a line meets both balls only inside
    it).  Everything passes where the two balls meet.  Every quantity but p - S is the same
    for every point, so a material computes them once (Cycles folds them into constants):
    nine nodes a point and lamp.  Some points pass needlessly (between S and the object, off
    its penumbra; behind the lamp): only render time.  The lamp's radius is grown by the
    point lamp's smallest cap (lamp_cap's EPS_ANGLE / 2) seen from twice its distance to the
    bound's far side: a point lamp's spheres' penumbra (under a millimetre wide) beyond that is
    cut, nothing else."""
    p = np.asarray(points, float)
    lamp = np.asarray(lamp_pos, float)
    centre, big = np.asarray(bound[0], float), float(bound[1])
    cl = centre - lamp
    dist = float(np.linalg.norm(cl))
    # lamp_cap gives a point lamp a cap of EPS_ANGLE / 2 (a penumbra that thin): a ball of that
    # angle seen from twice the lamp's distance to the bound's far side holds it there
    r = max(float(lamp_radius), 0.0) + 2.0 * (dist + big) * np.sin(0.5 * EPS_ANGLE)
    both = big + r
    if dist <= both:
        return np.ones(p.shape[:-1], bool)
    c = cl / dist
    # p - S from p - centre (S = centre - c D R / (R + r)): a sun's S is 1e5 m away, and the
    # difference of two such points keeps few digits in float32 (the materials' nodes)
    e = p - centre
    along = e @ c + dist * big / both
    across = np.linalg.norm(np.cross(e, c), axis=-1)
    return across < np.abs(along) * (both / np.sqrt(dist * dist - both * both))


def world_bound(bound, matrix):
    """(centre, radius, lamp growth) in world space for a ``bound`` (centre, radius) given in the
    frame of the 4x4 ``matrix``: the centre carried, the radius times the largest scale, and the
    factor (largest / mean scale) by which may_shadow must grow the lamp's radius.  The spheres
    are evaluated in the object's frame, where the lamp's radius is divided by the mean scale:
    mapped to the world, that frame's spheres and lamp are ellipsoids inside these spheres, so
    may_shadow in world space with them passes wherever it passes in the object's frame."""
    m = np.asarray(matrix, float)
    scale = np.linalg.norm(m[:3, :3], axis=0)
    centre = m[:3, :3] @ np.asarray(bound[0], float) + m[:3, 3]
    return centre, float(bound[1] * scale.max()), float(scale.max() / max(scale.mean(), 1e-12))


def sun_disk(direction, angle):
    """(position, radius) standing for a sun shining along ``direction`` (towards the scene)
    with angular diameter ``angle``: a disk SUN_DISTANCE away."""
    d = np.asarray(direction, float)
    d = d / np.linalg.norm(d)
    return -d * SUN_DISTANCE, SUN_DISTANCE * np.tan(0.5 * max(float(angle), 0.0))


def to_local(points, matrix):
    """``points`` (n, 3) in the frame of the 4x4 ``matrix`` (its inverse applied): the spheres
    are fitted in the object's own coordinates and evaluated there."""
    m = np.linalg.inv(np.asarray(matrix, float))
    p = np.asarray(points, float)
    return p @ m[:3, :3].T + m[:3, 3]
