# SPDX-License-Identifier: GPL-3.0-or-later
"""The clamped-cosine integral of a spherical cap: exact, including a cap across the horizon.

A sphere (or a disk light, or the cone of a main light) seen from a receiving point with normal
n is a cap of half-angle alpha (sin alpha = R / d) whose axis makes the angle beta with n.  Its
cosine-weighted solid angle over the receiver's hemisphere,

    C(beta, alpha) = integral over the cap of max(w.n, 0) dw,

is pi sin^2(alpha) cos(beta) while the cap is wholly above the horizon (beta <= pi/2 - alpha),
0 once it is wholly below (beta >= pi/2 + alpha), and in between (the cap straddles the
horizon; Snyder 1996, as written in Lagarde and de Rousiers 2014, "Moving Frostbite to PBR",
eq. 17), with x = sqrt(1 / sin^2 alpha - 1) = cot alpha and y = -x cot beta:

    C = (cos beta acos(y) - x sin beta sqrt(1 - y^2)) sin^2 alpha + atan(sin beta sqrt(1 - y^2) / x)

Seed 002 (eq. 4.3.1.3) keeps the first form everywhere, clamped at 0: at a cap centred on the
horizon it says 0 where the truth is alpha - sin alpha cos alpha, i.e. a shadow factor wrong by
0.12 (alpha = 50 deg), 0.23 (64 deg), 0.44 (85 deg): the case of the spheres of an object
standing on the receiver, which dip below its plane (tests/test_ar_env_shadow.py).  A receiver
inside the sphere (d <= R) sees it over the whole hemisphere: C = pi.

This module is the numpy twin of the shader's ``relight_cap_cosine`` (blender/shaders).
"""
from __future__ import annotations

import numpy as np


def cap_cosine_integral(cos_beta, sin2_alpha):
    """Exact C(beta, alpha) (see the module docstring), vectorised; ``cos_beta`` the cosine of
    the angle between the receiver's normal and the cap's axis, ``sin2_alpha`` = (R / d)^2
    (>= 1: the receiver is inside the sphere, C = pi).  Values in [0, pi]."""
    cb = np.clip(np.asarray(cos_beta, float), -1.0, 1.0)
    s2 = np.clip(np.asarray(sin2_alpha, float), 0.0, None)
    cb, s2 = np.broadcast_arrays(cb, s2)
    inside = s2 >= 1.0
    s2c = np.minimum(s2, 1.0 - 1e-12)
    above = cb * cb > s2c                                     # wholly above or wholly below
    sb = np.sqrt(np.maximum(1.0 - cb * cb, 0.0))
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        x = np.sqrt(1.0 / np.maximum(s2c, 1e-300) - 1.0)
        y = np.clip(-x * cb / np.maximum(sb, 1e-300), -1.0, 1.0)
        sy = sb * np.sqrt(np.maximum(1.0 - y * y, 0.0))
        straddle = (cb * np.arccos(y) - x * sy) * s2c + np.arctan2(sy, x)
    out = np.where(above, np.pi * s2c * np.maximum(cb, 0.0), straddle)
    out = np.where(inside, np.pi, out)
    return np.clip(np.nan_to_num(out, nan=0.0), 0.0, np.pi)


def seed_cap_cosine_integral(cos_beta, sin2_alpha):
    """Seed 002's eq. 4.3.1.3 (times pi): pi cos(beta) sin^2(alpha), clamped at 0 (exact only
    for a cap wholly above the horizon)."""
    cb = np.clip(np.asarray(cos_beta, float), -1.0, 1.0)
    s2 = np.clip(np.asarray(sin2_alpha, float), 0.0, 1.0)
    return np.pi * s2 * np.maximum(cb, 0.0)


def cone_sin2(half_angle):
    """sin^2 of a cone's half-angle (a main light of solid angle Omega: acos(1 - Omega/2pi))."""
    return np.sin(np.minimum(np.asarray(half_angle, float), np.pi / 2)) ** 2
