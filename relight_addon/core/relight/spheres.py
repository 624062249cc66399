"""A set of spheres standing in for an object (seed 002 §5.2, algorithm 5.1, filled).

Seed 002 paves the object's *surface*: area-uniform samples clustered by Lloyd iterations, each
sphere centred on its cluster with the cluster's mean distance as radius.  Measured against
ray-traced shadows (benchmarks/results/sphere_shadow.md) such spheres stick out of flat faces and
leave gaps, and their overlaps darken twice under the product rule of sphere_shadow.py.  So by
default the spheres fill the object's *volume*: samples uniform inside it (the voxels of a grid whose generalised
winding number is > 1/2, which also works for meshes with holes, e.g. Suzanne's eyes) clustered by Lloyd
iterations (``scipy.cluster.vq.kmeans2``, seeded by k-means++), each sphere given the volume of
its cluster's cell, so that the union has about the object's volume.  A mesh without volume (a
single plane, a cloth) falls back to the seed's surface paving.

A sphere set is what the relit materials evaluate at render time, so its size stays small
(8-128 spheres).  Everything is in the object's own coordinates: the set is fitted once and
follows the object through its transform (animation, drags) without being fitted again.
"""
from __future__ import annotations

import numpy as np

from ..numerics import nonzero

SAMPLES_PER_SPHERE = 200     # samples per sphere (the seed used 1000 per sphere)
LLOYD_ITERATIONS = 30
MIN_INSIDE = 0.02            # inside fraction of the bounding box below which there is no volume
MIN_THICKNESS = 1e-3         # thinner than this (relative) in some axis: no inside
WINDING_CHUNK = 256          # points per chunk of the winding number (chunk x triangles x 9)
WINDING_BUDGET = 1.5e6       # grid cells x triangles for the inside test (~0.3 s here)


def surface_samples(triangles, n, seed=0):
    """``n`` points uniformly distributed by area over ``triangles`` (t, 3, 3)."""
    tri = np.asarray(triangles, float).reshape(-1, 3, 3)
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    area = np.nan_to_num(area)
    if len(tri) == 0 or area.sum() <= 0:
        raise ValueError("the object has no surface to fit spheres to")
    rng = np.random.default_rng(seed)
    pick = rng.choice(len(tri), size=n, p=area / area.sum())
    r1, r2 = rng.random(n), rng.random(n)
    s = np.sqrt(r1)
    a, b, c = tri[pick, 0], tri[pick, 1], tri[pick, 2]
    return (1 - s)[:, None] * a + (s * (1 - r2))[:, None] * b + (s * r2)[:, None] * c


def winding_number(triangles, points):
    """Generalised winding number (Jacobson et al. 2013) of ``points`` (n, 3): the triangles'
    signed solid angles (Van Oosterom and Strackee) over 4 pi; ~1 inside, ~0 outside."""
    tri = np.asarray(triangles, float)
    out = np.empty(len(points))
    for c0 in range(0, len(points), WINDING_CHUNK):
        p = points[c0:c0 + WINDING_CHUNK, None, None, :]
        v = tri[None] - p                                    # (n, t, 3, 3)
        a, b, c = v[..., 0, :], v[..., 1, :], v[..., 2, :]
        la, lb, lc = (np.linalg.norm(x, axis=-1) for x in (a, b, c))
        det = np.einsum("ntk,ntk->nt", a, np.cross(b, c))
        den = (la * lb * lc + np.einsum("ntk,ntk->nt", a, b) * lc
               + np.einsum("ntk,ntk->nt", b, c) * la + np.einsum("ntk,ntk->nt", c, a) * lb)
        out[c0:c0 + WINDING_CHUNK] = 2.0 * np.arctan2(det, den).sum(axis=1) / (4 * np.pi)
    return out


