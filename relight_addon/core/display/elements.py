"""Per-element values for the viewport overlays (bpy-free): what each leaf of the last
precompute shows, coloured by the overlay shader's maps (core/display/colormap.py).

* ``"RATIO"``: B / D of each leaf = occluded / unoccluded irradiance (the seed's display ratio
  with rho cancelled): 1 where nothing blocks the light, towards 0 in shadow.
* ``"VISIBILITY"``: the worst visibility type over the lamps that matter for the leaf (those
  giving at least SIGNIFICANT_SHARE of its unoccluded direct light): VISIBLE 0, PARTIAL 1,
  INVISIBLE 2 (links.py codes).
* ``"FRONTIER"`` (element mode with reference elements): frontier leaves 0, shadowed leaves with
  a reference 1, without one 2; other leaves are not drawn.
* links: receiver and source centroids of the strongest links (F x V x B_source).
"""
from __future__ import annotations

import numpy as np

from ..numerics import safe_div
from ..radiosity.links import VISIBLE
from ..relight.refine import SIGNIFICANT_SHARE, visibility_class
from ..relight.transport import Transport, as_given
from ..texture.colour import luminance

MODES = ("RATIO", "VISIBILITY", "FRONTIER")


def element_values(result, mode: str):
    """(corners (n, 4, 3), values (n,)) of the leaves to draw for ``mode``."""
    if mode == "FRONTIER":
        info = getattr(result, "reference_info", None)
        if not info:
            return np.zeros((0, 4, 3)), np.zeros(0)
        h, leaves, codes = info["hierarchy"], info["leaves"], info["codes"]
        draw = codes >= 0
        return h.corners[leaves[draw]], codes[draw].astype(float)
    sol = result.solution
    h, leaves = sol.hierarchy, sol.leaves
    Hocc_k, HU_k, Docc_k, DU_k = Transport(sol).irradiance(sol.basis)
    lamp_leaf = sol.scene.lamp[h.patch[leaves]] >= 0
    if mode == "RATIO":
        hu, ho = luminance(as_given(HU_k, sol.scene)), luminance(as_given(Hocc_k, sol.scene))
        ratio = np.where(hu > 0, ho / np.where(hu > 0, hu, 1.0), 1.0)
        keep = ~lamp_leaf
        return h.corners[leaves[keep]], np.clip(ratio[keep], 0.0, 1.0)
    if mode == "VISIBILITY":
        du, do = luminance(DU_k), luminance(Docc_k)                        # (k, L)
        att = np.where(du > 0, do / np.where(du > 0, du, 1.0), 1.0)
        share = safe_div(du, luminance(as_given(HU_k, sol.scene))[None])
        sig = share >= SIGNIFICANT_SHARE
        code = visibility_class(att)
        worst = np.where(sig, code, VISIBLE).max(axis=0, initial=VISIBLE)
        keep = ~lamp_leaf
        return h.corners[leaves[keep]], worst[keep].astype(float)
    raise ValueError(f"unknown overlay mode {mode!r}")


def strongest_links(result, count: int = 5000):
    """(starts (n, 3), ends (n, 3)): receiver -> source centroids of the ``count`` links that
    carry the most light (F x V x brightest channel of the source's radiosity)."""
    sol = result.solution
    h, links = sol.hierarchy, sol.links
    if links.n == 0:
        return np.zeros((0, 3)), np.zeros((0, 3))
    b_leaf = sol.radiosity().max(axis=1)
    b_elem = sol.system.P_up @ b_leaf
    power = links.F * links.V * b_elem[links.source]
    top = np.argsort(power)[::-1][:count]
    return h.centroid[links.receiver[top]], h.centroid[links.source[top]]
