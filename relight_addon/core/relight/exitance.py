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
from types import SimpleNamespace

import numpy as np
from scipy.optimize import nnls

from ..geometry.patch import bilinear_point
from ..numerics import safe_div
from ..progress import tick
from ..radiosity.presets import get_preset
from ..texture.colour import LUMINANCE, luminance
from ..texture.mapping import adjacent_texel_pairs, count_adjacent_texel_pairs
from .albedo import RHO_ESTIMATE_MAX, albedo_rounds
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
    return ExitanceFit(E, float(safe_div(rnorm, np.linalg.norm(b))), bool(rank_deficient))


@dataclass
class LampEstimate:
    """What the precompute uses and what the photo says about each lamp.

    scale (k,): the exitance factors used (photo units per scene unit; the scene's emission is
    the user's light power).  photo_ratio (k,): the shadow-edge fit's relative exitance of each
    lamp on in the photo (geometric mean 1 over them; 1 for a single lamp, nan for lamps off
    in the photo), i.e. the photo's view of each lamp against the user's power;
    uncertainty (k,): its 1-sigma relative uncertainty (jackknife over the photographed
    surfaces; inf when it cannot be told); photo_weight (k,): how much of the photo's ratio
    was used (0: none, 1: in full; photo_weights, photo_factors), ``applied`` whether any.
    equal (k,), nnls (k,): eq 4.2 and NNLS factors, reported."""
    scale: np.ndarray
    photo_ratio: np.ndarray
    uncertainty: np.ndarray
    photo_weight: np.ndarray
    equal: np.ndarray
    nnls: np.ndarray
    method: str
    rho_mean: float = float("nan")     # rho^, the mean reflectance used (fitted or given)
    # rho^'s relative 1-sigma uncertainty (the vote's bootstrap); inf where the photo's shadows
    # do not tell it (fewer than VOTE_MIN_PIECES pieces vote) and rho^ stays the first guess
    rho_sigma: float = float("inf")

    @property
    def applied(self) -> np.ndarray:
        return self.photo_weight > 0


# The photo's ratio replaces the user's (mode "user") only when it is pinned down: its
# uncertainty (the jackknife's, and the preset's exitance_bias grown for a lamp with less than
# an equal share of the direct light, on which the other lamps' model error weighs) below
# PINNED_SIGMA and its distance from 1 above PINNED_Z of it: exact powers stay as set
PINNED_SIGMA = 0.15
PINNED_Z = 2.0
# ... and in full from PINNED_Z + PINNED_RAMP sigma on, in proportion in between: an estimate
# near the edge must not flip the result with the solver's seed
PINNED_RAMP = 0.25
JACKKNIFE_FOLDS = 8
# Rounds of the indirect-light fit (each moves rho^ and solves the albedo again), and the range
# rho^ is kept in.
INDIRECT_ROUNDS = 4
RHO_MEAN_RANGE = (0.05, 0.9)
# How fast log g falls as log rho^ rises (measured on the family's tuning rooms): sizes the
# secant search's first step and turns the vote's uncertainty into rho^'s.
G_PER_RHO = 2.7


