"""Per-texel irradiance (texel mode): direct light ray-cast over each texel's footprint, indirect
light interpolated from the radiosity solution.

The direct irradiance from each lamp is linear in the lamps' exitances, so it is cast once per
(scene, texel map) at unit exitance factors and scaled afterwards (the exitance fit and the
maps reuse it).  It is computed in chunks of texels so that the footprint points and their rays
stay bounded (about 0.3 kB per texel and lamp are kept, whatever the texture size), on two
threads (numpy and Embree release the GIL); each chunk has its own seed (from its first texel's
place in the whole map), so the result does not depend on scheduling, nor on whether it is cast
for the whole map or block by block.

Photo-resolution textures (four 2048^2 photos: 16 M texels) are not held whole: while the direct
light of every texel and lamp fits in TEXEL_CACHE_BYTES (radiosity.memory) it is kept (the
exitance fit and the maps both read it), past that :meth:`TexelLight.rows` gives a block of
texels whose light is cast when it is read, and the caller streams (texel_maps.py, the exitance
fit's sample of texels).
"""
from __future__ import annotations

import numpy as np

from ..geometry.patch import bilinear_point
from ..progress import chunked
from ..radiosity.exposure import read_in_the_open
from ..radiosity.memory import TEXEL_CACHE_BYTES, give_back_memory
from ..texture.colour import luminance
from ..texture.mapping import (CornerInterpolation, inverse_bilinear, inverse_triangle,
                               texel_subset, uv_patch_is_triangle, vertex_interpolate)
from .direct import lamp_irradiance
from .proxy_texels import SmoothRead
from .transport import Transport

TEXEL_CHUNK = 1 << 13     # texels whose direct light is computed at once
# A scan's direct light is cast from this many RMS bump heights above its faces: its noise
# would shadow grazing rays that the photographed, smooth surface lets through.
BUMPS = 3.0


