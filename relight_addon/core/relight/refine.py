"""Texture-based refinement (seed 000 §4.3.1, fig 4.7).

Neighbouring leaves (texel-adjacent, so also across patch edges that are continuous in UV) are
compared by colour (CIE LAB distance of their photo means, eq 4.4) and by visibility of each
lamp (type and attenuation); a leaf that disagrees with a neighbour, or sees a lamp partially,
is a candidate.  Instead of splitting and undoing, each candidate's four children are probed
first (visibility of every lamp at their centres) and the split is made only where they differ:
the same result as "undo a subdivision whose children show no visibility change", without the
round trip.  Splits stop at the preset's minimum element size and at about one texel.
"""
from __future__ import annotations

import numpy as np

from ..geometry.patch import bilinear_point
from ..numerics import safe_div
from ..radiosity.links import INVISIBLE, PARTIAL, VISIBLE
from ..radiosity.presets import get_preset
from ..texture.colour import lab_distance, linear_rgb_to_lab, luminance
from ..texture.mapping import element_means, neighbour_element_pairs, texel_elements
from .direct import lamp_irradiance

# A lamp whose unoccluded share of a leaf's irradiance is below this does not make it
# "shadowed" (or "lit") for refinement and the frontier / reference step.
SIGNIFICANT_SHARE = 0.05
# Attenuation above 1 - VIS_TOL counts as fully visible, below VIS_TOL as invisible.
VIS_TOL = 0.02


def visibility_class(att):
    """VISIBLE / PARTIAL / INVISIBLE of lamp attenuations (visible fraction of the light)."""
    return np.where(att >= 1 - VIS_TOL, VISIBLE, np.where(att <= VIS_TOL, INVISIBLE, PARTIAL))


def lab_of(values, white):
    """CIE LAB of linear values normalised by ``white`` (clipped at 0)."""
    return linear_rgb_to_lab(np.clip(safe_div(np.nan_to_num(values), white), 0.0, None))


def probe_attenuation(sol, elements, occluder, opt, scale, uv_points):
    """Per lamp attenuation (n, m, k) at parameter points ``uv_points`` (m, 2) of elements."""
    h = sol.hierarchy
    c = h.corners[elements]
    pts = bilinear_point(c[:, None], uv_points[None, :, 0], uv_points[None, :, 1])
    nrm = np.repeat(h.normal[elements], len(uv_points), axis=0)
    U, O = lamp_irradiance(sol.scene, pts.reshape(-1, 3), nrm, occluder, opt.probe_rays,
                           opt.seed + 7, scale)
    u, o = luminance(U), luminance(O)
    att = np.where(u > 0, o / np.where(u > 0, u, 1.0), 1.0)
    share = safe_div(u, u.sum(axis=1, keepdims=True))
    m = len(uv_points)
    return att.reshape(len(elements), m, -1), share.reshape(len(elements), m, -1)


_CHILD_CENTRES = np.array([[0.25, 0.25], [0.75, 0.25], [0.75, 0.75], [0.25, 0.75]])
_CENTRE = np.array([[0.5, 0.5]])


def refine_by_texture(sol, tm, values, white, occluder, opt, scale, colour=True):
    """Fig 4.7 (see the module docstring); splits leaves of ``sol.hierarchy`` in place."""
    h = sol.hierarchy
    min_area = (get_preset(opt.preset).min_area * opt.refine_min_area
                * float(h.area[:sol.scene.n_patches].sum()))
    lamp_patch = sol.scene.lamp >= 0
    total_split = 0
    for _ in range(opt.refine_rounds):
        leaves = h.leaves()
        elem = texel_elements(h, tm)
        means, counts = element_means(values, elem, h.n, hierarchy=h)
        pairs = neighbour_element_pairs(tm, elem)
        live = leaves[~lamp_patch[h.patch[leaves]]]
        att, share = probe_attenuation(sol, live, occluder, opt, scale, _CENTRE)
        att, share = att[:, 0], share[:, 0]
        sig = share >= SIGNIFICANT_SHARE
        vis = np.where(sig, visibility_class(att), VISIBLE)
        slot = np.full(h.n, -1, np.int64)
        slot[live] = np.arange(len(live))
        cand = np.zeros(h.n, bool)
        cand[live[np.any(vis == PARTIAL, axis=1)]] = True
        if len(pairs):
            a, b = slot[pairs[:, 0]], slot[pairs[:, 1]]
            ok = (a >= 0) & (b >= 0)
            pa, pb, a, b = pairs[ok, 0], pairs[ok, 1], a[ok], b[ok]
            differ = np.any(vis[a] != vis[b], axis=1) | np.any(
                np.abs(att[a] - att[b]) * (sig[a] | sig[b]) > opt.attenuation_threshold, axis=1)
            if colour:
                lab = lab_of(means, white)
                differ |= lab_distance(lab[pa], lab[pb]) > opt.colour_threshold
            cand[pa[differ]] = True
            cand[pb[differ]] = True
        # Stop at the minimum element size and at about one texel per child.
        cand &= (h.area[: h.n] / 4 >= min_area) & (counts >= 4)
        ids = np.flatnonzero(cand)
        if len(ids) == 0:
            break
        # Probe the four children: split only where the visibility changes inside.
        catt, cshare = probe_attenuation(sol, ids, occluder, opt, scale, _CHILD_CENTRES)
        csig = cshare.max(axis=1) >= SIGNIFICANT_SHARE
        cvis = visibility_class(catt)
        change = (np.any((cvis != cvis[:, :1]) & csig[:, None], axis=(1, 2))
                  | np.any((catt.max(1) - catt.min(1)) * csig > opt.attenuation_threshold, axis=1))
        ids = ids[change]
        if len(ids) == 0:
            break
        h.split(ids)
        total_split += len(ids)
    sol.counts["texture_splits"] = total_split
    return total_split
