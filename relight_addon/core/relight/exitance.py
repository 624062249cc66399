"""Lamp exitances from the photographs (seed 000 §4.2.1, eq 4.2, and beyond it).

Eq 4.2 estimates the lamps' exitance from the energy balance of a closed scene,
    sum_i E_i A_i = (1 - rho^) B^_A sum_i A_i,
with all lamps equal, as the seed does.  Beyond the seed (its §4.2.1 says a system could be
solved for unequal lamps): with one radiosity basis per lamp at unit exitance, the exitances are
the non-negative least-squares fit of sum_k E_k B_k to the photographed radiosities; and the
shadow-edge fit, which finds the ratios that make photo / irradiance smoothest across the
photo's shadow edges.  Every estimate is a factor per lamp: photo units per scene unit.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import nnls

from ..texture.colour import LUMINANCE, luminance
from ..texture.mapping import adjacent_texel_pairs
from .albedo import albedo_rounds
from .transport import leaf_means


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


def fit_lamps(sol, tm, photo, use_patch, est, opt, texel_light):
    """Exitance factors (photo units per scene unit) by eq 4.2, by NNLS and by the shadow-edge
    fit (``opt.exitance``); then per-leaf albedo rounds (the basis is solved with them).
    Returns (scale used, eq 4.2, NNLS).

    Only lamps that are on in the photo (``scene.lamp_intensity`` > 0) are fitted; a lamp that
    is off in it takes the geometric mean of their factors (the user's power units)."""
    scene = sol.scene
    k = scene.n_lamps
    lamp_patch = scene.lamp >= 0
    lum_emission = luminance(scene.emission)
    area = scene.area_normal()[0]
    eq_k = np.ones(k)
    if est is not None:
        lamp_area = float(area[lamp_patch].sum())
        e_eq = equal_lamp_exitance(est.scene_intensity, est.rho_mean,
                                   float(area[use_patch].sum()), lamp_area)
        for j in range(k):
            sel = scene.lamp == j
            e_j = float((area[sel] * lum_emission[sel]).sum() / max(area[sel].sum(), 1e-300))
            eq_k[j] = e_eq / max(e_j, 1e-300)
    nnls_k = nnls_factors(sol, tm, photo, use_patch)
    on = scene.lamp_intensity > 0

    def rounds(scale):
        scale[~on] = np.exp(np.mean(np.log(np.maximum(scale[on], 1e-300))))
        albedo_rounds(sol, tm, photo, use_patch, opt.rho_mean, opt.albedo_rounds, scale)

    if opt.exitance == "nnls" and np.any(nnls_k > 0):
        scale = nnls_k.copy()
    elif opt.exitance == "equal" or on.sum() == 1:
        scale = eq_k.copy()
    else:   # "edges"
        scale = (nnls_k if np.any(nnls_k > 0) else eq_k).copy()
        rounds(scale)
        for _ in range(2):
            scale[on] = edge_fit(sol, tm, photo, scale, texel_light, on)
            rounds(scale)
        return scale, eq_k, nnls_k
    rounds(scale)
    return scale, eq_k, nnls_k


def edge_fit(sol, tm, photo, scale, texel_light, on):
    """Relative lamp exitances that make the reflectance photo / irradiance smoothest.

    Reflectance does not know where shadows fall: with the right exitance ratios the photo's
    shadow edges are explained by the irradiance and vanish from photo / H.  Minimises the
    total variation of log(photo / sum_k t_k H_k) over neighbouring texels (robust to genuine
    texture edges, which add a constant) over the k - 1 free ratios; irradiance per texel with
    ray-cast direct light (``texel_light``, a TexelLight), the overall scale is kept.  Only the
    lamps ``on`` in the photo take part; returns their factors.
    """
    from scipy.optimize import minimize
    k = int(np.sum(on))
    if k < 2 or tm.n_texels == 0:
        return scale[on]
    Hocc_k, _ = texel_light.irradiance(sol, scale)
    H = luminance(Hocc_k[on])                                         # (k, T)
    pairs = adjacent_texel_pairs(tm)
    t_lum = luminance(photo)
    ok = (t_lum[pairs[:, 0]] > 0) & (t_lum[pairs[:, 1]] > 0)
    pairs = pairs[ok]
    a, b = pairs[:, 0], pairs[:, 1]
    dlog_t = np.log(t_lum[a]) - np.log(t_lum[b])
    Ha, Hb = H[:, a], H[:, b]
    tiny = 1e-9 * max(float(H.sum(axis=0).max()), 1e-300)

    def objective(x):
        t = np.exp(np.r_[0.0, x])
        ha = np.maximum(t @ Ha, tiny)
        hb = np.maximum(t @ Hb, tiny)
        return float(np.abs(dlog_t - np.log(ha) + np.log(hb)).sum())

    x0 = np.zeros(k - 1)
    res = minimize(objective, x0, method="Nelder-Mead",
                   options={"xatol": 1e-3, "fatol": 1e-6 * objective(x0), "maxiter": 400 * k})
    t = np.exp(np.r_[0.0, res.x])
    t *= k / t.sum()                      # keep the overall scale (fixed later by rho^)
    return scale[on] * t


def nnls_factors(sol, tm, photo, use_patch, current=None):
    """Exitance factors of the scene's lamps that best explain the photo (per-lamp basis)."""
    obs, counts = leaf_means(sol, tm, photo)
    use = use_patch[sol.system.patch] & (counts > 0)
    on = sol.scene.lamp_intensity > 0                # lamps off in the photo cannot be fitted
    basis = sol.basis[:, use]
    if current is not None:                          # basis already scaled by ``current``
        basis = basis / np.where(current > 0, current, 1.0)[:, None, None]
    out = np.zeros(len(on))
    out[on] = fit_lamp_exitance(basis[on], obs[use], sol.system.leaf_area[use]).exitance
    return out


def photo_misfit(sol, tm, photo, use_patch):
    """Relative area-weighted RMS difference between the solution's leaf radiosity and the
    photo's leaf means (luminance, estimated leaves): how well the radiosity model explains
    the photograph (the panel's "model vs photo")."""
    obs, counts = leaf_means(sol, tm, photo)
    use = use_patch[sol.system.patch] & (counts > 0)
    if not use.any():
        return float("nan")
    a = sol.system.leaf_area[use]
    b, o = luminance(sol.radiosity()[use]), luminance(obs[use])
    return float(np.sqrt(a @ (b - o) ** 2) / max(np.sqrt(a @ o ** 2), 1e-300))
