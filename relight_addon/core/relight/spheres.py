"""A set of spheres standing in for an object (seed 002 §5.2, algorithm 5.1).

The object's surface is sampled uniformly by area, the samples are clustered by Lloyd iterations
(k-means: ``scipy.cluster.vq.kmeans2``, a sphere's centre is its cluster's mean), and each
sphere's radius is the mean distance of its cluster's samples to the centre (the seed paves the
surface with spheres of that size).  A sphere set is what the relit material evaluates at render
time (sphere_shadow.py), so its size stays small: 8-128 spheres.

Everything is in the object's own coordinates, so the set is fitted once and follows the object
through its transform (animation, drags) without being fitted again.
"""
from __future__ import annotations

import numpy as np

SAMPLES_PER_SPHERE = 200     # surface samples per sphere (the seed used 1000 per sphere)
LLOYD_ITERATIONS = 30


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


def fit_spheres(triangles, n=32, seed=0, samples_per_sphere=SAMPLES_PER_SPHERE):
    """(centres (m, 3), radii (m,)) of ``m <= n`` spheres approximating the surface of
    ``triangles`` (t, 3, 3); clusters left empty by Lloyd's iterations are dropped.  The result
    depends only on ``seed`` (fixed sample and initialisation streams)."""
    from scipy.cluster.vq import kmeans2

    n = max(1, int(n))
    pts = surface_samples(triangles, n * samples_per_sphere, seed)
    centres, label = kmeans2(pts, n, iter=LLOYD_ITERATIONS, minit="++", seed=seed)
    keep, radii = [], []
    for i in range(len(centres)):
        members = pts[label == i]
        if len(members) == 0:
            continue
        centres[i] = members.mean(axis=0)
        keep.append(i)
        radii.append(np.linalg.norm(members - centres[i], axis=1).mean())
    return centres[keep], np.asarray(radii)
