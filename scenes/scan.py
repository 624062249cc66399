"""Scanned-room-like meshes: a family room's surfaces re-meshed into many small noisy triangles.

A photogrammetry or depth-sensor scan of a room is one dense, irregular triangle mesh with
millimetre noise, not a few clean quads.  ``scan_spec(spec, triangles, noise, seed)`` turns
every surface of a family room (``scenes.family``) into such a mesh: each quad is cut into a
grid of cells about ``h`` on a side (``h`` chosen so that the whole room has about
``triangles`` triangles), the grid's inner vertices are jittered in the quad's parameter
plane (by up to 0.3 cell) and displaced along the normal by Gaussian noise of ``noise`` metres,
and every cell is split into two triangles along an alternating diagonal.  Vertices on a
quad's border stay where they were, so surfaces still meet without cracks.

UVs are the quad's own bilinear UVs at each vertex's parameters: the photo texels and the
Cycles truth of the clean room stay valid texel for texel (the displacement is noise of a few
millimetres, far below what the bakes resolve).  Faces are returned per surface as
``(n, 3, 3)`` triangles with ``(n, 3, 2)`` UVs; ``Surface.quads`` holds them as degenerate
quads ``(a, b, c, c)`` so the rest of ``scenes.family`` can treat them as before.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np


def _bilinear(q, s, t):
    s, t = s[..., None], t[..., None]
    return ((1 - s) * (1 - t) * q[0] + s * (1 - t) * q[1] + s * t * q[2] + (1 - s) * t * q[3])


def scan_quad(quad, uv, h, noise, rng):
    """Triangles (n, 3, 3) and UVs (n, 3, 2) of one quad re-meshed at cell size ~``h``."""
    quad = np.asarray(quad, float)
    uv = np.asarray(uv, float)
    nu = max(1, int(round(np.linalg.norm(quad[1] - quad[0]) / h)))
    nv = max(1, int(round(np.linalg.norm(quad[3] - quad[0]) / h)))
    s, t = np.meshgrid(np.linspace(0, 1, nu + 1), np.linspace(0, 1, nv + 1), indexing="ij")
    inner = (s > 0) & (s < 1) & (t > 0) & (t < 1)
    s = s + inner * rng.uniform(-0.3, 0.3, s.shape) / nu
    t = t + inner * rng.uniform(-0.3, 0.3, t.shape) / nv
    p = _bilinear(quad, s, t)
    n = np.cross(quad[2] - quad[0], quad[3] - quad[1])
    n /= np.linalg.norm(n)
    p = p + (inner * rng.normal(0.0, noise, s.shape))[..., None] * n
    w = _bilinear(uv, s, t)
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    i, j = i.ravel(), j.ravel()
    corner = [(i, j), (i + 1, j), (i + 1, j + 1), (i, j + 1)]       # a, b, c, d of each cell
    alt = ((i + j) % 2 == 1)[:, None]
    # Cells split along a-c, or along b-d on alternate cells (scan meshes have no grain).
    tri = np.concatenate([np.where(alt, [0, 1, 2], [0, 1, 3]), np.where(alt, [0, 2, 3], [1, 2, 3])])
    cells = np.concatenate([np.arange(len(i)), np.arange(len(i))])
    ci = np.stack([c[0] for c in corner], 1)[cells[:, None], tri]
    cj = np.stack([c[1] for c in corner], 1)[cells[:, None], tri]
    return p[ci, cj], w[ci, cj]


def cell_size(spec, triangles):
    """Cell edge that gives about ``triangles`` triangles over the room's surfaces."""
    area = 0.0
    for s in spec.surfaces:
        q = np.asarray(s.quads, float)
        area += 0.5 * np.linalg.norm(np.cross(q[:, 2] - q[:, 0], q[:, 3] - q[:, 1]), axis=1).sum()
    return math.sqrt(2.0 * area / triangles)


def scan_spec(spec, triangles=100_000, noise=0.002, seed=0):
    """A copy of ``spec`` whose surfaces are scan-like triangle meshes (see the module doc).
    Lamps are kept as they are (a scan does not capture the light fittings)."""
    rng = np.random.default_rng(seed)
    h = cell_size(spec, triangles)
    surfaces = []
    for s in spec.surfaces:
        parts = [scan_quad(q, w, h, noise, rng) for q, w in zip(s.quads, s.uvs)]
        tri = np.concatenate([p for p, _ in parts])
        tuv = np.concatenate([w for _, w in parts])
        quads = np.concatenate([tri, tri[:, 2:3]], axis=1)        # (a, b, c, c)
        uvs = np.concatenate([tuv, tuv[:, 2:3]], axis=1)
        flipped = None
        if s.flipped is not None:
            counts = [len(p) for p, _ in parts]
            flipped = np.repeat(np.asarray(s.flipped, bool), counts)
        surfaces.append(dataclasses.replace(s, quads=quads, uvs=uvs, flipped=flipped))
    return dataclasses.replace(spec, surfaces=surfaces)


def n_triangles(spec) -> int:
    return int(sum(len(s.quads) for s in spec.surfaces))