class TexelLight:
    """Irradiance at the texels of ``tm`` (a TexelMap of ``scene``): ``rays`` visibility rays per
    lamp patch, each texel's footprint sampled on a ``samples`` x ``samples`` grid."""

    def __init__(self, scene, tm, occluder, rays=32, samples=2, seed=0, solution_texels=None,
                 face_normals=None, smooth_read=False, offset=0.0, first=0):
        self.scene, self.tm, self.occluder = scene, tm, occluder
        # (p, 3) shading normals of the scene's faces instead of their own, read at each
        # texel's face when needed (a (T, 3) copy is 24 bytes a texel: 370 MB at 15 M)
        self.face_normals = face_normals
        # indirect light read by a kernel over the leaves (proxy_texels.SmoothRead) instead
        # of interpolated over the solution's elements
        self.smooth_read = smooth_read
        self.offset = offset          # ray origins lifted at least this far off the surface
        self._reader = (None, None)
        # where the solution's leaves are read (a radiosity proxy's own patches: proxy.py)
        self.solution_texels = tm if solution_texels is None else solution_texels
        self.rays, self.samples, self.seed = rays, samples, seed
        self.first = first            # the place of texel 0 in the whole map (the chunk seeds)
        self._direct = None
        self._subset = (None, None)
        self._direct_luminance = None

    @property
    def keeps_direct(self) -> bool:
        """Whether the direct light of every texel is kept once cast (else: read by blocks)."""
        return 48 * self.tm.n_texels * max(self.scene.n_lamps, 1) <= TEXEL_CACHE_BYTES

    def direct(self):
        """Direct irradiance (T, k, 3) from each lamp at unit exitance factor, unoccluded and
        with visibility, averaged over each texel's footprint (cast on the first call)."""
        if self._direct is None:
            self._direct = self.cast()
        return self._direct

    def rows(self, start, stop):
        """This light on the texels start .. stop - 1 (a block of the map): the same rays as
        the whole map's when ``start`` is a multiple of TEXEL_CHUNK; the direct light already
        cast is shared."""
        sl = slice(start, stop)
        part = TexelLight(self.scene, self.tm.rows(start, stop), self.occluder, self.rays,
                          self.samples, self.seed, self.solution_texels.rows(start, stop),
                          self.face_normals, self.smooth_read, self.offset, self.first + start)
        if self._direct is not None:
            part._direct = (self._direct[0][sl], self._direct[1][sl])
        return part

    def release(self):
        """Forget the light of :meth:`subset` (the exitance fit's sample) once it is done."""
        self._subset = (None, None)

    def subset(self, rows):
        """This light on the texels ``rows`` (sorted indices): their own rays (a sample of
        the map, e.g. the exitance fit's); the direct light already cast is shared."""
        key = (len(rows), hash(np.asarray(rows).tobytes()))
        if self._subset[0] == key:              # the exitance fit asks for it at every round
            return self._subset[1]
        mask = np.zeros(self.tm.n_texels, bool)
        mask[rows] = True
        tm = texel_subset(self.tm, mask)
        part = TexelLight(self.scene, tm, self.occluder, self.rays, self.samples, self.seed + 1,
                          tm if self.solution_texels is self.tm else
                          texel_subset(self.solution_texels, mask),
                          self.face_normals, self.smooth_read, self.offset)
        if self._direct is not None:
            part._direct = (self._direct[0][rows], self._direct[1][rows])
        self._subset = (key, part)
        return part

    def parts(self, sol, scale, leaf=None, unoccluded=True):
        """((direct occluded, direct unoccluded), (indirect occluded, indirect unoccluded)) per
        texel and lamp, each (k, T, 3): the direct and indirect terms of the irradiance (the
        unoccluded ones None unless ``unoccluded``).  ``leaf``: :func:`leaf_indirect` of
        ``sol``, when the caller already has it."""
        occ, un = leaf_indirect(sol) if leaf is None else leaf
        read = self.reader(sol)
        ind_occ = np.stack([read(x) for x in occ])
        ind_un = np.stack([read(x) for x in un]) if unoccluded else None
        U1, O1 = self.direct()
        s = np.asarray(scale, float)[None, :, None]
        O = np.moveaxis(O1 * s, 1, 0)                                    # (k, T, 3)
        U = np.moveaxis(U1 * s, 1, 0) if unoccluded else None
        return (O, U), (ind_occ, ind_un)

    def occluded_luminance(self, sol, scale):
        """Luminance of each lamp's occluded direct and indirect light per texel, (k, T) each,
        at the exitance factors ``scale``: what the exitance fit reads, with only the
        luminance of the direct light kept once cast (a sample of a photo-resolution map)."""
        if self._direct_luminance is None:
            if self._direct is not None:
                self._direct_luminance = luminance(self._direct[1]).T            # (k, T)
            else:
                self._direct_luminance = self.cast(luminance_only=True)
                give_back_memory()       # the casting threads' freed chunks (their own heaps)
        occ, _ = leaf_indirect(sol, unoccluded=False)
        read = self.reader(sol)
        indirect = np.stack([read(luminance(x)) for x in occ])
        return self._direct_luminance * np.asarray(scale, float)[:, None], indirect

    def reader(self, sol):
        """Leaf values -> per-texel values, for the solution's current leaves."""
        key = (id(sol.hierarchy), len(sol.leaves))
        if self._reader[0] == key:
            return self._reader[1]
        if self.smooth_read:
            patch = self.tm.patch
            points = bilinear_point(self.scene.corners[patch], self.tm.u, self.tm.v)
            read = SmoothRead(sol.hierarchy, sol.leaves, points, self._shading()[patch])
        else:
            stm = self.solution_texels
            interpolation = CornerInterpolation(sol.hierarchy, stm)

            def read(values):
                return vertex_interpolate(sol.hierarchy, values, stm, interpolation=interpolation)
        system = sol.system
        in_the_open = read_in_the_open(sol.hierarchy, sol.leaves, system.exposure,
                                       system.leaf_area)
        if in_the_open is not None:
            read_leaves = read

            def read(values):
                return read_leaves(in_the_open(values))
        self._reader = (key, read)
        return read

    def _shading(self):
        """(p, 3) the normal each face is lit by: its shading normal, else its own."""
        return self.face_normals if self.face_normals is not None else \
            self.scene.area_normal()[1]

    def cast(self, luminance_only=False):
        """(U, O) as :meth:`direct` gives them; with ``luminance_only`` the luminance of O
        alone, (k, T) (the exitance fit's sample of a photo-resolution map: 24 instead of 96
        bytes a texel at 2 lamps)."""
        scene, tm, first = self.scene, self.tm, self.first
        T, k = tm.n_texels, scene.n_lamps
        U = None if luminance_only else np.zeros((T, k, 3))
        O = np.zeros((k, T)) if luminance_only else np.zeros((T, k, 3))
        patch, u, v = tm.patch, tm.u, tm.v
        shading = self._shading()
        centre, size = texel_footprint_cells(tm)

        def chunk(c0):
            # chunks start at multiples of TEXEL_CHUNK of the whole map, whatever block this is
            sl = slice(c0, min(T, c0 + TEXEL_CHUNK - (first + c0) % TEXEL_CHUNK))
            pts, n_sub = footprint_points(scene, patch[sl], u[sl], v[sl], centre[sl], size[sl],
                                          self.samples)
            # the mean over each texel's footprint (a photo texel integrates it too)
            un, occ = lamp_irradiance(scene, pts.reshape(-1, n_sub, 3), shading[patch[sl]],
                                      self.occluder, self.rays, self.seed + 11 + first + c0,
                                      offset=self.offset)
            if luminance_only:
                O[:, sl] = luminance(occ).T
            else:
                U[sl], O[sl] = un, occ

        starts = [0] + list(range(TEXEL_CHUNK - first % TEXEL_CHUNK, T, TEXEL_CHUNK)) \
            if T else []
        chunked(chunk, starts, 2)
        return O if luminance_only else (U, O)


