# SPDX-License-Identifier: GPL-3.0-or-later
"""Ambient occlusion of a virtual object into a texture its material uses (seed 002 §5.1).

P_V(p) = (1 / pi) integral over the visible hemisphere of w.n dw (eq. 5.1.0.1): the cosine-
weighted fraction of the hemisphere of n(p) that the object itself leaves open.  Seed 002 renders
shadow maps from n random directions of the sphere and sums, in texture space, w.n x visible;
here every covered texel (texture/mapping.py's rasterisation of the object's UV triangles)
casts ``rays`` cosine-distributed rays (jittered strata per texel: the estimator is then the
plain fraction of rays that escape, with no cosine weights and no HS term) through Embree
(geometry/raycast.py).  Post-processing as the seed's: values in [0, 1] (the seed clamps what
its uniform estimator overshoots; ours cannot), seams dilated by SEAM_PIXELS texels from the
island edges (so bilinear filtering and mip-mapping at a UV seam read the island's values), and
the texels no island reaches filled with the mean of the covered ones (the seed's fill, so the
coarse mip levels are not pulled towards black).

The ray end points lift off the surface along the geometric normal by raycast.ray_offset; rays
may be limited to ``distance`` (Cycles' AO distance, world.light_settings.distance).
"""
from __future__ import annotations

import numpy as np

from ..geometry.raycast import make_occluder, ray_offset
from ..geometry.sampling import cosine_directions, stratified_unit_square
from ..relight.maps import SEAM_PIXELS
from ..scene import bilinear_point
from ..texture.mapping import dilate_seams, rasterize_patches

RAYS = 256                 # per texel: standard error <= 0.5 / 16 = 0.03, less with strata
CHUNK_RAYS = 1 << 20       # rays traced per batch (memory: ~100 bytes a ray)


def _as_triangles(triangles, uvs):
    tri = np.asarray(triangles, float).reshape(-1, 3, 3)
    uv = np.asarray(uvs, float).reshape(-1, 3, 2)
    if len(tri) != len(uv):
        raise ValueError(f"The object has {len(tri)} triangles but {len(uv)} UV triangles.")
    if len(tri) == 0:
        raise ValueError("The object has no triangles to compute ambient occlusion on.")
    return tri, uv


def ambient_occlusion(triangles, uvs, size, rays=RAYS, normals=None, distance=None,
                      seed=0, occluders=None, backend="auto"):
    """(image (H, W) float32 in [0, 1], coverage (H, W) bool): the object's ambient occlusion
    P_V in texture space, rows in Blender's order (row 0 at v = 0, as bpy's Image.pixels),
    after the seed's post-processing (module docstring).

    triangles (t, 3, 3) object-space (or world) positions; uvs (t, 3, 2) their texture
    coordinates; size (H, W) or an int; normals (t, 3, 3) optional per-corner shading normals
    (smooth shading; default the flat face normals); distance: rays stop there (None: 4 x the
    object's bounding-box diagonal, i.e. unbounded for the object alone); occluders: extra
    triangles (t2, 3, 3) that occlude but get no texels (None: the object alone)."""
    tri, uv = _as_triangles(triangles, uvs)
    h, w = (int(size), int(size)) if np.isscalar(size) else (int(size[0]), int(size[1]))
    tm = rasterize_patches(np.concatenate([uv, uv[:, 2:3]], axis=1), np.zeros(len(tri), int),
                           [(h, w)])
    im = tm.images[0]
    corners = np.concatenate([tri, tri[:, 2:3]], axis=1)            # triangles as (a, b, c, c)
    face_n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    face_n /= np.maximum(np.linalg.norm(face_n, axis=1, keepdims=True), 1e-300)
    patch, u, v = tm.patch, tm.u, tm.v
    pts = bilinear_point(corners[patch], u, v)
    if normals is not None:
        nc = np.asarray(normals, float).reshape(-1, 3, 3)[patch]
        lam = np.stack([(1 - u) * (1 - v), u * (1 - v), v], axis=1)  # Duffy -> barycentric
        shade = np.einsum("tk,tki->ti", lam, nc)
        shade /= np.maximum(np.linalg.norm(shade, axis=1, keepdims=True), 1e-300)
    else:
        shade = face_n[patch]
    geo = face_n[patch]
    shade = np.where(np.einsum("ij,ij->i", shade, geo)[:, None] < 0, -shade, shade)
    scene = tri if occluders is None else np.concatenate([tri, np.asarray(occluders, float)])
    lo, hi = scene.reshape(-1, 3).min(0), scene.reshape(-1, 3).max(0)
    diag = float(np.linalg.norm(hi - lo)) or 1.0
    reach = 4.0 * diag if distance is None else float(distance)
    occ = make_occluder(scene, backend=backend)
    lift = 4.0 * ray_offset(diag)
    rng = np.random.default_rng(seed)
    open_ = np.zeros(len(pts))
    per = max(1, CHUNK_RAYS // max(int(rays), 1))
    for a in range(0, len(pts), per):
        p, n = pts[a:a + per], shade[a:a + per]
        x1, x2 = stratified_unit_square(len(p), int(rays), rng)
        d = cosine_directions(n[:, None, :], x1[..., None], x2[..., None]).reshape(-1, 3)
        o = np.repeat(p + lift * geo[a:a + per], int(rays), axis=0)
        hit = occ.segments_occluded(o, o + reach * d, eps=1e-7)
        open_[a:a + per] = 1.0 - hit.reshape(len(p), int(rays)).mean(axis=1)
    ao = np.clip(open_, 0.0, 1.0).astype(np.float32)
    img = tm.scatter(ao[:, None], fill=0.0)[0][..., 0]
    img, grown = dilate_seams(img, im.coverage, SEAM_PIXELS)
    mean = float(ao.mean()) if len(ao) else 1.0
    img = np.where(grown, img, mean).astype(np.float32)
    return img, im.coverage.copy()
