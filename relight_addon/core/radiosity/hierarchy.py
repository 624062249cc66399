"""Element hierarchy: a quadtree of planar bilinear elements over the input patches.

Structure of arrays with amortised growth.  Element ``i`` of a patch covers the parameter box
``param[i]`` (four (u, v) corners) of that patch; its four children split it at u, v = 1/2 and are
stored contiguously from ``first_child[i]``.  Roots are the patches themselves (ids 0..p-1).
"""
from __future__ import annotations

import numpy as np

from ..geometry.patch import bilinear_point, quad_area_normal
from ..scene import SceneData

_ROOT_PARAM = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
# Corner (u, v) of the four children in the parent's parameter space (counter-clockwise).
_CHILD_UV = np.array([
    [[0.0, 0.0], [0.5, 0.0], [0.5, 0.5], [0.0, 0.5]],
    [[0.5, 0.0], [1.0, 0.0], [1.0, 0.5], [0.5, 0.5]],
    [[0.5, 0.5], [1.0, 0.5], [1.0, 1.0], [0.5, 1.0]],
    [[0.0, 0.5], [0.5, 0.5], [0.5, 1.0], [0.0, 1.0]],
])


class Hierarchy:
    _FIELDS = {
        "corners": ((4, 3), np.float64), "param": ((4, 2), np.float64),
        "parent": ((), np.int64), "first_child": ((), np.int64), "level": ((), np.int16),
        "patch": ((), np.int64), "area": ((), np.float64), "normal": ((3,), np.float64),
        "centroid": ((3,), np.float64),
    }

    def __init__(self, scene: SceneData):
        p = scene.n_patches
        self.n = 0
        self._cap = 0
        self._grow(max(16, 4 * p))
        self.n = p
        self.corners[:p] = scene.corners
        self.param[:p] = _ROOT_PARAM
        self.parent[:p] = -1
        self.first_child[:p] = -1
        self.level[:p] = 0
        self.patch[:p] = np.arange(p)
        area, normal = quad_area_normal(scene.corners)
        self.area[:p] = area
        self.normal[:p] = normal
        self.centroid[:p] = bilinear_point(scene.corners, 0.5, 0.5)

    def _grow(self, cap):
        for name, (shape, dtype) in self._FIELDS.items():
            new = np.empty((cap,) + shape, dtype)
            if self._cap:
                new[: self.n] = getattr(self, name)[: self.n]
            setattr(self, name, new)
        self._cap = cap

    def view(self, name):
        return getattr(self, name)[: self.n]

    def split(self, ids: np.ndarray) -> np.ndarray:
        """Give every element in ``ids`` four children (existing ones are kept).

        Returns ``first_child`` of ``ids``.
        """
        ids = np.asarray(ids, np.int64)
        todo = np.unique(ids[self.first_child[ids] < 0])
        k = len(todo)
        if k:
            if self.n + 4 * k > self._cap:
                self._grow(max(2 * self._cap, self.n + 4 * k))
            start = self.n
            new = slice(start, start + 4 * k)
            parent_corners = self.corners[todo]                      # (k, 4, 3)
            parent_param = self.param[todo]
            u = _CHILD_UV[None, :, :, 0]                              # (1, 4, 4)
            v = _CHILD_UV[None, :, :, 1]
            child_corners = bilinear_point(parent_corners[:, None, None], u, v)  # (k, 4, 4, 3)
            pu = _bilinear2(parent_param, u, v)
            self.corners[new] = child_corners.reshape(-1, 4, 3)
            self.param[new] = pu.reshape(-1, 4, 2)
            self.parent[new] = np.repeat(todo, 4)
            self.first_child[new] = -1
            self.level[new] = np.repeat(self.level[todo] + 1, 4)
            self.patch[new] = np.repeat(self.patch[todo], 4)
            area, _ = quad_area_normal(self.corners[new])
            self.area[new] = area
            self.normal[new] = np.repeat(self.normal[todo], 4, axis=0)  # planar: same normal
            self.centroid[new] = bilinear_point(self.corners[new], 0.5, 0.5)
            self.first_child[todo] = start + 4 * np.arange(k)
            self.n += 4 * k
        return self.first_child[ids]

    def locate(self, ids: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """The leaf under each element ``ids`` that contains its local parameter point (u, v)."""
        ids = np.asarray(ids, np.int64).copy()
        u = np.asarray(u, float).copy()
        v = np.asarray(v, float).copy()
        while True:
            fc = self.first_child[ids]
            inner = np.flatnonzero(fc >= 0)
            if len(inner) == 0:
                return ids
            hu = u[inner] >= 0.5
            hv = v[inner] >= 0.5
            # Child order (see _CHILD_UV): 0 (lo, lo), 1 (hi, lo), 2 (hi, hi), 3 (lo, hi).
            child = np.where(hv, np.where(hu, 2, 3), np.where(hu, 1, 0))
            ids[inner] = fc[inner] + child
            u[inner] = np.clip(2.0 * u[inner] - hu, 0.0, 1.0)
            v[inner] = np.clip(2.0 * v[inner] - hv, 0.0, 1.0)

    def leaves(self) -> np.ndarray:
        return np.flatnonzero(self.view("first_child") < 0)

    def radius(self) -> np.ndarray:
        """(n,) each element's distance from its centre to its farthest corner."""
        return np.linalg.norm(self.view("corners") - self.view("centroid")[:, None],
                              axis=2).max(axis=1)

    def ancestor_pairs(self, leaves: np.ndarray):
        """(leaf position, ancestor id) pairs, each leaf paired with itself and all ancestors."""
        rows, cols = [], []
        pos = np.arange(len(leaves))
        cur = leaves.copy()
        while len(cur):
            rows.append(pos)
            cols.append(cur)
            up = self.parent[cur]
            keep = up >= 0
            pos, cur = pos[keep], up[keep]
        return np.concatenate(rows), np.concatenate(cols)


def _bilinear2(param, u, v):
    """Bilinear interpolation of (k, 4, 2) corner parameters at u, v of shape (1, 4, 4)."""
    a, b, c, d = (param[:, None, None, i, :] for i in range(4))
    u = u[..., None]
    v = v[..., None]
    return (1 - u) * (1 - v) * a + u * (1 - v) * b + u * v * c + (1 - u) * v * d
