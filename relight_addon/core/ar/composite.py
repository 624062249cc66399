# SPDX-License-Identifier: GPL-3.0-or-later
"""The AR composite (differential rendering, Debevec 1998, with the shadow factor of
env_shadow.py in place of the second render): numpy twin of the compositor's node maths
(blender/ar_nodes.py).

The render (Cycles or EEVEE) draws the virtual objects lit by the World, the receivers as
holdouts for camera rays (their position, normal and coverage go to passes), the World
transparent.  Per pixel, with the photo P, the render's premultiplied colour C and alpha a,
the receivers' coverage c and their shadow factor F at the pixel's receiver point:

    out = C + P (1 - a - c (1 - F))

the photo where nothing is drawn (1 - a), darkened by F where a receiver is (c), the objects
over it.  F, per RGB channel, from the virtual objects ``casters`` (each its spheres, silhouette
sphere: relight.spheres) under the environment (lighting.EnvironmentLighting), with what the
set hides from itself at that point (receiver_view.py: the lights' parts S_j, the residual's
part O, the visibility cone):

    F = (E_res O prod_o (1 - w_o (1 - V_res,o)) + sum_j E_j S_j prod_o V_j,o)
        / (E_res O + sum_j E_j S_j)

E_res the residual's irradiance, E_j the lights', V_res,o / V_j,o their parts seen past object
o (env_shadow.residual_visibility / light_visibility), w_o whether o is inside the point's
visibility cone (:func:`seen`).  The residual's part seen past the set and past the
objects is the product O x prod: what the set hides and what an object hides are taken as
independent (O - 1 + prod, disjoint, removed twice where an object hides directions the set
already hides: a dark ring on the walls behind an object standing in a corner).  Without a
set that hides anything (S = O = w = 1) and for one object, F is env_shadow.env_shadow_factor
(within DARK_FLOOR).  A point the set leaves in the dark keeps its photo (both sums get
DARK_FLOOR x E).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .env_shadow import light_visibility, residual_irradiance, residual_visibility
from .main_light import light_irradiance

COVERAGE_FLOOR = 1e-6     # a pixel's receiver coverage below it: no receiver there
DARK_FLOOR = 1e-4         # of the unoccluded irradiance: what a point in the set's dark keeps
SEEN_MIN_ANGLE = 1e-3     # rad: the smallest angular size of a silhouette in seen()


@dataclass
class Caster:
    """A virtual object's shadow caster in world coordinates: its spheres (centres (m, 3),
    radii (m,)) and silhouette sphere ``hull`` (centre, radius)."""
    centres: np.ndarray
    radii: np.ndarray
    hull: tuple


def caster(centres, radii, hull):
    return Caster(np.asarray(centres, float).reshape(-1, 3), np.asarray(radii, float).ravel(),
                  (np.asarray(hull[0], float), float(hull[1])))


def smoothstep(x):
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def seen(points, hull, cone):
    """(n,) how much of the object (its silhouette sphere ``hull``) the points see through
    their visibility ``cone`` (n, 4) (receiver_view.py): 1 while the sphere's centre is inside
    the cone, down to 0 once it is one angular radius of the sphere outside."""
    v = np.asarray(hull[0], float) - np.asarray(points, float)
    d = np.maximum(np.linalg.norm(v, axis=1), 1e-12)
    cone = np.asarray(cone, float)
    gamma = np.arccos(np.clip(np.einsum("ij,ij->i", v / d[:, None], cone[:, :3]), -1.0, 1.0))
    theta = np.arccos(np.clip(cone[:, 3], -1.0, 1.0))
    alpha = np.arcsin(np.clip(hull[1] / d, 0.0, 1.0))
    return 1.0 - smoothstep((gamma - theta) / np.maximum(alpha, SEEN_MIN_ANGLE))


def receiver_factor(points, normals, casters, lighting, sun=None, openness=None, cone=None):
    """Shadow factor F (n, 3) of receivers (``points``, ``normals``) under ``lighting`` from
    the ``casters`` (a list of :class:`Caster`), with what the set hides at the points
    (receiver_view.py samples: ``sun`` (n, >= lights), ``openness`` (n, 3), ``cone`` (n, 4);
    None: nothing hidden).  See the module docstring."""
    p = np.asarray(points, float)
    n = len(p)
    nrm = np.asarray(normals, float)
    nrm = nrm / np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-300)
    e_amb = residual_irradiance(nrm, lighting)
    o = np.ones((n, 3)) if openness is None else np.asarray(openness, float)
    kept = np.ones_like(e_amb)
    for c in casters:
        w = np.ones(n) if cone is None else seen(p, c.hull, cone)
        v = residual_visibility(p, nrm, c.centres, c.radii, lighting, c.hull, e_amb)
        kept *= 1.0 - w[:, None] * (1.0 - v)
    lit = e_amb * o * kept
    received = e_amb * o
    total = e_amb.copy()
    lights = [lt for lt in lighting.lights if lt.solid_angle > 0]
    for j, light in enumerate(lights):
        e = light_irradiance(light, nrm)
        s_j = np.ones(n) if sun is None or j >= np.shape(sun)[1] else np.asarray(sun)[:, j]
        vis = np.ones(n)
        for c in casters:
            vis *= light_visibility(p, light, c.centres, c.radii, c.hull)
        lit += e * (s_j * vis)[:, None]
        received += e * s_j[:, None]
        total += e
    floor = DARK_FLOOR * total
    return np.clip((lit + floor) / (received + floor), 0.0, 1.0)


def composite(photo, colour, alpha, coverage, factor):
    """The composite (H, W, 3) of the module docstring: ``photo`` and ``colour`` (H, W, 3)
    linear, ``alpha`` and ``coverage`` (H, W), ``factor`` (H, W, 3)."""
    keep = 1.0 - alpha[..., None] - coverage[..., None] * (1.0 - factor)
    return colour + photo * keep
