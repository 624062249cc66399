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


def smoothstep(x):
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def _one_minus_cos(s):
    """1 - cos(asin s) without the cancellation of 1 - cos for small caps (float32 in shaders)."""
    sq = s * s
    return sq / (1.0 + np.sqrt(np.maximum(1.0 - sq, 0.0)))


def cap_visibility(points, lamp_pos, lamp_radius, centre, radius):
    """Fraction (n,) of the lamp (a disk of ``lamp_radius`` at ``lamp_pos``, each (3,) or
    (n, 3)) seen from ``points`` (n, 3) past one sphere (``centre`` (3,), ``radius``)."""
    p = np.asarray(points, float)
    to_l = np.asarray(lamp_pos, float) - p
    to_c = np.asarray(centre, float) - p
    d_l = np.maximum(np.linalg.norm(to_l, axis=-1), 1e-12)
    d_c = np.maximum(np.linalg.norm(to_c, axis=-1), 1e-12)
    cos_g = np.clip(np.sum(to_l * to_c, axis=-1) / (d_l * d_c), -1.0, 1.0)
    gamma = np.arccos(cos_g)
    s_l = np.minimum(lamp_radius / d_l, 1.0)
    s_o = np.minimum(radius / d_c, 1.0)
    th_l, th_o = np.arcsin(s_l), np.arcsin(s_o)
    om_l, om_o = _one_minus_cos(s_l), _one_minus_cos(s_o)      # Omega / 2 pi
    width = np.maximum(2.0 * np.minimum(th_l, th_o), EPS_ANGLE)
    # overlap / Omega_L, written so that a point lamp (Omega_L = 0) takes its limit
    blocked = (np.minimum(om_o / np.maximum(om_l, 1e-30), 1.0)
               * smoothstep((th_l + th_o - gamma) / width))
    blocked = np.where(d_c < d_l, blocked, 0.0)          # a sphere behind the lamp
    blocked = np.where(d_c < radius, 1.0, blocked)       # a receiver inside the object
    return np.clip(1.0 - blocked, 0.0, 1.0)


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
    part = None
    if hull is not None:
        part = 1.0 - cap_visibility(points, lamp_pos, lamp_radius, hull[0], hull[1])
    blocked = (1.0 - cap_visibility(points, lamp_pos, lamp_radius, c, r)
               for c, r in zip(centres, radii))
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
