"""The ray-casting fallback where no embreex wheel exists: ``mathutils.bvhtree.BVHTree``.

One Python call per ray (0.1-1 M rays/s: BVHTree finds the closest hit, with no any-hit early
exit, so cluttered scenes and long segments cost most).  It lives in the bridge because it needs
mathutils; importing ``relight_addon.blender`` registers it with the core's ray casting
(``core/geometry/raycast.py``), after Embree in the "auto" order.
"""
from __future__ import annotations

import numpy as np

from ..core.geometry.raycast import Occluder, register_backend


def _import_bvhtree():
    from mathutils.bvhtree import BVHTree
    return BVHTree


class BVHTreeOccluder(Occluder):
    """mathutils BVHTree fallback: one ``ray_cast`` call per ray (Blender normalises direction
    and measures ``distance`` in world units; no tnear, so origins are moved instead)."""

    name = "bvhtree"

    def __init__(self, triangles, epsilon: float = 0.0):
        super().__init__(triangles)
        BVHTree = _import_bvhtree()
        self._tree = None
        self._centre = np.zeros(3)
        if self.n_triangles:
            # BVHTree stores float32: centre the scene first, as for Embree.
            self._centre = 0.5 * (self.triangles.min(axis=(0, 1)) + self.triangles.max(axis=(0, 1)))
            verts = (self.triangles - self._centre).reshape(-1, 3).tolist()
            polys = np.arange(3 * self.n_triangles).reshape(-1, 3).tolist()
            self._tree = BVHTree.FromPolygons(verts, polys, all_triangles=True, epsilon=epsilon)

    # Rays per Python batch.  Converting all rays with .tolist() at once creates millions of
    # GC-tracked lists and triggers full collections (2-4x slower inside bpy); small batches
    # die young.
    _BATCH = 512

    def _occluded(self, o, d, eps):
        length = np.sqrt(np.einsum("ij,ij->i", d, d))
        start = (o - self._centre) + eps * d
        dist = length * (1.0 - 2.0 * eps)
        rc = self._tree.ray_cast
        out = np.empty(len(o), bool)
        k = self._BATCH
        for a in range(0, len(o), k):
            # index (item 2) is None for a miss
            out[a:a + k] = [rc(p, q, s)[2] is not None for p, q, s in
                            zip(start[a:a + k].tolist(), d[a:a + k].tolist(), dist[a:a + k].tolist())]
        return out

    def _first_hit(self, o, u, tmax):
        # BVHTree stores floats: a distance beyond float32 range comes back as a bogus hit.
        tmax = np.minimum(tmax, 1e30)
        start = o - self._centre
        rc = self._tree.ray_cast
        out = np.empty(len(o))
        k = self._BATCH
        for a in range(0, len(o), k):
            t = [rc(p, q, s)[3] for p, q, s in
                 zip(start[a:a + k].tolist(), u[a:a + k].tolist(), tmax[a:a + k].tolist())]
            out[a:a + k] = [np.inf if x is None else x for x in t]
        return out

    def _first_hit_prim(self, o, u, tmax):
        tmax = np.minimum(tmax, 1e30)
        start = o - self._centre
        rc = self._tree.ray_cast
        t, prim = np.full(len(o), np.inf), np.full(len(o), -1, np.int64)
        k = self._BATCH
        for a in range(0, len(o), k):
            for i, (_, _, index, dist) in enumerate(
                    rc(p, q, s) for p, q, s in zip(start[a:a + k].tolist(), u[a:a + k].tolist(),
                                                   tmax[a:a + k].tolist())):
                if index is not None:
                    t[a + i], prim[a + i] = dist, index
        return t, prim


register_backend("bvhtree", BVHTreeOccluder, _import_bvhtree)
