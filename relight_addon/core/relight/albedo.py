"""Reflectances from the photographs (seed 000 §4.2.1, eq 4.1, and per-leaf re-estimation).

Eq 4.1 estimates each element's reflectance from the mean of its texels,
    rho_i = (B^_i / B^_A) rho^,
with B^_A the mean intensity of the whole photograph and rho^ the scene's mean reflectance: set by
the user first, then re-estimated as the mean of the computed reflectances (which differs from
the first guess once reflectances are clamped), and the reflectances recomputed.

Eq 4.1 assumes uniform lighting.  Once a radiosity solution exists, the reflectance of every
leaf is re-estimated as photo / irradiance (beyond the seed), with the mean held at rho^: the
absolute scale of reflectance is not observable from a photo, so the lamps' exitance factors
absorb it and the radiosity stays in photo units.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..radiosity.precompute import solve_basis
from ..texture.colour import LUMINANCE, luminance
from .transport import Transport, leaf_means

# Reflectances estimated from photos stay below this, under the scene's hard limit RHO_MAX:
# a few noisy leaves at 0.99 multiply the interreflections (1 / (1 - rho)); measured on the
# white office (true albedo 0.9), lamp off: CIEDE2000 1.3 with 0.95, 1.7 with 0.99.
RHO_ESTIMATE_MAX = 0.95


@dataclass
class ReflectanceEstimate:
    rho: np.ndarray            # (n, 3) per element
    rho_mean: float            # the final rho^ (area-weighted mean luminance reflectance)
    rho_mean_initial: float
    scene_intensity: float     # B^_A
    iterations: int


def estimate_reflectance(texel_mean, area, rho_mean=0.5, iterations=20,
                         rho_max=RHO_ESTIMATE_MAX,
                         tol=1e-9) -> ReflectanceEstimate:
    """Eq 4.1 with the seed's re-estimation of the mean reflectance.

    texel_mean (n, 3) linear RGB mean of each element's texels (the photograph), area (n,).
    The mean intensity B^_A is the area-weighted mean luminance; colours keep their ratios.
    """
    texel_mean = np.asarray(texel_mean, float)
    area = np.asarray(area, float)
    lum = texel_mean @ LUMINANCE
    total = float(area.sum())
    if total <= 0:
        raise ValueError("The photographed surfaces have no area")
    b_a = float(area @ lum) / total
    if b_a <= 0:
        raise ValueError("The photograph is black: nothing to estimate reflectances from")
    guess = float(rho_mean)
    current = guess
    for it in range(1, iterations + 1):
        rho = np.clip(texel_mean / b_a * current, 0.0, rho_max)
        new = float(area @ (rho @ LUMINANCE)) / total
        if abs(new - current) <= tol * max(current, 1e-12):
            current = new
            break
        current = new
    rho = np.clip(texel_mean / b_a * current, 0.0, rho_max)
    return ReflectanceEstimate(rho, current, guess, b_a, it)


def albedo_rounds(sol, tm, values, use_patch, rho_mean, rounds, scale, unoccluded=False):
    """rho per leaf = photo mean / irradiance, and the basis solved with it.

    ``use_patch`` (p,) marks the patches whose leaves are estimated (textured, not lamps).  The
    mean reflectance is held at ``rho_mean`` (rho^) and the exitance factors ``scale``
    (updated in place) absorb the rest.  With ``unoccluded`` the irradiance ignores visibility
    (T_final is lit without shadows).  Returns the leaf reflectances (L, 3)."""
    obs, counts = leaf_means(sol, tm, values)
    use = use_patch[sol.system.patch] & (counts > 0)
    a = sol.system.leaf_area
    rho = sol.system.rho.copy()
    solve_basis(sol, rho, scale)
    for _ in range(max(rounds, 1)):
        H = Transport(sol).total(sol.radiosity(), sol.scene.lamp_intensity, unoccluded)
        with np.errstate(divide="ignore", invalid="ignore"):
            r = np.where(H > 1e-12 * max(H.max(), 1e-300), obs / np.where(H > 0, H, 1.0), np.nan)
        ok = use[:, None] & np.isfinite(r)
        r = np.where(ok, r, rho)
        c = clipped_mean_scale(luminance(r[use]), a[use], rho_mean)
        r[use] /= c
        scale *= c
        rho = np.where(use[:, None], np.clip(r, 0.0, RHO_ESTIMATE_MAX), rho)
        solve_basis(sol, rho, scale)
    return rho


def clipped_mean_scale(lum, area, target, iterations=100):
    """c such that the area-weighted mean of min(lum / c, RHO_ESTIMATE_MAX) is ``target``
    (eq 4.1's re-estimated mean: reflectances are clipped, so a few unlit leaves with huge
    photo / irradiance ratios cannot drag the scale).  Bisection on log c; 1 when undefined."""
    ok = np.isfinite(lum) & (lum > 0)
    lum, area = lum[ok], area[ok]
    if len(lum) == 0 or area.sum() <= 0 or not 0 < target < RHO_ESTIMATE_MAX:
        return 1.0
    w = area / area.sum()
    med = float(np.median(lum))
    lo, hi = np.log(med) - 30.0, np.log(med) + 30.0
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        if float(w @ np.minimum(lum / np.exp(mid), RHO_ESTIMATE_MAX)) > target:
            lo = mid
        else:
            hi = mid
    return float(np.exp(0.5 * (lo + hi)))
