"""The AR benchmark's scenes (objects and receivers), shared by tests and benchmarks/bench_ar.py.

Objects, in world coordinates, resting on z = 0 unless said: a sphere (0.3 m, 5 cm above the
floor), Suzanne (tests/data/ar_suzanne.npz: bpy's primitive_monkey_add(size=1) exported once,
smart-project UVs), a chair with thin legs (3 cm legs), a torus lying on the floor.  Receivers:
a ground plane (3.2 x 3.2 m), a table top (a 1.2 x 0.8 m rectangle at z = 0 under the object:
the same floor, sampled finer near the object, where the chair and the torus stand on it and
cast contact shadows; only the object occludes), a corner of two walls (the floor plus walls
15 cm beyond the object's box, facing +x and +y).
"""
from __future__ import annotations

import os

import numpy as np

DATA = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data")


def uv_sphere(radius=0.3, centre=(0, 0, 0.35), n_lat=24, n_lon=48):
    th = np.linspace(0, np.pi, n_lat + 1)
    ph = np.linspace(0, 2 * np.pi, n_lon + 1)
    T, P = np.meshgrid(th, ph, indexing="ij")
    v = radius * np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1)
    v = v + np.asarray(centre, float)
    a, b, c, d = v[:-1, :-1], v[1:, :-1], v[1:, 1:], v[:-1, 1:]
    tri = np.concatenate([np.stack([a, b, c], -2).reshape(-1, 3, 3),
                          np.stack([a, c, d], -2).reshape(-1, 3, 3)])
    area = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    return tri[area > 1e-12]


def box(lo, hi):
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    v = np.array([[x, y, z] for z in (lo[2], hi[2]) for y in (lo[1], hi[1])
                  for x in (lo[0], hi[0])])
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    return np.array([v[[a, b, c]] for a, b, c, d in quads] + [v[[a, c, d]] for a, b, c, d in quads])


def chair():
    """Seat 0.45 x 0.45 x 0.04 m at 0.45 m, four 3 x 3 cm legs, a back 0.45 x 0.03 x 0.45 m."""
    parts = [box([-0.225, -0.225, 0.43], [0.225, 0.225, 0.47])]
    for x in (-0.2, 0.17):
        for y in (-0.2, 0.17):
            parts.append(box([x, y, 0.0], [x + 0.03, y + 0.03, 0.43]))
    parts.append(box([-0.225, 0.195, 0.47], [0.225, 0.225, 0.92]))
    return np.concatenate(parts)


def torus(R=0.35, r=0.12, n=48, m=24):
    u = np.linspace(0, 2 * np.pi, n + 1)
    v = np.linspace(0, 2 * np.pi, m + 1)
    U, V = np.meshgrid(u, v, indexing="ij")
    pts = np.stack([(R + r * np.cos(V)) * np.cos(U), (R + r * np.cos(V)) * np.sin(U),
                    r * np.sin(V) + r], -1)
    a, b, c, d = pts[:-1, :-1], pts[1:, :-1], pts[1:, 1:], pts[:-1, 1:]
    return np.concatenate([np.stack([a, b, c], -2).reshape(-1, 3, 3),
                           np.stack([a, c, d], -2).reshape(-1, 3, 3)])


def suzanne(lift=0.05):
    """Suzanne's triangles raised so that her lowest point is ``lift`` above the floor."""
    tri = np.load(os.path.join(DATA, "ar_suzanne.npz"))["triangles"].copy()
    tri[..., 2] += lift - tri[..., 2].min()
    return tri


def suzanne_uvs():
    return np.load(os.path.join(DATA, "ar_suzanne.npz"))["uvs"]


OBJECTS = {"sphere": uv_sphere, "Suzanne": suzanne, "chair": chair, "torus": torus}


def plane_points(origin, u, v, nu, nv):
    """(nu * nv, 3) cell centres of the rectangle origin + [0, 1] u + [0, 1] v."""
    a = (np.arange(nu) + 0.5) / nu
    b = (np.arange(nv) + 0.5) / nv
    A, B = np.meshgrid(a, b, indexing="ij")
    return (np.asarray(origin, float) + A.ravel()[:, None] * np.asarray(u, float)
            + B.ravel()[:, None] * np.asarray(v, float))


def receivers(scene, tri, cells=40):
    """[(points (n, 3), normal (3,)), ...] of a receiver scene around the object ``tri``;
    points inside the object's bounding box footprint are dropped (they lie under it)."""
    lo, hi = tri.min(axis=(0, 1)), tri.max(axis=(0, 1))
    if scene == "ground":
        planes = [(plane_points([-1.6, -1.6, 0], [3.2, 0, 0], [0, 3.2, 0], cells, cells),
                   [0, 0, 1.0])]
    elif scene == "table":
        planes = [(plane_points([-0.6, -0.4, 0], [1.2, 0, 0], [0, 0.8, 0], cells, cells * 2 // 3),
                   [0, 0, 1.0])]
    elif scene == "corner":
        x0, y0 = lo[0] - 0.15, lo[1] - 0.15
        planes = [(plane_points([x0, y0, 0], [1.6, 0, 0], [0, 1.6, 0], cells, cells), [0, 0, 1.0]),
                  (plane_points([x0, y0, 0], [0, 1.6, 0], [0, 0, 1.2], cells, cells * 3 // 4),
                   [1.0, 0, 0]),
                  (plane_points([x0, y0, 0], [1.6, 0, 0], [0, 0, 1.2], cells, cells * 3 // 4),
                   [0, 1.0, 0])]
    else:
        raise ValueError(scene)
    out = []
    for pts, n in planes:
        n = np.asarray(n, float)
        under = np.all((pts[:, :2] > lo[:2] - 1e-9) & (pts[:, :2] < hi[:2] + 1e-9), 1) & (n[2] > 0)
        if n[2] > 0:
            under &= _inside_footprint(tri, pts)
        out.append((pts[~under], n))
    return out


def _inside_footprint(tri, pts):
    """Floor points lying under some triangle touching the floor (z < 1 mm): inside the
    object where it stands (a receiver there is covered by it)."""
    low = tri[tri[..., 2].max(1) < 0.03]
    if len(low) == 0:
        return np.zeros(len(pts), bool)
    from relight_addon.core.geometry.raycast import make_occluder
    occ = make_occluder(tri)
    o = pts + [0, 0, 1e-4]
    return occ.segments_occluded(o, o + [0, 0, 0.02])
