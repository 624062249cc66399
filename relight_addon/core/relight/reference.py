"""Second modification of the textures (seed 000 fig 4.11, eq 4.8-4.9): frontier and reference
elements.

Shadowed leaves (a significant lamp not fully visible), frontier leaves (every significant lamp
fully visible, a shadowed neighbour, seen by the camera), and a reference per shadowed leaf: the
nearest frontier leaf of the same object whose reflectance is within ``reference_eps`` in LAB.
rho_corr (eq 4.8) and T_final (eq 4.9).  Reflectances here are physical (photo / irradiance), so
the seed's form-factor ratio of eq 4.8 is already inside them: rho_corr_i = rho_r.
"""
from __future__ import annotations

import numpy as np

from ..geometry.extent import bounding_diagonal
from ..geometry.raycast import ray_offset
from ..numerics import safe_div
from ..texture.colour import lab_distance, luminance
from ..texture.mapping import element_means, neighbour_element_pairs
from .maps import clipped_ratio
from .refine import SIGNIFICANT_SHARE, VIS_TOL, lab_of


def camera_visible(sol, leaves, occluder):
    vp = sol.scene.viewpoint
    h = sol.hierarchy
    if vp is None:
        return np.ones(len(leaves), bool)
    vp = np.asarray(vp, float)
    c = h.centroid[leaves]
    d = vp[None] - c
    facing = np.einsum("ij,ij->i", d, h.normal[leaves]) > 0
    if occluder is None:
        return facing
    eps = ray_offset(bounding_diagonal(h.corners[: sol.scene.n_patches]))
    blocked = occluder.segments_occluded(c + eps * h.normal[leaves], np.broadcast_to(vp, c.shape))
    return facing & ~blocked


def reference_correction(sol, tm, elem, t_inter, HU, Docc_k, DU_k, occluder, opt):
    """Per-leaf factor rho_corr / rho_inter (L, 3), (shadowed, frontier, referenced,
    defaulted) counts, and per-leaf codes for the overlay (frontier 0, shadowed with a
    reference 1, without 2, others -1)."""
    h = sol.hierarchy
    leaves = sol.leaves
    L = len(leaves)
    slot = np.full(h.n, -1, np.int64)
    slot[leaves] = np.arange(L)
    patch = h.patch[leaves]
    lamp_leaf = sol.scene.lamp[patch] >= 0
    du, do = luminance(DU_k), luminance(Docc_k)                           # (k, L)
    att = np.where(du > 0, do / np.where(du > 0, du, 1.0), 1.0).T
    share = safe_div(du, luminance(HU)[None]).T
    sig = (share >= SIGNIFICANT_SHARE) & (sol.scene.lamp_intensity > 0)[None, :]  # lit in the photo
    shadowed = np.any(sig & (att < 1 - VIS_TOL), axis=1) & ~lamp_leaf
    lit = ~np.any(sig & (att < 1 - VIS_TOL), axis=1) & ~lamp_leaf & np.any(sig, axis=1)
    means, counts = element_means(t_inter, elem, h.n, hierarchy=h)
    obs = means[leaves]
    has_tex = counts[leaves] > 0
    rho_inter = safe_div(obs, HU)                            # physical albedo
    pairs = neighbour_element_pairs(tm, elem)
    near_shadow = np.zeros(L, bool)
    if len(pairs):
        a, b = slot[pairs[:, 0]], slot[pairs[:, 1]]
        ok = (a >= 0) & (b >= 0)
        a, b = a[ok], b[ok]
        near_shadow[a[shadowed[b]]] = True
        near_shadow[b[shadowed[a]]] = True
    frontier = lit & near_shadow & has_tex
    fidx = np.flatnonzero(frontier)
    if len(fidx):
        fidx = fidx[camera_visible(sol, leaves[fidx], occluder)]
    corr = np.ones((L, 3))
    codes = np.full(L, -1, np.int8)
    codes[fidx] = 0
    sidx = np.flatnonzero(shadowed & has_tex)
    if len(sidx) == 0:
        return corr, (0, len(fidx), 0, 0), codes
    white = float(np.percentile(luminance(rho_inter[has_tex]), 99)) if has_tex.any() else 1.0
    lab = lab_of(rho_inter, white)
    ref = np.full(len(sidx), -1, np.int64)
    group = sol.scene.group[patch]
    defaulted = 0
    for start in range(0, len(sidx), 2048):
        s = sidx[start:start + 2048]
        if len(fidx) == 0:
            break
        same = group[s][:, None] == group[fidx][None, :]
        dlab = lab_distance(lab[s][:, None], lab[fidx][None, :])
        dist = np.linalg.norm(h.centroid[leaves[s]][:, None] - h.centroid[leaves[fidx]][None], axis=2)
        ok = same & (dlab <= opt.reference_eps)
        best = np.where(ok, dist, np.inf).argmin(axis=1)
        found = np.isfinite(np.where(ok, dist, np.inf).min(axis=1))
        r = np.where(found, fidx[best], -1)
        if opt.default_reference == "auto":
            # Default: the frontier leaf of the same object with the closest colour.
            dflt = np.where(same, dlab, np.inf)
            has = np.isfinite(dflt.min(axis=1))
            r = np.where(~found & has, fidx[dflt.argmin(axis=1)], r)
            defaulted += int(np.sum(~found & has))
        elif opt.default_reference is not None:
            d = int(slot[int(opt.default_reference)]) if int(opt.default_reference) < h.n else -1
            if d >= 0:
                defaulted += int(np.sum(~found))
                r = np.where(found, r, d)
        ref[start:start + len(s)] = r
    has_ref = ref >= 0
    si, ri = sidx[has_ref], ref[has_ref]
    corr[si] = clipped_ratio(rho_inter[ri], rho_inter[si])
    codes[sidx] = np.where(has_ref, 1, 2)
    return corr, (len(sidx), len(fidx), int(has_ref.sum()) - defaulted, defaulted), codes
