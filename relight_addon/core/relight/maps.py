"""Display maps and textures: per-texel values -> images, with the floors that keep them finite.

The relit colour of a texel is ``T_final x sum_k I_k M_k``: ``T_final`` the shadow-free texture,
``M_k`` lamp k's display map (its occluded irradiance over the irradiance the photo was lit by).

Floors (no NaN or Inf ever reaches a texture; textures stay linear and unclamped above 1):
* ratios such as the shadow-removal factor are clipped to [1 / FACTOR_MAX, FACTOR_MAX] (or a
  caller's floor): a texel in full shadow of every lamp has nothing to recover;
* M_k = 0 where the denominator is below DISPLAY_EPS x its maximum (unlit texels render black).
Seams are dilated by SEAM_PIXELS rings so that bilinear filtering does not pull in black.
"""
from __future__ import annotations

import numpy as np

from ..texture.colour import luminance
from ..texture.mapping import dilate_seams, texel_elements, vertex_interpolate

FACTOR_MAX = 64.0
# a floor far below any light the photo shows (float64 sums): a sun at 1e9 W/m^2 in a room lit
# by 60 W lamps must not black out the rest of the room
DISPLAY_EPS = 1e-12
SEAM_PIXELS = 4


def texels_of(image) -> np.ndarray:
    """(h, w, 3) float32 texels of an ImageTexels or a bare array."""
    return np.asarray(getattr(image, "texels", image), np.float32)[..., :3]


def clipped_ratio(num, den, fmax=FACTOR_MAX, fmin=None):
    """num / den clipped to [fmin (default 1/fmax), fmax]; 1 where both vanish."""
    num = np.maximum(np.asarray(num, float), 0.0)
    den = np.maximum(np.asarray(den, float), 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(den > 0, num / np.where(den > 0, den, 1.0), np.where(num > 0, fmax, 1.0))
    return np.clip(np.nan_to_num(r, nan=1.0, posinf=fmax), 1.0 / fmax if fmin is None else fmin,
                   fmax)


def maps_from(Hocc_k, HU, eps=DISPLAY_EPS):
    """M_k = H_occ,k / H_unocc per texel; 0 where H_unocc is below ``eps`` of its max (per
    channel, over every texel)."""
    HU = np.maximum(HU, 0.0)
    floor = np.maximum(eps * HU.max(axis=0, initial=0.0), 1e-300)
    lit = HU >= floor
    return np.where(lit[None], np.maximum(Hocc_k, 0.0) / np.where(lit, HU, 1.0)[None], 0.0)


def ratio_maps(sol, tm, eps=DISPLAY_EPS, weights=None):
    """The DRB97 display maps (texture correction off): M_k = B_k / sum_k w_k B_k per texel
    (k, T, 3), from vertex-interpolated leaf radiosity, with ``weights`` w_k each lamp's
    intensity in the photo (default 1); 0 below the floor (see maps_from)."""
    elem = texel_elements(sol.hierarchy, tm)
    Bk = np.stack([vertex_interpolate(sol.hierarchy, np.maximum(b, 0.0), tm, elem)
                   for b in sol.basis])
    w = np.ones(len(Bk)) if weights is None else np.asarray(weights, float)
    return maps_from(Bk, np.tensordot(w, Bk, axes=1), eps)


def map_images(tm, maps, seam_pixels=SEAM_PIXELS):
    """Per-texel maps (k, T, 3) -> {image index: (k, H, W, 3) float32}, dilated across seams,
    and {image index: coverage (H, W)}, for every image with covered texels."""
    mp, cov = {}, {}
    off = tm.offsets
    k = len(maps)
    for i, im in enumerate(tm.images):
        if len(im) == 0:
            continue
        hh, ww = im.shape
        sl = slice(off[i], off[i + 1])
        m = np.zeros((k, hh, ww, 3), np.float32)
        for j in range(k):
            full = np.zeros((hh * ww, 3), np.float32)
            full[im.texel_index] = maps[j][sl]
            m[j] = dilated(full.reshape(hh, ww, 3), im.coverage, seam_pixels)
        mp[i] = m
        cov[i] = im.coverage.copy()
    return mp, cov


def direct_fraction(direct_k, Hocc_k):
    """Per lamp and texel (k, T), the part of the lamp's light that comes straight from it:
    luminance(direct) / luminance(direct + indirect), in [0, 1] (1 where there is no light).
    A shadow cast later by a moving object (sphere_shadow.py) scales this part only."""
    d = luminance(np.maximum(direct_k, 0.0))
    h = luminance(np.maximum(Hocc_k, 0.0))
    return np.clip(np.where(h > 0, d / np.where(h > 0, h, 1.0), 1.0), 0.0, 1.0)


def texture_images(tm, t_final, images):
    """T_final per image: the original texels (``images``, the scene's photographs) outside the
    covered ones, dilated across seams."""
    tex = {}
    off = tm.offsets
    for i, im in enumerate(tm.images):
        if len(im) == 0:
            continue
        hh, ww = im.shape
        base = texels_of(images[i]).reshape(hh * ww, 3).copy()
        base[im.texel_index] = t_final[off[i]:off[i + 1]]
        tex[i] = dilated(base.reshape(hh, ww, 3), im.coverage).astype(np.float32)
    return tex


def dilated(image, coverage, pixels=SEAM_PIXELS):
    """``image`` with its seams dilated ``pixels`` rings deep (dilate_seams), NaN and Inf
    replaced by finite values."""
    return np.nan_to_num(dilate_seams(image, coverage, pixels)[0])