def fit_lamps(sol, tm, photo, use_patch, est, opt, texel_light) -> LampEstimate:
    """Exitance factors by ``opt.exitance`` (then per-leaf albedo rounds; the basis is solved
    with them):

    * "user" (default): the lights' powers and colours are what the user set: their ratios are
      kept and only the common scale is fitted (with the reflectances); a lamp's ratio comes
      from the photo only when the shadow-edge fit pins it down (PINNED_SIGMA, PINNED_Z);
    * "photo": the shadow-edge fit's ratios, always;
    * "nnls": non-negative least squares of the per-lamp basis against the photo;
    * "equal": eq 4.2 (every lamp patch the same exitance).

    Only lamps that are on in the photo (``scene.lamp_intensity`` > 0) are fitted; a lamp that
    is off in it takes the geometric mean of their factors (the user's power units)."""
    scene = sol.scene
    k = scene.n_lamps
    on = scene.lamp_intensity > 0
    eq_k = _equal_factors(scene, est, use_patch)
    nnls_k = nnls_factors(sol, tm, photo, use_patch)
    tick(0.1)

    rho_first = sol.system.rho.copy()          # eq 4.1's, at the first guess of rho^

    def rounds(scale, rho_mean):
        # From eq 4.1's reflectances scaled to rho^ each time, so that the result depends on
        # rho^ and not on the rounds that came before.
        scale[~on] = np.exp(np.mean(np.log(np.maximum(scale[on], 1e-300))))
        sol.system.rho = np.clip(rho_first * rho_mean / opt.rho_mean, 0.0, RHO_ESTIMATE_MAX)
        albedo_rounds(sol, tm, photo, use_patch, rho_mean, opt.albedo_rounds, scale)
        return scale

    ratio = np.where(on, 1.0, np.nan)
    sigma = np.where(on, 0.0 if on.sum() == 1 else np.inf, np.nan)
    weight = np.zeros(k)                   # how much of the photo's ratio each lamp takes
    rho_mean, rho_sigma = opt.rho_mean, np.inf
    if opt.exitance == "nnls" and np.any(nnls_k > 0):
        scale = rounds(nnls_k.copy(), rho_mean)
    elif opt.exitance == "equal":
        scale = rounds(eq_k.copy(), rho_mean)
    else:
        scale = rounds(np.ones(k), rho_mean)
        tick(0.3)
        if opt.fit_indirect and tm.n_texels:
            rho_mean, scale, rho_sigma = _fit_rho_mean(sol, tm, photo, scale, texel_light,
                                                       on, rho_mean, rounds)
        tick(0.7)
        fit = edge_fit(sol, tm, photo, scale, texel_light, on, folds=JACKKNIFE_FOLDS,
                       indirect=False)
        if on.sum() >= 2 and tm.n_texels:
            floor = get_preset(opt.preset).exitance_bias
            with np.errstate(divide="ignore"):     # inf for a lamp that lights nothing
                bias = floor / np.minimum(on.sum() * fit.share, 1.0)
            sig = np.hypot(fit.sigma_t, bias)
            ratio[on], sigma[on] = fit.t, sig
            weight[on] = 1.0 if opt.exitance == "photo" else photo_weights(fit.t, sig)
            if np.any(weight > 0):
                tick(0.9)
                scale = rounds(scale * photo_factors(ratio, weight, on), rho_mean)
    return LampEstimate(scale, ratio, sigma, weight, eq_k, nnls_k, opt.exitance, rho_mean,
                        rho_sigma)


def photo_weights(t, sigma):
    """How much of the photo's log ratio ``t`` (uncertainty ``sigma``) replaces the user's in
    mode "user": none below PINNED_Z sigma (or where sigma is PINNED_SIGMA or more), all from
    PINNED_Z + PINNED_RAMP sigma on, in proportion between."""
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.abs(np.log(t)) / sigma
    sure = np.isfinite(z) & (sigma < PINNED_SIGMA)
    return np.where(sure, np.clip((z - PINNED_Z) / PINNED_RAMP, 0.0, 1.0), 0.0)


def photo_factors(ratio, weight, on):
    """Factors on the lamps' exitances that take ``weight`` of the photo's log ratios.  They
    are relative to the lamps that keep the user's ratios (the photo's ratios have their
    geometric mean 1 over every lamp, the kept ones included): against the mean log ratio of
    the lamps on, each weighted by how much of the user's ratio it keeps.  With weights 0 and
    1 that is the kept lamps' mean; a lamp of weight w beside one kept lamp takes
    (t / t_kept) ** (w / (2 - w)) of the photo's ratio between them: continuous in w."""
    with np.errstate(divide="ignore", invalid="ignore"):
        log_t = np.log(np.where(on, ratio, 1.0))
    told = on & np.isfinite(log_t)          # (a lamp the fit cannot tell counts for nothing)
    log_t = np.where(told, log_t, 0.0)
    keep = np.where(told, 1.0 - weight, 0.0)
    base = float(keep @ log_t / keep.sum()) if keep.sum() > 0 else 0.0
    return np.exp(np.where(told, weight, 0.0) * (log_t - base))


