# SPDX-License-Identifier: GPL-3.0-or-later
"""What the photographed set hides from itself, per pixel of the photo: the "without the
object" half of differential rendering, once at set-up (the receivers do not move and the
camera matches the photo).

A receiver point under a table top does not see the sky above it, nor a sun behind a wall: the
photo already shows that, and an inserted object must not darken it again.  Per pixel, at the
receiver point the camera ray meets first (Embree):

* ``sun`` (H, W, 4): the part of each light's cone (main_light.py) seen past the receivers
  (stratified rays inside the cone); 1 for unused channels;
* ``open`` (H, W, 3): the residual irradiance the point receives past the receivers over the
  unoccluded one (cosine-distributed rays weighted by the residual's radiance, RGB);
* ``cone`` (H, W, 4): the visibility cone of the point (ambient aperture, Oat and Sander 2007):
  xyz its axis (the mean unoccluded direction, the bent normal), w the cosine of its half-angle,
  the cone around the normal with the same cosine-weighted open part f: asin(sqrt(f)).  An
  object outside it is hidden from the point by the set (composite.py: ``seen``).

Pixels without a receiver hold 1, 1 and the cone (0, 0, 1, 0).  Rows top first.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geometry.raycast import make_occluder, ray_offset
from ..geometry.sampling import cosine_directions, stratified_unit_square
from .envmap import sample_equirect

MAX_WIDTH = 480          # pixels: the maps are smooth where they matter (shadows' insides)
LIGHT_RAYS = 16          # per light and pixel (stratified in the cone)
SKY_RAYS = 64            # per pixel (stratified, cosine-distributed)
CHUNK = 4096             # pixels per batch of rays


@dataclass
class ReceiverView:
    hit: np.ndarray           # (H, W) bool: a receiver is seen at the pixel's centre
    sun: np.ndarray           # (H, W, 4)
    open: np.ndarray          # (H, W, 3)
    cone: np.ndarray          # (H, W, 4)


def view_size(resolution, max_width=MAX_WIDTH):
    """(w, h) of the maps for a render of ``resolution`` (W, H): at most max_width wide."""
    w, h = (int(x) for x in resolution)
    if w <= max_width:
        return w, h
    return max_width, max(1, int(round(h * max_width / w)))


def pixel_rays(camera, w, h):
    """(origins (h w, 3), unit directions (h w, 3)) of the camera rays through the centres of
    a w x h grid over the frame, rows top first (core/ar/view.py's model inverted)."""
    a_u, a_v, b_u, b_v = camera.factors()
    u = (np.arange(w) + 0.5) / w
    v = 1.0 - (np.arange(h) + 0.5) / h
    U, V = np.meshgrid(u, v)
    x = (U.ravel() - 0.5 + b_u) / a_u
    y = (V.ravel() - 0.5 + b_v) / a_v
    d_cam = np.stack([x, y, -np.ones_like(x)], 1)
    m = np.asarray(camera.matrix, float)
    r = m[:3, :3] / np.maximum(np.linalg.norm(m[:3, :3], axis=0, keepdims=True), 1e-300)
    d = d_cam @ r.T
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return np.broadcast_to(m[:3, 3], d.shape).copy(), d


def _cone_directions(axis, half_angle, k, rng):
    """(k, 3) directions stratified uniformly in solid angle inside a cone."""
    x1, x2 = stratified_unit_square(1, k, rng)
    x1, x2 = x1[0], x2[0]
    cos_t = 1.0 - x1 * (1.0 - np.cos(half_angle))
    sin_t = np.sqrt(np.maximum(1.0 - cos_t * cos_t, 0.0))
    a = np.asarray(axis, float)
    helper = np.array([1.0, 0.0, 0.0]) if abs(a[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    t1 = np.cross(a, helper)
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(a, t1)
    phi = 2 * np.pi * x2
    return (sin_t * np.cos(phi))[:, None] * t1 + (sin_t * np.sin(phi))[:, None] * t2 + \
        cos_t[:, None] * a


def receiver_view(camera, triangles, lights, residual, size, light_rays=LIGHT_RAYS,
                  sky_rays=SKY_RAYS, seed=0):
    """The :class:`ReceiverView` of the receivers ``triangles`` (t, 3, 3, world) seen by
    ``camera`` (view.CameraModel) on a ``size`` = (w, h) grid, under ``lights`` (up to 4
    MainLight) and the ``residual`` map (H, W, 3, top row first)."""
    w, h = size
    tri = np.asarray(triangles, float).reshape(-1, 3, 3)
    occ = make_occluder(tri)
    o, d = pixel_rays(camera, w, h)
    t, prim = occ.first_hit(o, d)
    hit = np.isfinite(t)
    n_px = w * h
    sun = np.ones((n_px, 4))
    opened = np.ones((n_px, 3))
    cone = np.tile([0.0, 0.0, 1.0, 0.0], (n_px, 1))
    idx = np.flatnonzero(hit)
    if len(idx):
        lo, hi = tri.reshape(-1, 3).min(0), tri.reshape(-1, 3).max(0)
        lift = 4.0 * ray_offset(float(np.linalg.norm(hi - lo)))
        reach = 4.0 * float(np.linalg.norm(hi - lo)) + 1.0
        fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        fn /= np.maximum(np.linalg.norm(fn, axis=1, keepdims=True), 1e-300)
        rng = np.random.default_rng(seed)
        cones = [_cone_directions(lt.direction, max(lt.half_angle, 1e-4), light_rays, rng)
                 for lt in lights[:4]]
        for a in range(0, len(idx), CHUNK):
            sel = idx[a:a + CHUNK]
            m = len(sel)
            nrm = fn[prim[sel]]
            nrm = np.where((np.einsum("ij,ij->i", nrm, d[sel]) > 0)[:, None], -nrm, nrm)
            p = o[sel] + t[sel, None] * d[sel] + lift * nrm
            for j, dirs in enumerate(cones):
                q = np.repeat(p, len(dirs), axis=0)
                e = q + reach * np.tile(dirs, (m, 1))
                blocked = occ.segments_occluded(q, e, eps=1e-7).reshape(m, len(dirs))
                sun[sel, j] = 1.0 - blocked.mean(axis=1)
            x1, x2 = stratified_unit_square(m, sky_rays, rng)
            dirs = cosine_directions(nrm[:, None, :], x1[..., None], x2[..., None])
            q = np.repeat(p, sky_rays, axis=0)
            flat = dirs.reshape(-1, 3)
            blocked = occ.segments_occluded(q, q + reach * flat, eps=1e-7).reshape(m, sky_rays)
            rad = sample_equirect(residual, flat).reshape(m, sky_rays, 3)
            free = ~blocked
            total = rad.sum(axis=1)
            opened[sel] = np.where(total > 0, (rad * free[..., None]).sum(axis=1) /
                                   np.maximum(total, 1e-300), free.mean(axis=1)[:, None])
            mean = (dirs * free[..., None]).sum(axis=1)
            norm = np.linalg.norm(mean, axis=1, keepdims=True)
            bent = np.where(norm > 1e-9, mean / np.maximum(norm, 1e-300), nrm)
            f = free.mean(axis=1)
            cone[sel, :3] = bent
            cone[sel, 3] = np.cos(np.arcsin(np.sqrt(np.clip(f, 0.0, 1.0))))
    return ReceiverView(hit.reshape(h, w), sun.reshape(h, w, 4), opened.reshape(h, w, 3),
                        cone.reshape(h, w, 4))
