"""Leaves partly covered by a touching object: a box standing on the floor, a cabinet against a
wall.

A leaf's irradiance is the weighted mean over its quadrature points, and a point under a box
gets none: a floor leaf that a box covers by half has half the irradiance, so half the
radiosity, of its exposed half.  As a source the same leaf was counted dark twice: its light
leaves from the exposed half only (rays aimed at the buried half are blocked, so a link's
visibility already says so), yet the gather multiplied that visibility by the leaf's mean
radiosity over both halves.  In the closed Cornell box 0.4 % of the emitted power was lost
that way at medium (0.2 % at high), and the boxes' faces, which see the floor right next to
them, came out 3-5 % dark against Mitsuba.

Here every quadrature point of a leaf that gathers on its quadrature points casts a few
cosine-distributed rays; a point whose rays all meet the backs of faces is inside a closed
object (buried).  The leaf's exposure ``a`` is the weight of its other points.  As a source an
element's value is its power over its exposed area (``LeafSystem.set_exposure``).  A lamp
patch's emission under the object stays there (precompute._lamp_emission takes it out again).
Texels still read the leaf's mean irradiance: read as H / a, the few straddling leaves (a of
1/4, 1/2, 3/4 at medium) put steps into the interpolated indirect light that the lamp fit
followed (family room 5: rho^ 0.435 -> 0.406, lamp off 0.54 -> 0.66 CIEDE2000).  Leaves
that gather at their centre only (far from all their sources) and leaves buried whole (no light
reaches them) keep a = 1.
"""
from __future__ import annotations

import numpy as np

from ..geometry.raycast import ray_offset
from ..geometry.sampling import cosine_directions, quadrature

BURIED_RAYS = 8         # per quadrature point


def leaf_exposure(h, leaves, near, occluder, scene, m, rng, scale):
    """Exposure (L,) in (0, 1] of each leaf (see the module docstring).  ``near`` (h.n,) bool:
    the leaves that gather on their m x m quadrature points (links.final_form_factors);
    ``occluder`` knows the patch of each of its triangles (``patch_of_triangle``)."""
    L = len(leaves)
    a = np.ones(L)
    patch_of = getattr(occluder, "patch_of_triangle", None) if occluder is not None else None
    if L == 0 or patch_of is None or near is None or m <= 1:
        return a
    patch_of = np.asarray(patch_of)
    test = np.flatnonzero(near[leaves])
    if len(test) == 0:
        return a
    pts, w = quadrature(h.corners[leaves[test]], m)            # (t, m*m, 3), (t, m*m)
    _, patch_normal = scene.area_normal()
    n = h.normal[leaves[test]]
    eps = ray_offset(scale)
    mm, R = pts.shape[1], BURIED_RAYS
    buried = np.zeros((len(test), mm), bool)
    chunk = max(1, (1 << 20) // (mm * R))
    for c0 in range(0, len(test), chunk):
        c1 = min(c0 + chunk, len(test))
        x1, x2 = rng.random((2, c1 - c0, mm, R, 1))
        nn = n[c0:c1, None, None]
        D = cosine_directions(nn, x1, x2)
        O = np.broadcast_to(pts[c0:c1, :, None] + eps * nn, D.shape)
        _, prim = occluder.first_hit(O.reshape(-1, 3), D.reshape(-1, 3))
        hit = prim >= 0
        back = hit & (np.einsum("ij,ij->i", patch_normal[patch_of[np.maximum(prim, 0)]],
                                D.reshape(-1, 3)) > 0)
        buried[c0:c1] = back.reshape(c1 - c0, mm, R).all(axis=2)
    exposed = (w * ~buried).sum(axis=1) / np.maximum(w.sum(axis=1), 1e-300)
    a[test] = np.where(exposed > 0, exposed, 1.0)
    return a