def _fit_rho_mean(sol, tm, photo, scale, texel_light, on, rho_mean, rounds):
    """rho^ such that the shadow-edge fit wants no more and no less indirect light (g = 1): a
    secant search on log rho^ against log g, from the first guess, at most INDIRECT_ROUNDS
    fits after the first.  log g falls about 2.7 times as fast as log rho^ rises (measured on
    the family's tuning rooms: G_PER_RHO), which sizes the first step.  Returns (rho^, scale,
    rho^'s relative uncertainty: inf, and rho^ unmoved, where too few pieces vote)."""
    lo, hi = np.log(RHO_MEAN_RANGE[0]), np.log(RHO_MEAN_RANGE[1])
    x = np.log(rho_mean)
    first = edge_fit(sol, tm, photo, scale, texel_light, on)
    f = np.log(first.g)
    if not np.isfinite(first.sigma_vote):
        # too few pieces vote: the photo does not show its shadows' depth
        return rho_mean, scale, np.inf
    rho_sigma = first.sigma_vote / G_PER_RHO
    best = (abs(f), x, scale.copy())
    slope = -G_PER_RHO
    for _ in range(INDIRECT_ROUNDS):
        if abs(f) < 0.01:
            break
        x_new = float(np.clip(x - f / slope, max(lo, x - 0.7), min(hi, x + 0.7)))
        if x_new == x:
            break
        scale = rounds(scale, float(np.exp(x_new)))
        fit = edge_fit(sol, tm, photo, scale, texel_light, on)
        if not np.isfinite(fit.sigma_vote):     # too few pieces vote here: back to the best
            x = x_new
            break
        f_new = np.log(fit.g)
        if f_new != f:
            slope = float(np.clip((f_new - f) / (x_new - x), -20.0, -0.5))
        x, f = x_new, f_new
        if abs(f) < best[0]:
            best = (abs(f), x, scale.copy())
    if best[1] != x:                  # the last step was not the best: go back to it
        scale = rounds(best[2], float(np.exp(best[1])))
        x = best[1]
    return float(np.exp(x)), scale, rho_sigma


def _equal_factors(scene, est, use_patch):
    """Eq 4.2 factors (equal exitance on every lamp patch); 1 for lamps without patches."""
    k = scene.n_lamps
    eq_k = np.ones(k)
    lamp_patch = scene.lamp >= 0
    area = scene.area_normal()[0]
    if est is None or not lamp_patch.any():
        return eq_k
    e_eq = equal_lamp_exitance(est.scene_intensity, est.rho_mean, float(area[use_patch].sum()),
                               float(area[lamp_patch].sum()))
    lum_emission = luminance(scene.emission)
    for j in range(k):
        sel = scene.lamp == j
        if sel.any():
            e_j = float(safe_div((area[sel] * lum_emission[sel]).sum(), area[sel].sum()))
            eq_k[j] = safe_div(e_eq, e_j)
    return eq_k


@dataclass
class EdgeFit:
    """The shadow-edge fit: lamp ratios ``t`` (geometric mean 1 over the lamps on) and the
    weight ``g`` of the indirect light against the direct, with the jackknife standard errors
    of their logarithms (inf when there are too few surfaces to tell; sigma_g is the pooled
    fit's jackknife, sigma_vote the vote's bootstrap: g is the surfaces' vote), and each
    lamp's share of the direct light on the photographed texels."""
    t: np.ndarray
    g: float
    sigma_t: np.ndarray
    sigma_g: float
    share: np.ndarray
    sigma_vote: float = np.inf      # the vote's (g's) standard error in log, bootstrap


