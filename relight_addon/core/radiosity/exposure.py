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
followed (family room 5: rho^ 0.435 -> 0.406, lamp off 0.54 -> 0.66 CIEDE2000).  A leaf that
gathers at its centre only (far from all its sources; every leaf at draft) is exposed or not by
that point (a = 1 or 0).  A leaf buried whole (a = 0) is no source: a ray that lands on a part
of it out in the open sees its nearest ancestor with an exposed part (LeafSystem.set_exposure),
and a texel on it reads that ancestor's exposed mean (read_in_the_open);
before, such leaves kept a = 1 and counted dark (clutter furnace, box on the floor, high, rho
0.9: 0.9 % -> 0.3 %).  At draft (one point per leaf, m = 1) every leaf is decided by its
centre: a floor leaf whose centre a box covers is no source (the clutter furnace at rho 0.99:
8 % low before, exact now), and its photographed open part is read in the open.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..geometry.raycast import ray_offset
from ..geometry.sampling import cosine_directions, quadrature
from ..numerics import safe_div
from .conserve import back_copies

BURIED_RAYS = 8         # per quadrature point


def leaf_exposure(h, leaves, near, occluder, scene, m, rng, scale):
    """Exposure (L,) in [0, 1] of each leaf (see the module docstring).  ``near`` (h.n,) bool:
    the leaves that gather on their m x m quadrature points (final_links.final_form_factors), the
    others gather at their centre, which decides for them (0 or 1; every leaf at draft, m = 1).
    ``occluder`` knows the patch of each of its triangles (``patch_of_triangle``)."""
    L = len(leaves)
    a = np.ones(L)
    patch_of = getattr(occluder, "patch_of_triangle", None) if occluder is not None else None
    if L == 0 or patch_of is None:
        return a
    patch_of = np.asarray(patch_of)
    _, patch_normal = scene.area_normal()
    # a face with a back copy (two-sided: conserve.back_copies) met from behind is open
    backed = back_copies(scene) >= 0
    eps = ray_offset(scale)
    on_points = np.zeros(L, bool) if near is None else near[leaves]
    for test in (np.flatnonzero(on_points), np.flatnonzero(~on_points)):
        if len(test) == 0:
            continue
        if on_points[test[0]]:
            pts, w = quadrature(h.corners[leaves[test]], m)      # (t, m*m, 3), (t, m*m)
        else:                                                  # at its centre
            pts, w = h.centroid[leaves[test]][:, None], np.ones((len(test), 1))
        buried = _buried(pts, h.normal[leaves[test]], occluder, patch_of, patch_normal, backed,
                         eps, rng)
        a[test] = safe_div((w * ~buried).sum(axis=1), w.sum(axis=1))
    return a


def _buried(pts, n, occluder, patch_of, patch_normal, backed, eps, rng):
    """(t, mm) bool: the points (t, mm, 3) on faces of normals n (t, 3) whose cosine rays all
    meet backs of faces (not ``backed``: those of two-sided faces)."""
    mm, R = pts.shape[1], BURIED_RAYS
    buried = np.zeros(pts.shape[:2], bool)
    chunk = max(1, (1 << 20) // (mm * R))
    for c0 in range(0, len(pts), chunk):
        c1 = min(c0 + chunk, len(pts))
        x1, x2 = rng.random((2, c1 - c0, mm, R, 1))
        nn = n[c0:c1, None, None]
        D = cosine_directions(nn, x1, x2)
        O = np.broadcast_to(pts[c0:c1, :, None] + eps * nn, D.shape)
        _, prim = occluder.first_hit(O.reshape(-1, 3), D.reshape(-1, 3))
        hit = prim >= 0
        p = patch_of[np.maximum(prim, 0)]
        back = hit & (np.einsum("ij,ij->i", patch_normal[p], D.reshape(-1, 3)) > 0) & ~backed[p]
        buried[c0:c1] = back.reshape(c1 - c0, mm, R).all(axis=2)
    return buried


def read_in_the_open(h, leaves, exposure, leaf_area):
    """A function of leaf values (L, ...) giving them back with every leaf buried whole
    (exposure 0) at the exposed-area mean of its nearest ancestor with an exposed part; None
    when no leaf is buried.  For texels: a texel whose centre lies on such a leaf is
    photographed, so part of its footprint is out in the open, lit as the open surface around
    it, while the leaf itself reads no light in the model (a table leg's foot on the office
    floor: four texels relit black with contact lines on)."""
    buried = np.flatnonzero(np.asarray(exposure) <= 0)
    if not len(buried):
        return None
    pos, anc = h.ancestor_pairs(leaves)
    w = leaf_area[pos] * exposure[pos]
    A = sp.csr_matrix((w, (anc, pos)), shape=(h.n, len(leaves)))
    exposed = np.asarray(A.sum(axis=1)).ravel()
    area = np.bincount(anc, leaf_area[pos], h.n)
    up = leaves[buried].copy()
    for _ in range(int(h.level[: h.n].max(initial=0)) + 1):
        move = (up >= 0) & (exposed[np.maximum(up, 0)] <= 1e-9 * area[np.maximum(up, 0)])
        if not move.any():
            break
        up[move] = h.parent[up[move]]
    ok = up >= 0
    rows, anc_ok = buried[ok], up[ok]
    R = sp.diags(1.0 / exposed[anc_ok]) @ A[anc_ok]

    def read(values):
        v = np.array(values, float)
        flat = v.reshape(len(v), -1)
        flat[rows] = R @ flat
        return v
    return read
