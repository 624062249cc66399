# SPDX-License-Identifier: GPL-3.0-or-later
"""The texels of a mesh solved on a radiosity proxy (core/radiosity/proxy.py: a scan's dense
mesh): where each texel sits on the proxy, and how it reads the proxy's solution."""
from __future__ import annotations

import dataclasses

import numpy as np
from scipy.spatial import cKDTree

from ..geometry.patch import bilinear_point
from ..numerics import nonzero
from ..radiosity.proxy import CHUNK, Proxy, finder
from ..scene import SceneData
from ..texture.mapping import TexelMap

KERNEL_LEAVES = 16      # leaves around each texel that its indirect light is read from
FACING = 0.5            # ... those whose normal is within 60 degrees of the texel's


def texels_on(proxy: Proxy, scene: SceneData, tm):
    """The texel map ``tm`` of ``scene`` with every texel's patch and parameters on the proxy
    instead (the same images, texel order and dtypes): where the solution's light is read.
    Located CHUNK texels at a time: a photo's texels are tens of millions."""
    normal = scene.area_normal()[1]
    find = finder(proxy.scene)
    images = []
    for im in tm.images:
        patch = np.empty(len(im), im.patch.dtype)
        u, v = np.empty(len(im), im.u.dtype), np.empty(len(im), im.v.dtype)
        for c0 in range(0, len(im), CHUNK):
            sl = slice(c0, c0 + CHUNK)
            face = im.patch[sl]
            pts = bilinear_point(scene.corners[face], im.u[sl], im.v[sl])
            patch[sl], u[sl], v[sl], _ = find(pts, normal[face])
        images.append(dataclasses.replace(im, patch=patch, u=u, v=v))
    return TexelMap(images)


class SmoothRead:
    """Values of a solution's leaves read at points of the full mesh by a Gaussian kernel over
    the leaves near each point that face its way (each leaf's width its own size), instead of
    interpolating over the proxy's triangles: QEM leaves long thin triangles on flat regions,
    and an indirect field interpolated over them has their streaks, which the photo does not
    (the shadow-edge fit read them as lamp-ratio evidence: 10 % off on family room 0)."""

    def __init__(self, hierarchy, leaves, points, normals, neighbours=KERNEL_LEAVES):
        centre = hierarchy.centroid[leaves]
        leaf_normal = hierarchy.normal[leaves]
        width2 = nonzero(hierarchy.area[leaves])
        tree = cKDTree(centre)
        k = min(neighbours, len(leaves))
        n = len(points)
        # uint16 (at most 65,536 leaves) or int32 / float32: 96 or 128 bytes a texel instead of
        # 256 (6.8 M texels of photos: 0.9 GB; the exitance fit's sample of 2 M: 0.2 GB)
        self.index = np.empty((n, k), np.uint16 if len(leaves) <= 1 << 16 else np.int32)
        self.weight = np.empty((n, k), np.float32)
        for c0 in range(0, n, CHUNK):
            p = points[c0:c0 + CHUNK]
            d, idx = tree.query(p, k=k)
            d, idx = d.reshape(len(p), k), idx.reshape(len(p), k)
            facing = np.einsum("ikj,ij->ik", leaf_normal[idx], normals[c0:c0 + CHUNK]) > FACING
            w = np.exp(-0.5 * d ** 2 / width2[idx]) * facing
            # no facing leaf near: the nearest facing one (or the nearest at all)
            lost = w.sum(axis=1) <= 1e-12
            if lost.any():
                pick = np.where(facing[lost].any(axis=1), np.argmax(facing[lost], axis=1), 0)
                w[lost] = 0.0
                w[np.flatnonzero(lost), pick] = 1.0
            self.index[c0:c0 + len(p)] = idx
            self.weight[c0:c0 + len(p)] = w / w.sum(axis=1, keepdims=True)

    def __call__(self, leaf_values):
        v = np.asarray(leaf_values, np.float64)
        flat = v.reshape(len(v), -1)
        out = np.empty((len(self.index), flat.shape[1]))
        for c0 in range(0, len(out), CHUNK):      # the gathered (chunk, k, c) values only
            rows = slice(c0, c0 + CHUNK)
            out[rows] = np.einsum("tk,tkc->tc", self.weight[rows], flat[self.index[rows]])
        return out.reshape((len(self.index),) + v.shape[1:])