def edge_fit(sol, tm, photo, scale, texel_light, on, folds=0, indirect=True) -> EdgeFit:
    """Relative lamp exitances, and the weight of the indirect light, that make the reflectance
    photo / irradiance smoothest.

    Reflectance does not know where shadows fall: with the right exitance ratios the photo's
    shadow edges are explained by the irradiance and vanish from photo / H.  The same holds for
    the share of indirect light: in a shadow only the indirect light is left, so the depth of
    the photo's shadows tells how strong it is against the direct light (the one thing a
    photo says about the absolute level of the reflectances).  Minimises the total variation
    of log(photo / sum_k t_k (D_k + g I_k)) over neighbouring texels (robust to genuine texture
    edges, which add a constant) over the k - 1 free ratios and log g; D_k the direct
    irradiance per texel (ray cast), I_k the indirect one (from the solution), at the factors
    ``scale``.  Only the lamps ``on`` in the photo take part.  The jackknife runs over
    ``folds`` groups of photographed surfaces."""
    k = int(np.sum(on))
    n_free = (k - 1) + (1 if indirect else 0)
    if n_free == 0 or tm.n_texels == 0:
        return EdgeFit(np.ones(k), 1.0, np.zeros(k), 0.0, np.full(k, 1.0 / max(k, 1)))
    # ``tm`` is the solution's (texel_light.solution_texels: on a proxy, its patches)
    pairs, dlog_t = edge_pairs(tm, photo)
    if texel_light.keeps_direct:
        light, (a, b) = texel_light, pairs.T
        (D, _), (I, _) = light.parts(sol, scale, unoccluded=False)
        D, I = luminance(D[on]), luminance(I[on])                      # (k, T)
    else:          # photo-resolution textures: the light of the sampled pairs' texels only
        rows, inv = np.unique(pairs, return_inverse=True)
        light, (a, b) = texel_light.subset(rows), inv.reshape(-1, 2).T
        D, I = light.occluded_luminance(sol, scale)
        D, I = D[on], I[on]
    share = safe_div(D.sum(axis=1), float(D.sum()))
    Da, Db, Ia, Ib = D[:, a], D[:, b], I[:, a], I[:, b]
    tiny = 1e-9 * max(float((D + I).sum(axis=0).max()), 1e-300)

    def unpack(x):
        x = np.clip(x, -20.0, 20.0)          # a lamp the photo does not see drifts away
        lt = np.r_[0.0, x[:k - 1]]
        return np.exp(lt - lt.mean()), (float(np.exp(x[k - 1])) if indirect else 1.0)

    def variation(t, g, da, db, ia, ib, dl):
        ha = np.maximum(t @ da + g * (t @ ia), tiny)
        hb = np.maximum(t @ db + g * (t @ ib), tiny)
        return float(np.abs(dl - np.log(ha) + np.log(hb)).sum())

    def solve(left_out):
        """The fit on every pair but ``left_out`` (a mask, or None): the sum over all pairs
        minus the one over the left-out ones, whose arrays are copied once (a fold is a small
        part; copying the rest at each of the optimiser's calls made each call 4x slower, with
        twice the peak memory, on family room 5)."""
        from scipy.optimize import minimize
        out = None if left_out is None else \
            (Da[:, left_out], Db[:, left_out], Ia[:, left_out], Ib[:, left_out],
             dlog_t[left_out])

        def objective(x):
            t, g = unpack(x)
            total = variation(t, g, Da, Db, Ia, Ib, dlog_t)
            return total if out is None else total - variation(t, g, *out)
        x0 = np.zeros(n_free)
        # An explicit simplex of +-0.1 in the logs: scipy's default around 0 is 2.5e-4 wide,
        # below xatol, and would stop where it started.
        simplex = np.vstack([x0, x0 + 0.1 * np.eye(n_free)])
        res = minimize(objective, x0, method="Nelder-Mead",
                       options={"xatol": 1e-3, "fatol": 1e-6 * max(objective(x0), 1e-300),
                                "maxiter": 400 * (n_free + 1), "initial_simplex": simplex})
        t, g = unpack(res.x)
        return np.r_[np.log(t), np.log(g)]

    full = solve(None)
    t, g = np.exp(full[:k]), float(np.exp(full[k]))
    sigma_vote = np.inf
    if indirect:          # the surfaces' vote at the current ratios (VOTE_*), not the pooled fit
        D_sum, I_sum, stm = D.sum(axis=0), I.sum(axis=0), light.solution_texels
        per_patch = np.bincount(tm.patch)
        g, sigma_vote = _vote_g(D_sum, I_sum, dlog_t, stm, a, b, per_patch, fallback=g)
        if not np.isfinite(sigma_vote):
            # pieces too small to vote (a fine proxy's triangles): cells of space vote, not
            # whole surfaces, where one region's contact shadows would decide
            cells = SimpleNamespace(patch=np.zeros(len(stm.patch), np.int64), u=stm.u, v=stm.v)
            cells.patch[a] = _space_cells(sol.scene, stm, a, per_patch)
            g, sigma_vote = _vote_g(D_sum, I_sum, dlog_t, cells, a, b,
                                    np.ones(int(cells.patch.max(initial=0)) + 1), fallback=g)
        if not np.isfinite(sigma_vote):
            # too few cells either: whole surfaces (groups) vote, rather than rho^ staying
            group = np.asarray(sol.scene.group)
            by_group = SimpleNamespace(patch=group[stm.patch], u=stm.u, v=stm.v)
            g, sigma_vote = _vote_g(D_sum, I_sum, dlog_t, by_group, a, b,
                                    np.ones(int(group.max(initial=0)) + 1), fallback=g)
    if folds <= 1:
        return EdgeFit(t, g, np.zeros(k), 0.0, share, sigma_vote)
    # Jackknife over groups of surfaces (patch groups, dealt into folds by texel count): a
    # value that only some surfaces support is not pinned down.
    group = np.asarray(sol.scene.group)[light.solution_texels.patch[a]]
    ids, counts = np.unique(group, return_counts=True)
    if len(ids) < 3:
        return EdgeFit(t, g, np.full(k, np.inf), np.inf, share, sigma_vote)
    fold_of = np.zeros(int(ids.max()) + 1, np.int64)
    load = np.zeros(min(folds, len(ids)))
    for gid, c in sorted(zip(ids, counts), key=lambda x: -x[1]):
        f = int(np.argmin(load))
        fold_of[gid] = f
        load[f] += c
    fold = fold_of[group]
    n = len(load)
    loo = np.array([solve(fold == f) for f in range(n)])
    sigma = np.sqrt((n - 1) / n * ((loo - loo.mean(axis=0)) ** 2).sum(axis=0))
    return EdgeFit(t, g, sigma[:k], float(sigma[k]), share, sigma_vote)


