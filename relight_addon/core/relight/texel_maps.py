"""Texel mode's last step (seed 000 §4.3 in texel terms), block by block: T_final, the maps M_k
and the part of each that is direct light, written straight into their images.

Per texel, H_occ,k and H_unocc,k are each lamp's direct light (ray cast, texel.py) plus its
indirect light (read from the solution); T_final = photo x H_unocc / H_occ (the shadow-removal
factor, never below 1) and M_k = H_occ,k / D, D = H_occ x that factor, so that T_final x sum_k
I_k M_k gives the photo back at its own intensities.  The texels are taken BLOCK at a time
(a multiple of the ray casting's chunk, so the rays are the whole map's): what is held per
texel is the images themselves and D (float32, kept for virtual lamps and objects added
later), whatever the photos' resolution.  The display floor of maps.maps_from (M_k = 0 where D
is below DISPLAY_EPS of its largest value) needs every texel's D, so it is applied once they
are all known.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..radiosity.memory import give_back_memory
from ..progress import tick
from .maps import DISPLAY_EPS, clipped_ratio, dilated, direct_fraction, texels_of
from . import texel
from .texel import leaf_indirect
from .transport import Transport, as_given

BLOCK = 16 * texel.TEXEL_CHUNK     # texels per block: ~150 MB of working arrays at 4 lamps


@dataclass
class TexelMaps:
    texture: dict          # image index -> (H, W, 3) float32 T_final (dilated)
    maps: dict             # image index -> (k, H, W, 3) float32 M_k (dilated)
    coverage: dict         # image index -> (H, W) bool
    direct: dict           # image index -> (k, H, W) float32 direct part of each map
    denominator: np.ndarray    # (T, 3) float32 D, the irradiance the photo was lit by


def texel_maps(light, sol, scale, scene, images, block=None) -> TexelMaps:
    """T_final, M_k and their direct parts for the texels of ``light`` (a TexelLight) from the
    solution ``sol`` at the exitance factors ``scale`` (k,); ``images`` the scene's photographs
    (read block by block; the texels no patch covers are kept)."""
    tm = light.tm
    out = _Images(tm, scene.n_lamps)
    photos = [texels_of(im) for im in images]
    texture = {i: photos[i].copy() for i in out.used}
    denominator = np.empty((tm.n_texels, 3), np.float32)
    leaf = leaf_indirect(sol)
    for start, stop in _blocks(tm.n_texels, block):
        tick(0.9 * start / max(tm.n_texels, 1))
        (O_k, U_k), (ind_occ, ind_un) = light.rows(start, stop).parts(sol, scale, leaf)
        tick(0.9 * (start + 0.5 * (stop - start)) / max(tm.n_texels, 1))
        Hocc_k, HU_k = np.maximum(O_k + ind_occ, 0.0), np.maximum(U_k + ind_un, 0.0)
        Hocc = as_given(Hocc_k, scene)
        # Removing occlusion never darkens (E-bar >= 0; sampling noise could say otherwise).
        factor = clipped_ratio(as_given(HU_k, scene), Hocc, fmin=1.0)
        D = Hocc * factor
        denominator[start:stop] = D
        t_final = tm.rows(start, stop).gather(photos) * factor
        for i, idx, src in out.put(start, stop, _ratio(Hocc_k, D), direct_fraction(O_k, Hocc_k)):
            texture[i].reshape(-1, 3)[idx] = t_final[src]
        give_back_memory()
    out.finish(denominator)
    for i in out.used:
        im = tm.images[i]
        texture[i] = dilated(texture[i], im.coverage)
    return TexelMaps(texture, out.maps, out.coverage, out.direct, denominator)


def lamp_maps(light, sol, lamps, s, denominator, block=None):
    """The maps (m, H, W, 3) and their direct parts (m, H, W) per image of lamps added to a
    solved room (virtual lamps): ``lamps`` their indices in ``sol``'s lamps, ``s`` their
    exitance factor, ``light`` a TexelLight whose scene has them (and no other light), over
    ``denominator`` (T, 3), the irradiance the photo was lit by."""
    tr = Transport(sol)
    basis = sol.basis[lamps]
    indirect = tr.per_lamp(tr.occ, basis) - tr.per_lamp(tr.dir_occ, basis)        # (m, L, 3)
    tm = light.tm
    out = _Images(tm, len(lamps))
    for start, stop in _blocks(tm.n_texels, block):
        tick(start / max(tm.n_texels, 1))
        part = light.rows(start, stop)
        read = part.reader(sol)
        O = np.moveaxis(part.direct()[1][:, lamps] * s, 1, 0)                      # (m, t, 3)
        H = np.maximum(O + np.stack([read(x) for x in indirect]), 0.0)
        D = np.asarray(denominator[start:stop], np.float64)
        list(out.put(start, stop, _ratio(H, D), direct_fraction(O, H)))
        give_back_memory()
    out.finish(denominator)
    return out.maps, out.direct


def _blocks(T, block):
    """Blocks of ``block`` (default BLOCK) texels, whole chunks of the ray casting each."""
    chunk = texel.TEXEL_CHUNK
    block = BLOCK if block is None else block
    block = max(chunk, block - block % chunk)
    return [(a, min(T, a + block)) for a in range(0, T, block)]


def _ratio(H_k, D):
    """H_k / D per lamp (k, t, 3), 0 where D is 0 (the display floor comes in finish)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(D > 0, np.maximum(H_k, 0.0) / np.where(D > 0, D, 1.0), 0.0)


class _Images:
    """Per-lamp maps and direct parts of a texel map's images, written block by block."""

    def __init__(self, tm, k):
        self.tm, self.k = tm, k
        self.used = [i for i, im in enumerate(tm.images) if len(im)]
        self.maps = {i: np.zeros((k,) + tm.images[i].shape + (3,), np.float32) for i in self.used}
        self.direct = {i: np.zeros((k,) + tm.images[i].shape, np.float32) for i in self.used}
        self.coverage = {}

    def put(self, start, stop, maps, fraction):
        """Write the block's maps (k, t, 3) and fractions (k, t); yields (image, texel
        indices in it, the block's rows) for the caller's own per-texel values."""
        off, k = self.tm.offsets, self.k
        for i in self.used:
            a, b = max(start, off[i]), min(stop, off[i + 1])
            if a >= b:
                continue
            idx = self.tm.images[i].texel_index[a - off[i]:b - off[i]]
            src = slice(a - start, b - start)
            self.maps[i].reshape(k, -1, 3)[:, idx] = maps[:, src]
            self.direct[i].reshape(k, -1)[:, idx] = fraction[:, src]
            yield i, idx, src

    def finish(self, denominator):
        """The display floor of maps.maps_from (0 where the denominator is below DISPLAY_EPS
        of its largest value, per channel, over every texel), then the seams dilated as
        maps.map_images does."""
        tm, k, off = self.tm, self.k, self.tm.offsets
        floor = np.maximum(DISPLAY_EPS * np.max(denominator, axis=0, initial=0.0), 1e-300)
        for i in self.used:
            im = tm.images[i]
            dark = denominator[off[i]:off[i + 1]] < floor
            flat = self.maps[i].reshape(k, -1, 3)
            for c in range(3):
                flat[:, im.texel_index[dark[:, c]], c] = 0.0
            for j in range(k):
                self.maps[i][j] = dilated(self.maps[i][j], im.coverage)
                self.direct[i][j] = dilated(self.direct[i][j], im.coverage)
            self.coverage[i] = im.coverage.copy()
