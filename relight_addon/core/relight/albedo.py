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
    """rho per leaf = photo / irradiance, and the basis solved with it.

    A photographed leaf's radiosity is its photo (in photo units), so the light it sends to the
    others is known without its reflectance: its irradiance is f D + I*, with D the lamps'
    direct light at the current exitance factors and I* the light reflected by the other
    leaves, photographed ones at their photo (others at their solved radiosity).  Its
    reflectance is then photo / (f D + I*), and the one factor f on the lamps is the one that
    holds the mean reflectance at ``rho_mean`` (rho^: the absolute level is not in the photo;
    eq 4.1's assumption, or the shadow-depth fit of exitance.py).  ``scale`` (the exitance
    factors) is multiplied by f in place.  A round of this needs no fixed-point iteration of
    the reflectances (which drifts in colour in a strongly coloured room); the rounds only
    update the radiosity of the leaves that are not photographed and of clipped ones.
    ``use_patch`` (p,) marks the patches whose leaves are estimated (textured, not lamps).
    With ``unoccluded`` the irradiance ignores visibility (T_final is lit without shadows).
    Returns the leaf reflectances (L, 3)."""
    obs, counts = leaf_means(sol, tm, values)
    use = use_patch[sol.system.patch] & (counts > 0)
    a = sol.system.leaf_area
    rho = sol.system.rho.copy()
    solve_basis(sol, rho, scale)
    intensities = sol.scene.lamp_intensity
    for _ in range(max(rounds, 1)):
        B = sol.radiosity()
        B = np.where(use[:, None], obs, B)
        tr = Transport(sol)
        H = tr.total(B, intensities, unoccluded)
        D = tr.direct(B, intensities, unoccluded)
        I = np.maximum(H - D, 0.0)
        f = _lamp_factor(obs[use], D[use], I[use], a[use], rho_mean)
        with np.errstate(divide="ignore", invalid="ignore"):
            h = f * D + I
            r = np.where(h > 1e-12 * max(h.max(), 1e-300), obs / np.where(h > 0, h, 1.0), np.nan)
        ok = use[:, None] & np.isfinite(r)
        rho = np.where(ok, np.clip(r, 0.0, RHO_ESTIMATE_MAX), rho)
        scale *= f
        solve_basis(sol, rho, scale)
    return rho


def _lamp_factor(obs, D, I, area, target, iterations=100):
    """f such that the area-weighted mean luminance of min(obs / (f D + I), RHO_ESTIMATE_MAX)
    is ``target``; bisection on log f (the mean falls as f grows); 1 when undefined."""
    if len(obs) == 0 or area.sum() <= 0 or not 0 < target < RHO_ESTIMATE_MAX or not D.any():
        return 1.0
    w = area / area.sum()

    def mean_rho(f):
        h = f * D + I
        with np.errstate(divide="ignore", invalid="ignore"):
            r = np.where(h > 0, obs / np.where(h > 0, h, 1.0), RHO_ESTIMATE_MAX)
        return float(w @ luminance(np.minimum(np.nan_to_num(r, nan=0.0), RHO_ESTIMATE_MAX)))

    lo, hi = -30.0, 30.0
    if mean_rho(np.exp(hi)) > target or mean_rho(np.exp(lo)) < target:
        return 1.0                    # the indirect light alone explains the photo, or nothing
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        if mean_rho(np.exp(mid)) > target:
            lo = mid
        else:
            hi = mid
    return float(np.exp(0.5 * (lo + hi)))
