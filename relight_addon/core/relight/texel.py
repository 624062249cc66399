"""Per-texel irradiance (texel mode): direct light ray-cast over each texel's footprint, indirect
light interpolated from the radiosity solution.

The direct irradiance from each lamp is linear in the lamps' exitances, so it is cast once per
(scene, texel map) at unit exitance factors and scaled afterwards (the exitance fit and the
maps reuse it).  It is computed in chunks of texels so that the footprint points and their rays
stay bounded (about 0.3 kB per texel and lamp are kept, whatever the texture size), on two
threads (numpy and Embree release the GIL); each chunk has its own seed, so the result does not
depend on scheduling.
"""
from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np

from ..scene import bilinear_point
from ..texture.mapping import (CornerInterpolation, inverse_bilinear, inverse_triangle,
                               uv_patch_is_triangle, vertex_interpolate)
from .direct import lamp_irradiance
from .transport import Transport

TEXEL_CHUNK = 1 << 13     # texels whose direct light is computed at once


class TexelLight:
    """Irradiance at the texels of ``tm`` (a TexelMap of ``scene``): ``rays`` visibility rays per
    lamp patch, each texel's footprint sampled on a ``samples`` x ``samples`` grid."""

    def __init__(self, scene, tm, occluder, rays=32, samples=2, seed=0, solution_texels=None,
                 normals=None, smooth_read=False, offset=0.0):
        self.scene, self.tm, self.occluder = scene, tm, occluder
        self.normals = normals        # (T, 3) shading normals instead of the faces' own
        # indirect light read by a kernel over the leaves (radiosity.proxy.SmoothRead) instead
        # of interpolated over the solution's elements
        self.smooth_read = smooth_read
        self.offset = offset          # ray origins lifted at least this far off the surface
        self._reader = (None, None)
        # where the solution's leaves are read (a radiosity proxy's own patches: proxy.py)
        self.solution_texels = tm if solution_texels is None else solution_texels
        self.rays, self.samples, self.seed = rays, samples, seed
        self._direct = None

    def direct(self):
        """Direct irradiance (T, k, 3) from each lamp at unit exitance factor, unoccluded and
        with visibility, averaged over each texel's footprint (cast on the first call)."""
        if self._direct is None:
            self._direct = self._cast()
        return self._direct

    def irradiance(self, sol, scale):
        """(H_occ,k, H_unocc,k) per texel (k, T, 3) with the exitance factors ``scale`` (k,):
        direct by ray casting, indirect interpolated from the solution's leaves."""
        (O, U), (ind_occ, ind_un) = self.parts(sol, scale)
        return np.maximum(O + ind_occ, 0.0), np.maximum(U + ind_un, 0.0)

    def parts(self, sol, scale):
        """((direct occluded, direct unoccluded), (indirect occluded, indirect unoccluded)) per
        texel and lamp, each (k, T, 3): the two terms of :meth:`irradiance`."""
        Hocc_k, HU_k, Docc_k, DU_k = Transport(sol).irradiance(sol.basis)
        read = self.reader(sol)
        ind_occ = np.stack([read(o - d) for o, d in zip(Hocc_k, Docc_k)])
        ind_un = np.stack([read(u - d) for u, d in zip(HU_k, DU_k)])
        U1, O1 = self.direct()
        s = np.asarray(scale, float)[None, :, None]
        U, O = np.moveaxis(U1 * s, 1, 0), np.moveaxis(O1 * s, 1, 0)      # (k, T, 3)
        return (O, U), (ind_occ, ind_un)

    def reader(self, sol):
        """Leaf values -> per-texel values, for the solution's current leaves."""
        key = (id(sol.hierarchy), len(sol.leaves))
        if self._reader[0] == key:
            return self._reader[1]
        if self.smooth_read:
            from ..radiosity.proxy import SmoothRead
            tm = self.tm
            points = bilinear_point(self.scene.corners[tm.patch], tm.u, tm.v)
            normals = self.normals if self.normals is not None else \
                self.scene.area_normal()[1][tm.patch]
            read = SmoothRead(sol.hierarchy, sol.leaves, points, normals)
        else:
            stm = self.solution_texels
            interpolation = CornerInterpolation(sol.hierarchy, stm)

            def read(values):
                return vertex_interpolate(sol.hierarchy, values, stm, interpolation=interpolation)
        self._reader = (key, read)
        return read

    def _cast(self):
        scene, tm = self.scene, self.tm
        T, k = tm.n_texels, scene.n_lamps
        U = np.zeros((T, k, 3))
        O = np.zeros((T, k, 3))
        patch, u, v = tm.patch, tm.u, tm.v
        parts = [im for im in tm.images if len(im)]
        centre = np.concatenate([im.uv for im in parts]) if parts else np.zeros((0, 2))
        size = np.concatenate([np.repeat([[im.shape[1], im.shape[0]]], len(im), axis=0)
                               for im in parts]) if parts else np.zeros((0, 2))

        def chunk(c0):
            sl = slice(c0, c0 + TEXEL_CHUNK)
            pts, nrm, n_sub = footprint_points(scene, patch[sl], u[sl], v[sl], centre[sl],
                                               size[sl], self.samples)
            # the mean over each texel's footprint (a photo texel integrates it too)
            if self.normals is not None:
                nrm = np.repeat(self.normals[sl], n_sub, axis=0)
            U[sl], O[sl] = lamp_irradiance(scene, pts.reshape(-1, n_sub, 3), nrm[::n_sub],
                                           self.occluder, self.rays, self.seed + 11 + c0,
                                           offset=self.offset)

        starts = range(0, T, TEXEL_CHUNK)
        if len(starts) > 1:
            with ThreadPoolExecutor(2) as pool:
                list(pool.map(chunk, starts))
        else:
            for c0 in starts:
                chunk(c0)
        return U, O


def footprint_points(scene, patch, u, v, centre, size, samples):
    """3D points (t * samples^2, 3) and normals over each texel's footprint (a samples x
    samples grid in UV around the texel centre ``centre`` (t, 2) of an image of ``size`` (t, 2)
    texels, mapped through the owning patch; points past the patch edge are clamped onto it).
    ``u``, ``v``: the patch parameters of the texel centres."""
    normals = scene.area_normal()[1][patch]
    if samples <= 1 or len(patch) == 0:
        pts = bilinear_point(scene.corners[patch][:, None], u[:, None], v[:, None])[:, 0]
        return pts, normals, 1
    uvc = scene.uv[patch]
    g = (np.arange(samples) + 0.5) / samples - 0.5
    off = np.stack(np.meshgrid(g, g, indexing="xy"), -1).reshape(-1, 2)        # (s^2, 2)
    q = (centre[:, None] + off[None] / size[:, None]).reshape(-1, 2)            # (t s^2, 2)
    rep = np.repeat(np.arange(len(patch)), len(off))
    tri = uv_patch_is_triangle(uvc)[rep]
    uu = np.empty(len(q))
    vv = np.empty(len(q))
    if (~tri).any():
        uu[~tri], vv[~tri], _ = inverse_bilinear(uvc[rep[~tri]], q[~tri])
    if tri.any():
        uu[tri], vv[tri] = inverse_triangle(uvc[rep[tri]], q[tri])[:2]
    uu = np.clip(np.nan_to_num(uu, nan=0.5), 0.0, 1.0)
    vv = np.clip(np.nan_to_num(vv, nan=0.5), 0.0, 1.0)
    pts = bilinear_point(scene.corners[patch][rep][:, None], uu[:, None], vv[:, None])[:, 0]
    return pts, normals[rep], len(off)
