"""Direct irradiance from the lamps at arbitrary surface points (texel mode, visibility probes).

For every (point, lamp patch) pair: the exact point-to-polygon form factor F (unoccluded), and
the visible fraction from ``rays`` segments to area-uniform lamp points on a shifted R2
sequence, weighted by the point-to-point kernel (the ratio estimator of the solver's final
links).  The first FIRST_RAYS rays decide: only pairs that see part of the lamp get the rest.  Irradiance = exitance x F (x visible fraction), summed per lamp.
"""
from __future__ import annotations

import numpy as np

from ..geometry.formfactor import point_to_polygon
from ..geometry.sampling import area_uniform_uv
from ..radiosity.links import _R2, _kernel
from ..scene import SceneData, bilinear_point, quad_area_normal

_CHUNK_RAYS = 1 << 20
FIRST_RAYS = 16


def _cast(occluder, eps, geo, shift, j0, count):
    """Rays j0 .. j0 + count - 1 of each (point, lamp patch) pair's shifted R2 sequence:
    kernel weights of all and of the free rays, and counts of free / blocked rays."""
    P0, N0, C, NL0 = geo
    j = np.arange(j0, j0 + count)
    xu = np.mod(j[None] * _R2[0] + shift[:, :1], 1.0)
    xv = np.mod(j[None] * _R2[1] + shift[:, 1:], 1.0)
    u, v = area_uniform_uv(C, xu, xv)
    Q = bilinear_point(C[:, None], u, v).reshape(-1, 3)
    P = np.repeat(P0, count, axis=0)
    NP = np.repeat(N0, count, axis=0)
    NL = np.repeat(NL0, count, axis=0)
    w = _kernel(NP, NL, Q - P)
    blocked = occluder.segments_occluded(P + eps * NP, Q + eps * NL)
    counted = w > 0
    w = w.reshape(-1, count)
    free = (~blocked).reshape(-1, count)
    return (w.sum(axis=1), (w * free).sum(axis=1),
            (free & counted.reshape(-1, count)).sum(axis=1),
            (~free & counted.reshape(-1, count)).sum(axis=1))


def lamp_irradiance(scene: SceneData, points, normals, occluder=None, rays: int = 16, seed=0,
                    exitance_scale=None):
    """Direct irradiance (n, k, 3) from each of the scene's k lamps at ``points`` with
    ``normals``: returns (unoccluded, with visibility).  ``exitance_scale`` (k,) multiplies each
    lamp's exitance.  Without an occluder the two are equal."""
    points = np.asarray(points, float).reshape(-1, 3)
    normals = np.asarray(normals, float).reshape(-1, 3)
    n, k = len(points), scene.n_lamps
    unocc = np.zeros((n, k, 3))
    occ = np.zeros((n, k, 3))
    lamp_patches = np.flatnonzero(scene.lamp >= 0)
    if n == 0 or len(lamp_patches) == 0:
        return unocc, occ
    scale_k = np.ones(k) if exitance_scale is None else np.asarray(exitance_scale, float)
    lo, hi = scene.corners.reshape(-1, 3).min(0), scene.corners.reshape(-1, 3).max(0)
    eps = 1e-6 * (float(np.linalg.norm(hi - lo)) or 1.0)
    rng = np.random.default_rng(seed)
    corners = scene.corners[lamp_patches]
    _, lamp_normal = quad_area_normal(corners)
    lamp_k = scene.lamp[lamp_patches]
    exitance = scene.emission[lamp_patches] * scale_k[lamp_k][:, None]
    m = len(lamp_patches)
    rays = max(int(rays), 0) if occluder is not None else 0
    step = max(1, _CHUNK_RAYS // max(m * max(rays, 1), 1))
    for start in range(0, n, step):
        pts = points[start:start + step]
        nrm = normals[start:start + step]
        c = len(pts)
        pi = np.repeat(np.arange(c), m)
        li = np.tile(np.arange(m), c)
        F = point_to_polygon(pts[pi], nrm[pi], corners[li], lamp_normal[li])
        live = F > 0
        pi, li, F = pi[live], li[live], F[live]
        frac = np.ones(len(F))
        if rays and len(F):
            shift = rng.random((len(F), 2))
            geo = (pts[pi], nrm[pi], corners[li], lamp_normal[li])
            # Few rays first; the rest only where they disagree (penumbrae): a point that sees
            # the whole lamp or none of it with the first rays costs no more.
            first = min(rays, FIRST_RAYS)
            w_all, w_free, n_free, n_blocked = _cast(occluder, eps, geo, shift, 0, first)
            mixed = np.flatnonzero((n_free > 0) & (n_blocked > 0))
            if rays > first and len(mixed):
                sub = tuple(g[mixed] for g in geo)
                w2, f2, _, _ = _cast(occluder, eps, sub, shift[mixed], first, rays - first)
                w_all[mixed] += w2
                w_free[mixed] += f2
            frac = np.where(w_all > 0, w_free / np.where(w_all > 0, w_all, 1.0), 1.0)
        gi = start + pi
        contrib = F[:, None] * exitance[li]
        kk = lamp_k[li]
        np.add.at(unocc, (gi, kk), contrib)
        np.add.at(occ, (gi, kk), contrib * frac[:, None])
    return unocc, occ