# The indirect weight g is voted on by pieces of surface (a patch, or a cell of it: large
# patches are cut into up to VOTE_CELLS^2 cells of their own parameters), at the lamp ratios
# given: each piece whose total variation has a minimum in g votes for it, with the weight of
# how sharply it pins g (the second difference over +-VOTE_STEP grid steps) capped at the median
# piece's, and the weighted median wins: a pooled fit lets the steepest region decide.
# The shadow-edge fit reads at most this many neighbouring texel pairs (its time grows with them)
EDGE_PAIRS = 1_000_000
PAIRS_WHOLE = 8_000_000          # more pairs than this (~4 M texels) are not listed whole
VOTE_CELLS = 4
VOTE_CELL_TEXELS = 32
VOTE_STEP = 2                                 # grid steps (0.25 in log g)
VOTE_MIN_PAIRS = 200
VOTE_GRID = np.linspace(-2.0, 2.0, 33)       # log g
VOTE_PAIRS = 300_000                          # pairs sampled for the vote (seeded)
CELLS_CHUNK = 1 << 16                         # pairs placed in space cells at once
VOTE_MIN_PIECES = 5
VOTE_MIN_COVER = 0.5       # of the pairs, in pieces large enough to vote
VOTE_BOOTSTRAP = 400


def edge_pairs(tm, photo):
    """The neighbouring texel pairs (n, 2) the shadow-edge fit reads, both lit in the photo (at
    most EDGE_PAIRS of them, a seeded sample), and the photo's log luminance difference over
    each.  A map of more than PAIRS_WHOLE pairs is thinned image by image as they are listed."""
    total = count_adjacent_texel_pairs(tm)
    fraction = 1.0 if total <= PAIRS_WHOLE else min(1.0, 1.5 * EDGE_PAIRS / total)
    pairs = adjacent_texel_pairs(tm, fraction, seed=11)
    if fraction < 1.0:       # the photo's luminance at the listed texels only
        lum = luminance(photo[pairs])
    else:
        t_lum = luminance(photo)
        lum = np.stack([t_lum[pairs[:, 0]], t_lum[pairs[:, 1]]], axis=1)
    ok = (lum[:, 0] > 0) & (lum[:, 1] > 0)
    pairs, lum = pairs[ok], lum[ok]
    if len(pairs) > EDGE_PAIRS:          # photo-resolution textures: a seeded sample of pairs
        pick = np.sort(np.random.default_rng(11).choice(len(pairs), EDGE_PAIRS, replace=False))
        pairs, lum = pairs[pick], lum[pick]
    return pairs, np.log(lum[:, 0]) - np.log(lum[:, 1])


