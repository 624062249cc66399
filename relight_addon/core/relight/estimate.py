"""Scene parameters from the photographs (seed 000 §4.2.1): reflectances and lamp exitances.

Eq 4.1 estimates each element's reflectance from the mean of its texels,
    rho_i = (B^_i / B^_A) rho^,
with B^_A the mean intensity of the whole photograph and rho^ the scene's mean reflectance: set by
the user first, then re-estimated as the mean of the computed reflectances (which differs from
the first guess once reflectances are clamped below one), and the reflectances recomputed.

Eq 4.2 estimates the lamps' exitance from the energy balance of a closed scene,
    sum_i E_i A_i = (1 - rho^) B^_A sum_i A_i,
with all lamps equal, as the seed does.  Beyond the seed (its §4.2.1 says a system could be
solved for unequal lamps): with one radiosity basis per lamp at unit exitance, the exitances are
the non-negative least-squares fit of sum_k E_k B_k to the photographed radiosities.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import nnls

# Rec. 709 luminance weights: the photograph's "intensity" in eq 4.1 and 4.2.
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
# Reflectances are kept below this so that the radiosity system stays well conditioned.
RHO_MAX = 0.95


@dataclass
class ReflectanceEstimate:
    rho: np.ndarray            # (n, 3) per element
    rho_mean: float            # the final rho^ (area-weighted mean luminance reflectance)
    rho_mean_initial: float
    scene_intensity: float     # B^_A
    iterations: int


def estimate_reflectance(texel_mean, area, rho_mean=0.5, iterations=20, rho_max=RHO_MAX,
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


def equal_lamp_exitance(scene_intensity, rho_mean, total_area, lamp_area) -> float:
    """Eq 4.2 with equal lamps: the exitance shared by every lamp patch."""
    if lamp_area <= 0:
        raise ValueError("No lamp area to spread the emitted power over")
    return (1.0 - rho_mean) * scene_intensity * total_area / lamp_area


@dataclass
class ExitanceFit:
    exitance: np.ndarray       # (k,) per lamp, in the units of the observations
    residual: float            # relative area-weighted RMS misfit
    rank_deficient: bool


def fit_lamp_exitance(unit_basis, observed, area, channels_weight=LUMINANCE) -> ExitanceFit:
    """Non-negative least squares for per-lamp exitances.

    unit_basis (k, n, 3): radiosity of n elements with lamp k at unit exitance (others off),
    observed (n, 3): photographed radiosity, area (n,): weights (each element counts by area).
    Minimises sum_i A_i |sum_k E_k B_k,i - B^_i|^2 over the luminance, E >= 0.
    """
    unit_basis = np.asarray(unit_basis, float)
    observed = np.asarray(observed, float)
    w = np.sqrt(np.asarray(area, float))
    A = (unit_basis @ channels_weight).T * w[:, None]          # (n, k)
    b = (observed @ channels_weight) * w
    E, rnorm = nnls(A, b)
    rank_deficient = np.linalg.matrix_rank(A) < A.shape[1]
    return ExitanceFit(E, float(rnorm / max(np.linalg.norm(b), 1e-300)), bool(rank_deficient))
