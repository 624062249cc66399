"""Direct irradiance from the lamps at surface points or texel footprints (texel mode, probes).

For every (point group, lamp patch) pair -- a group is one point, or the sample points of one
texel's footprint -- the exact point-to-polygon form factor F (unoccluded) averaged over the
group's points, and the visible fraction from ``rays`` segments, weighted by the point-to-point
kernel (the ratio estimator of the solver's final links).  Ray j of a pair starts at the group's
point j mod S (so the rays also cover the texel's footprint) and ends at a table entry of
area-uniform lamp points on an R2 sequence: each starting point walks its own window of
consecutive entries, from a random offset j0 per pair (a window of a low-discrepancy sequence
is itself evenly spread).  The first FIRST_RAYS rays
decide: only pairs that see part of the lamp get the rest.
Irradiance = exitance x F (x visible fraction), summed per lamp.
"""
from __future__ import annotations

import numpy as np

from ..geometry.patch import bilinear_point, quad_area_normal
from ..geometry.sampling import R2, area_uniform_uv
from ..lights import light_irradiance
from ..geometry.formfactor import point_kernel, point_to_polygon
from ..geometry.extent import bounding_diagonal
from ..geometry.raycast import ray_offset
from ..scene import SceneData

_CHUNK_RAYS = 1 << 17     # rays in flight per call (two may run at once): ~60 MB each
FIRST_RAYS = 16
TABLE = 256            # area-uniform sample points kept per lamp patch


def _lamp_tables(corners):
    """(m, TABLE, 3) area-uniform points of each lamp patch, R2 order."""
    j = np.arange(TABLE)
    xu = np.broadcast_to(np.mod(0.5 + j * R2[0], 1.0), (len(corners), TABLE))
    xv = np.broadcast_to(np.mod(0.5 + j * R2[1], 1.0), (len(corners), TABLE))
    u, v = area_uniform_uv(corners, xu, xv)
    return bilinear_point(corners[:, None], u, v)


def _cast(occluder, eps, origins, normals, table, lamp_normal, j0, start, count):
    """Rays start .. start + count - 1 of each pair: kernel weights of all and of the free rays,
    and counts of free / blocked rays.  origins (p, S, 3), normals (p, 3), table (p, TABLE, 3),
    lamp_normal (p, 3), j0 (p,)."""
    p, S = origins.shape[:2]
    j = np.arange(start, start + count)
    rows = np.arange(p)[:, None]
    # Ray j starts at point s = j mod S and takes entry i = j div S of that point's own window
    # of consecutive table entries: a strided run of an R2 sequence is badly spread (4 alpha is
    # nearly 0 in x), a consecutive one is not.
    s, i = j % S, j // S
    P = origins[rows, s[None]].reshape(-1, 3)
    Q = table[rows, (j0[:, None] + (s * (TABLE // max(S, 1)) + i)[None]) % TABLE].reshape(-1, 3)
    NP = np.repeat(normals, count, axis=0)
    NL = np.repeat(lamp_normal, count, axis=0)
    w = point_kernel(NP, NL, Q - P)
    blocked = occluder.segments_occluded(P + eps * NP, Q + eps * NL)
    counted = (w > 0).reshape(p, count)
    w = w.reshape(p, count)
    free = (~blocked).reshape(p, count)
    return (w.sum(axis=1), (w * free).sum(axis=1),
            (free & counted).sum(axis=1), (~free & counted).sum(axis=1))


def lamp_irradiance(scene: SceneData, points, normals, occluder=None, rays: int = 16, seed=0,
                    exitance_scale=None, offset=0.0):
    """Direct irradiance (n, k, 3) from each of the scene's k lamps (lamp patches and the
    ``scene.lights``): returns (unoccluded, with visibility).  ``points`` (n, 3), or (n, S, 3)
    for groups of S points whose mean is wanted (a texel's footprint), with ``normals`` (n, 3).
    ``exitance_scale`` (k,) multiplies each lamp's exitance.  Without an occluder the two are
    equal."""
    points = np.asarray(points, float)
    points = points.reshape(len(points), -1, 3) if points.ndim == 3 else points.reshape(-1, 1, 3)
    normals = np.asarray(normals, float).reshape(-1, 3)
    n, S = points.shape[:2]
    k = scene.n_lamps
    unocc = np.zeros((n, k, 3))
    occ = np.zeros((n, k, 3))
    if n == 0:
        return unocc, occ
    scale_k = np.ones(k) if exitance_scale is None else np.asarray(exitance_scale, float)
    size = bounding_diagonal(scene.corners)
    eps = max(ray_offset(size), offset)        # ``offset``: a rough surface's bumps (proxy.py)
    rng = np.random.default_rng(seed)
    if len(scene.lights):
        lu, lo_ = light_irradiance(scene.lights, points, normals, occluder, rays,
                                   int(rng.integers(2**31)), size, eps)
        for i, lamp in enumerate(scene.lights.lamp):
            unocc[:, lamp] += lu[:, i] * scale_k[lamp]
            occ[:, lamp] += lo_[:, i] * scale_k[lamp]
    lamp_patches = np.flatnonzero(scene.lamp >= 0)
    if len(lamp_patches) == 0:
        return unocc, occ
    corners = scene.corners[lamp_patches]
    _, lamp_normal = quad_area_normal(corners)
    table = _lamp_tables(corners)
    lamp_k = scene.lamp[lamp_patches]
    exitance = scene.emission[lamp_patches] * scale_k[lamp_k][:, None]
    m = len(lamp_patches)
    rays = max(int(rays), 0) if occluder is not None else 0
    step = max(1, _CHUNK_RAYS // max(m * max(rays, S), 1))
    for start in range(0, n, step):
        pts = points[start:start + step]
        nrm = normals[start:start + step]
        c = len(pts)
        pi = np.repeat(np.arange(c), m)
        li = np.tile(np.arange(m), c)
        F = point_to_polygon(pts[pi].reshape(-1, 3), np.repeat(nrm[pi], S, axis=0),
                             np.repeat(corners[li], S, axis=0),
                             np.repeat(lamp_normal[li], S, axis=0)).reshape(-1, S).mean(axis=1)
        live = F > 0
        pi, li, F = pi[live], li[live], F[live]
        frac = np.ones(len(F))
        if rays and len(F):
            geo = (pts[pi], nrm[pi], table[li], lamp_normal[li],
                   rng.integers(0, TABLE, len(F)))
            # Few rays first; the rest only where they disagree (penumbrae): a point that sees
            # the whole lamp or none of it with the first rays costs no more.
            first = min(rays, FIRST_RAYS)
            w_all, w_free, n_free, n_blocked = _cast(occluder, eps, *geo, 0, first)
            mixed = np.flatnonzero((n_free > 0) & (n_blocked > 0))
            if rays > first and len(mixed):
                sub = tuple(g[mixed] for g in geo)
                w2, f2, _, _ = _cast(occluder, eps, *sub, first, rays - first)
                w_all[mixed] += w2
                w_free[mixed] += f2
            frac = np.where(w_all > 0, w_free / np.where(w_all > 0, w_all, 1.0), 1.0)
        # Sum per (point, lamp): bincount over flat (point, lamp) slots (np.add.at is slow).
        slot = pi * k + lamp_k[li]
        contrib = F[:, None] * exitance[li]
        for ch in range(3):
            unocc[start:start + c, :, ch] += np.bincount(slot, contrib[:, ch], c * k).reshape(c, k)
            occ[start:start + c, :, ch] += np.bincount(slot, contrib[:, ch] * frac,
                                                       c * k).reshape(c, k)
    return unocc, occ