def texel_light_for(scene, tm, occluder, opt, seed, proxy, solution_texels):
    """The TexelLight of a shadow-free run (``opt``: its ShadowFreeOptions) on ``tm`` of
    ``scene``; on a proxy's scan: its shading normals, rays lifted over its bumps, the
    solution read by the proxy's kernel."""
    return TexelLight(scene, tm, occluder, opt.texel_rays, opt.texel_samples, seed,
                      solution_texels=solution_texels,
                      face_normals=None if proxy is None else proxy.normals,
                      smooth_read=proxy is not None,
                      offset=0.0 if proxy is None else BUMPS * proxy.roughness)


def leaf_indirect(sol, unoccluded=True):
    """Per lamp (k, L, 3) the indirect irradiance of each leaf, occluded and unoccluded
    (total minus direct; the latter None unless ``unoccluded``): what the texels read of the
    solution."""
    Hocc_k, HU_k, Docc_k, DU_k = Transport(sol).irradiance(sol.basis)
    return Hocc_k - Docc_k, (HU_k - DU_k if unoccluded else None)


def texel_footprint_cells(tm):
    """(T, 2) UV centre of every texel of ``tm`` and (T, 2) the size (width, height, texels)
    of its image: what :func:`footprint_points` spreads a texel's points by."""
    parts = [im for im in tm.images if len(im)]
    centre = np.concatenate([im.uv for im in parts]) if parts else np.zeros((0, 2))
    size = np.concatenate([np.repeat([[im.shape[1], im.shape[0]]], len(im), axis=0)
                           for im in parts]) if parts else np.zeros((0, 2))
    return centre, size


def footprint_points(scene, patch, u, v, centre, size, samples):
    """3D points (t * samples^2, 3) over each texel's footprint (a samples x samples grid in
    UV around the texel centre ``centre`` (t, 2) of an image of ``size`` (t, 2) texels, mapped
    through the owning patch; points past the patch edge are clamped onto it), and samples^2.
    ``u``, ``v``: the patch parameters of the texel centres."""
    if samples <= 1 or len(patch) == 0:
        pts = bilinear_point(scene.corners[patch][:, None], u[:, None], v[:, None])[:, 0]
        return pts, 1
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
    return pts, len(off)