def volume_samples(triangles, n, seed=0):
    """(``n`` points uniform inside the mesh ``triangles``, its volume), from the voxels of a
    grid over its bounding box whose centres have winding number > 1/2 (the grid is as fine as
    WINDING_BUDGET allows: the winding number costs cells x triangles).  No inside: (empty, 0)."""
    tri = np.asarray(triangles, float).reshape(-1, 3, 3)
    lo, hi = tri.reshape(-1, 3).min(0), tri.reshape(-1, 3).max(0)
    ext = hi - lo
    if not np.all(ext > MIN_THICKNESS * max(float(ext.max()), 1e-30)):
        return np.zeros((0, 3)), 0.0           # flat: no inside
    cells = int(np.clip(WINDING_BUDGET / max(len(tri), 1), 10 ** 3, 48 ** 3))
    step = (np.prod(ext) / cells) ** (1.0 / 3.0)
    side = int(round(cells ** (1.0 / 3.0)))
    shape = np.clip(np.ceil(ext / step).astype(int), 1, 8 * side)     # cells stay bounded
    size = ext / shape
    grid = np.stack(np.meshgrid(*[np.arange(k) for k in shape], indexing="ij"), -1).reshape(-1, 3)
    centres = lo + (grid + 0.5) * size
    inside = np.abs(winding_number(tri, centres)) > 0.5
    if not inside.any():
        return np.zeros((0, 3)), 0.0
    rng = np.random.default_rng(seed + 1)
    cells_in = centres[inside]
    pick = rng.integers(len(cells_in), size=n)
    pts = cells_in[pick] + (rng.random((n, 3)) - 0.5) * size
    volume = float(inside.sum() * np.prod(size))
    # a closed mesh's own volume (divergence theorem) is exact where the grid's is coarse
    signed = abs(float(np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum()) / 6)
    if 0.8 * volume < signed < 1.25 * volume:
        volume = signed
    return pts, volume


def silhouette_sphere(triangles):
    """(centre, radius) of the sphere whose silhouette stands for the object's: centred on the
    area-weighted centroid, with the object's mean projected area (Cauchy: a convex body's mean
    shadow is a quarter of its surface area), pi r^2 = A / 4."""
    tri = np.asarray(triangles, float).reshape(-1, 3, 3)
    area = np.nan_to_num(0.5 * np.linalg.norm(
        np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1))
    total = nonzero(float(area.sum()))
    centre = (tri.mean(axis=1) * area[:, None]).sum(0) / total
    return centre, float(np.sqrt(total / (4.0 * np.pi)))


def _kmeans_pp(pts, k, rng):
    """k-means++ seeds keeping each point's distance to its nearest seed (k x n, not k^2 x n)."""
    first = rng.integers(len(pts))
    seeds = [first]
    d2 = np.sum((pts - pts[first]) ** 2, axis=1)
    for _ in range(1, k):
        total = d2.sum()
        i = rng.integers(len(pts)) if total <= 0 else rng.choice(len(pts), p=d2 / total)
        seeds.append(i)
        d2 = np.minimum(d2, np.sum((pts - pts[i]) ** 2, axis=1))
    return pts[seeds].copy()


def _lloyd(pts, n, seed):
    from scipy.cluster.vq import kmeans2
    rng = np.random.default_rng(seed)
    init = _kmeans_pp(pts, n, rng)
    centres, label = kmeans2(pts, init, iter=LLOYD_ITERATIONS, minit="matrix")
    return centres, label


def fit_spheres(triangles, n=32, seed=0, samples_per_sphere=SAMPLES_PER_SPHERE, fill=True):
    """(centres (m, 3), radii (m,)) of ``m <= n`` spheres approximating the object
    ``triangles`` (t, 3, 3): filling its volume (``fill``, when it has one) or paving its
    surface (seed 002).  Clusters left empty by Lloyd's iterations are dropped.  The result
    depends only on ``seed``."""
    tri = np.asarray(triangles, float).reshape(-1, 3, 3)
    n = max(1, int(n))
    want = n * samples_per_sphere
    if fill and len(tri):
        pts, volume = volume_samples(tri, want, seed)
        lo, hi = tri.reshape(-1, 3).min(0), tri.reshape(-1, 3).max(0)
        if volume > MIN_INSIDE * float(np.prod(hi - lo)):
            centres, label = _lloyd(pts, n, seed)
            counts = np.bincount(label, minlength=len(centres))
            keep = counts > 0
            cell = volume * counts[keep] / counts.sum()
            return centres[keep], (3.0 * cell / (4.0 * np.pi)) ** (1.0 / 3.0)
    pts = surface_samples(tri, want, seed)
    centres, label = _lloyd(pts, n, seed)
    keep, radii = [], []
    for i in range(len(centres)):
        members = pts[label == i]
        if len(members) == 0:
            continue
        centres[i] = members.mean(axis=0)
        keep.append(i)
        radii.append(np.linalg.norm(members - centres[i], axis=1).mean())
    return centres[keep], np.asarray(radii)