def _vote_g(D, I, dlog_t, tm, a, b, per_patch, fallback=1.0):
    """The voted indirect weight (``fallback`` where no piece votes) and the standard error of
    its logarithm (bootstrap over the pieces, at least half a grid step; inf with fewer than
    VOTE_MIN_PIECES voting pieces) over the pairs of texels
    (a, b) of ``tm``.  D, I (T,): direct and indirect irradiance at the current ratios; dlog_t:
    the photo's log difference over each pair; ``per_patch``: each patch's texels in the whole
    map (``tm`` may be a sample of it)."""
    # a patch of n texels is cut into c x c cells of about VOTE_CELL_TEXELS^2 (c <= VOTE_CELLS)
    cells = np.clip(np.sqrt(per_patch) // VOTE_CELL_TEXELS, 1, VOTE_CELLS).astype(np.int64)
    c = cells[tm.patch[a]]
    cell = (np.minimum((tm.u[a] * c).astype(np.int64), c - 1) * VOTE_CELLS
            + np.minimum((tm.v[a] * c).astype(np.int64), c - 1))
    piece = np.unique(tm.patch[a] * VOTE_CELLS ** 2 + cell, return_inverse=True)[1].ravel()
    n = len(a)
    sel = np.arange(n) if n <= VOTE_PAIRS else \
        np.sort(np.random.default_rng(7).choice(n, VOTE_PAIRS, replace=False))
    pc = piece[sel]
    counts = np.bincount(pc, minlength=int(piece.max(initial=-1)) + 1)
    da, db, ia, ib = D[a[sel]], D[b[sel]], I[a[sel]], I[b[sel]]
    dl = dlog_t[sel]
    # the grid, VOTE_STEP points wider on each side for the second difference at its ends
    m = len(VOTE_GRID)
    h = VOTE_GRID[1] - VOTE_GRID[0]
    grid = VOTE_GRID[0] + h * np.arange(-VOTE_STEP, m + VOTE_STEP)
    f = np.empty((len(grid), len(counts)))
    for j, lg in enumerate(grid):
        w = np.exp(lg)
        r = np.abs(dl - np.log(np.maximum(da + w * ia, 1e-300))
                   + np.log(np.maximum(db + w * ib, 1e-300)))
        f[j] = np.bincount(pc, weights=r, minlength=len(counts))
    centre, up, down = f[VOTE_STEP:VOTE_STEP + m], f[2 * VOTE_STEP:], f[:m]
    best = np.argmin(centre, axis=0)
    cols = np.arange(len(counts))
    info = np.maximum(up[best, cols] + down[best, cols] - 2.0 * centre[best, cols], 0.0)
    # a minimum at the grid's edge is no minimum: the piece cannot tell
    voting = (counts >= VOTE_MIN_PAIRS) & (best > 0) & (best < m - 1) & (info > 0)
    if not voting.any():
        return fallback, np.inf
    if counts[counts >= VOTE_MIN_PAIRS].sum() < VOTE_MIN_COVER * len(pc):
        # most pairs lie in pieces too small to vote: the few large ones are no sample of the
        # scene (a scan's proxy of 3,000 triangles: 2-3 % of its pairs; 99 % on the family's
        # clean rooms)
        return fallback, np.inf
    # Each piece's minimum between grid points (the parabola through its neighbours), and the
    # median interpolated between the votes: on the grid alone the vote jumped a whole step
    # (12 % in g, 12 % in the lamps' scale through rho^) with the solver's random seed.
    lg = VOTE_GRID[best] + h * _parabola_vertex(f[VOTE_STEP - 1:VOTE_STEP + m - 1][best, cols],
                                                centre[best, cols],
                                                f[VOTE_STEP + 1:VOTE_STEP + m + 1][best, cols])
    # no piece weighs more than the typical one: the steepest pieces are where the model is
    # most often wrong (contact shadows), and would decide alone
    w = np.minimum(info[voting], np.median(info[voting]))
    order = np.argsort(lg[voting])
    votes, w = lg[voting][order], w[order]
    g = float(np.exp(_weighted_median(votes, w)))
    if len(votes) < VOTE_MIN_PIECES:
        return g, np.inf
    # how sure: the spread of the weighted median when the pieces are drawn again (seeded)
    draws = np.random.default_rng(5).multinomial(len(votes), np.full(len(votes), 1 / len(votes)),
                                                  size=VOTE_BOOTSTRAP) * w
    medians = _weighted_median(votes, draws)
    return g, max(float(medians.std()), 0.5 * h)      # no surer than half the grid's step


def _space_cells(scene, tm, rows, per_patch):
    """Cells of space for the texels ``rows`` of ``tm`` (patches of ``scene``, ``per_patch``
    texels each in the whole map): the same group, facing along the same axis, in the same
    cube of VOTE_CELL_TEXELS texels a side (each patch's texel spacing, the median over them).
    Pieces whose size does not follow the tessellation."""
    if len(rows) == 0:
        return np.zeros(0, np.int64)
    area, normal = scene.area_normal()
    patch = tm.patch[rows]
    spacing = np.sqrt(area[patch] / np.maximum(per_patch[patch], 1))
    size = VOTE_CELL_TEXELS * max(float(np.median(spacing)), 1e-12)
    n = normal[patch]
    axis = np.argmax(np.abs(n), axis=1)
    facing = 2 * axis + (n[np.arange(len(n)), axis] > 0)
    u, v = tm.u[rows], tm.v[rows]
    cell = np.empty((len(rows), 3), np.int64)
    for c0 in range(0, len(rows), CELLS_CHUNK):    # (n, 4, 3) corners for a million pairs: 96 MB
        sl = slice(c0, c0 + CELLS_CHUNK)
        cell[sl] = np.floor(bilinear_point(scene.corners[patch[sl]], u[sl], v[sl]) / size)
    columns = [np.asarray(scene.group)[patch], facing, cell[:, 0], cell[:, 1], cell[:, 2]]
    return _row_labels(columns)


def _row_labels(columns):
    """np.unique(np.column_stack(columns), axis=0, return_inverse=True)[1] a column at a time:
    the same labels (rows in lexicographic order) without the (n, c) sorting copies (107 MB
    for a photo-resolution map's million pairs)."""
    label = np.zeros(len(columns[0]), np.int64)
    for col in columns:
        rank = np.unique(col, return_inverse=True)[1].ravel()
        label = np.unique(label * (int(rank.max(initial=0)) + 1) + rank,
                          return_inverse=True)[1].ravel()
    return label


def _parabola_vertex(left, mid, right):
    """Offset (in grid steps, within +-0.5) of the minimum of the parabola through three
    equally spaced values whose middle one is the least."""
    curv = left - 2.0 * mid + right
    return np.clip(0.5 * (left - right) / np.where(curv > 0, curv, np.inf), -0.5, 0.5)


def _weighted_median(values, weights):
    """Weighted median of sorted ``values``, interpolated between them (each value stands
    at the middle of its weight), so that it moves smoothly with the values and weights; a
    large majority still leans a little towards its neighbour (values 0, 1 weighted 10, 1:
    0.09, not 0).  ``weights`` (n,) or (draws, n) for one median per row, each with some
    weight."""
    w = np.atleast_2d(np.asarray(weights, float))
    cum = np.cumsum(w, axis=1)
    at = safe_div(cum - 0.5 * w, cum[:, -1:])
    out = np.array([np.interp(0.5, a[wr > 0], values[wr > 0]) if np.any(wr > 0) else values[0]
                    for a, wr in zip(at, w)])
    return out if np.ndim(weights) == 2 else float(out[0])


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
    return float(safe_div(np.sqrt(a @ (b - o) ** 2), np.sqrt(a @ o ** 2)))
