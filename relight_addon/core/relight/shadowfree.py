"""Shadow-free textures (seed 000 §4.2-4.3): the whole precompute on a SceneData, bpy-free.

Input: a SceneData whose patches carry the photographs (``images[i].texels`` linear RGB, UVs)
and the real lamps (emission in Blender units; only their ratios and geometry are trusted).
Output (:class:`ShadowFreeResult`): per image the texture ``T_final`` and one display map
``M_k`` per lamp, so that the relit texture is ``T_final x sum_k I_k M_k`` (``I_k`` = lamp
intensity relative to the photo).

Pipeline (``mode="element"``, the seed's method)
1. Initialisation (§4.2.1): reflectance per patch by eq 4.1 (re-estimated mean), a first
   hierarchical BFV solution, lamp exitances by eq 4.2 (equal lamps) and by non-negative least
   squares of the per-lamp basis against the photo (beyond the seed; used by default, both are
   reported).  Beyond the seed, the reflectance of every leaf is then re-estimated as
   photo / irradiance (eq 4.1 assumes uniform lighting), rescaled to the mean reflectance rho^
   (the absolute scale of reflectance is not observable from a photo), a few times with the
   exitance fit.
2. Texture-based refinement (§4.3.1, fig 4.7): neighbouring leaves (texel-adjacent, so also
   across patch edges that are continuous in UV) are compared by colour (CIE LAB distance of
   their photo means, eq 4.4) and by visibility of each lamp (type and attenuation); a leaf
   that disagrees with a neighbour, or sees a lamp partially, is a candidate.  Instead of
   splitting and undoing, each candidate's four children are probed first (visibility of every
   lamp at their centres) and the split is made only where they differ: the same result as
   "undo a subdivision whose children show no visibility change", without the round trip.
   Splits stop at the preset's minimum element size and at about one texel.  The leaf gather
   is then recomputed (every light-source link at the leaves) and B_orig, D_orig updated.
3. First modification (§4.3.2): blocked irradiance E-bar (eq 4.5) = unoccluded minus occluded
   gather of the solution, over lamps and secondary sources; T_inter = T x (E + E-bar) / E
   (eq 4.6, rho cancels), with E and E + E-bar interpolated at element vertices.
4. Second modification (fig 4.11): shadowed leaves (a significant lamp not fully visible),
   frontier leaves (every significant lamp fully visible, a shadowed neighbour, seen by the
   camera), a reference per shadowed leaf = the nearest frontier leaf of the same object whose
   reflectance is within ``reference_eps`` in LAB; rho_corr (eq 4.8) and T_final (eq 4.9).
   Reflectances here are physical (photo / irradiance), so the seed's form-factor ratio of
   eq 4.8 is already inside them: rho_corr_i = rho_r.
5. Fresh solution (§4.3.3): a new BFV solution on T_final (new mesh and links, the same
   texture-based refinement), B with visibility, then D = rho (E + E-bar) from the unoccluded
   gather of that B (the seed's two passes); M_k = B_k / D per texel with rho cancelled per
   leaf, i.e. (occluded irradiance from lamp k) / (unoccluded irradiance), vertex-interpolated.

``mode="texel"`` (the seed's conclusion asks for it): after step 1, the direct part of both
irradiances is computed at every texel by ray casting to each lamp (``texel_rays`` rays per lamp
patch), the indirect part interpolated from the solution; T_final = T x H_unocc / H_occ and
M_k = H_occ,k / H_unocc per texel.  No reference step is needed and the original lighting is
reproduced by construction.

``mode="none"``: the DRB97 baseline (no texture correction): T = photo, M_k = B_k / sum B.

Floors (no NaN or Inf ever reaches a texture; textures stay linear and unclamped above 1):
* the shadow-removal factor (E + E-bar) / E is clipped to [1, FACTOR_MAX] (removing occlusion
  never darkens; a texel in full shadow of every lamp has nothing to recover), rho_corr /
  rho_inter to [1 / FACTOR_MAX, FACTOR_MAX];
* in texel mode D = H_occ x the clipped factor, so T_final x sum_k M_k is the photo exactly;
* M_k = 0 where the unoccluded irradiance is below DISPLAY_EPS x its maximum (unlit texels).
"""
from __future__ import annotations

import copy
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from ..radiosity.links import INVISIBLE, PARTIAL, VISIBLE
from ..radiosity.precompute import regather, solve_basis, solve_radiosity
from ..radiosity.presets import get_preset
from ..radiosity.solver import LeafSystem
from ..scene import SceneData, bilinear_point
from ..texture.colour import lab_distance, linear_rgb_to_lab
from ..texture.mapping import (TexelMap, dilate_seams, element_means, rasterize_patches,
                               texel_elements, vertex_interpolate)
from .direct import lamp_irradiance
from .estimate import LUMINANCE, RHO_MAX, equal_lamp_exitance, estimate_reflectance, fit_lamp_exitance

FACTOR_MAX = 64.0
DISPLAY_EPS = 1e-6
# A lamp whose unoccluded share of a leaf's irradiance is below this does not make it
# "shadowed" (or "lit") for the frontier / reference step.
SIGNIFICANT_SHARE = 0.05
# Attenuation above 1 - VIS_TOL counts as fully visible, below VIS_TOL as invisible.
VIS_TOL = 0.02
SEAM_PIXELS = 4
TEXEL_CHUNK = 1 << 15     # texels whose direct light is computed at once (texel mode)


@dataclass
class ShadowFreeOptions:
    mode: str = "element"               # "element" | "texel" | "none" (DRB97)
    preset: str = "medium"
    exitance: str = "edges"             # "edges" | "nnls" | "equal" (eq 4.2)
    rho_mean: float = 0.5               # rho^, the user's mean reflectance (eq 4.1)
    albedo_rounds: int = 3              # photo / irradiance re-estimation rounds
    refine: bool = True                 # texture-based refinement (fig 4.7)
    colour_threshold: float = 8.0       # LAB distance (eq 4.4) between neighbours
    attenuation_threshold: float = 0.15  # visibility difference that counts as a change
    refine_rounds: int = 4
    refine_min_area: float = 1 / 16     # smallest element, relative to the preset's minimum
    probe_rays: int = 16
    # Second modification (fig 4.11).  Off by default: on textured surfaces the reference's
    # mean reflectance is not the shadowed element's, and the error in the former shadows grows
    # (benchmarks/results/shadowfree.md: 1.8 -> 4.3 CIEDE2000 on the office, medium).
    reference: bool = False
    reference_eps: float = 12.0         # LAB distance for a reference element
    default_reference: object = "auto"  # "auto" | None | element id (first solution's ids)
    texel_rays: int = 32
    texel_samples: int = 2              # texel footprint sampled on an s x s grid
    seed: int = 0


@dataclass
class ShadowFreeResult:
    options: ShadowFreeOptions
    texel_map: TexelMap
    texture: dict                 # image index -> (H, W, 3) float32 T_final (dilated)
    maps: dict                    # image index -> (k, H, W, 3) float32 M_k (dilated)
    coverage: dict                # image index -> (H, W) bool
    exitance_scale: np.ndarray    # (k,) factor on each lamp's scene exitance (photo units)
    exitance_equal: np.ndarray    # (k,) eq 4.2 factors, for the report
    exitance_nnls: np.ndarray     # (k,) NNLS factors, for the report
    solution: object              # the solution the maps come from
    first_solution: object | None = None
    stats: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)
    reference_info: dict | None = None   # frontier / reference codes per first-solution leaf

    def relit(self, intensities=None) -> dict:
        """T_final x sum_k I_k M_k per image (covered texels meaningful)."""
        out = {}
        for i, tex in self.texture.items():
            m = self.maps[i]
            I = np.ones(len(m)) if intensities is None else np.asarray(intensities, float)
            out[i] = (tex * np.tensordot(I.astype(np.float32), m, axes=1)).astype(np.float32)
        return out


# -- helpers --------------------------------------------------------------------------------------

def _texels(img):
    return np.asarray(getattr(img, "texels", img), np.float32)[..., :3]


def _lum(x):
    return np.asarray(x) @ LUMINANCE


class _Transport:
    """Leaf irradiances of a solution, unoccluded (F) and occluded (F V), all sources and lamps only."""

    def __init__(self, sol):
        h, g = sol.hierarchy, sol.gather
        rho = sol.scene.rho
        self.occ = sol.system
        self.unocc = LeafSystem(h, g.leaf, g.source, g.F, rho)
        self.unocc.U, self.unocc.W = sol.system.U, sol.system.W
        lamp_src = sol.scene.lamp[h.patch[g.source]] >= 0
        self.dir_occ = LeafSystem(h, g.leaf[lamp_src], g.source[lamp_src], g.FV[lamp_src], rho)
        self.dir_unocc = LeafSystem(h, g.leaf[lamp_src], g.source[lamp_src], g.F[lamp_src], rho)

    @staticmethod
    def _per_lamp(system, basis):
        k, L, _ = basis.shape
        flat = np.moveaxis(basis, 0, 2).reshape(L, 3 * k)
        return np.moveaxis(system.gather(flat).reshape(L, 3, k), 2, 0)   # (k, L, 3)

    def irradiance(self, basis):
        """Per lamp (k, L, 3): occluded, unoccluded, direct occluded, direct unoccluded."""
        return (self._per_lamp(self.occ, basis), self._per_lamp(self.unocc, basis),
                self._per_lamp(self.dir_occ, basis), self._per_lamp(self.dir_unocc, basis))


def _ratio(num, den, fmax=FACTOR_MAX, fmin=None):
    """num / den clipped to [fmin (default 1/fmax), fmax]; 1 where both vanish."""
    num = np.maximum(np.asarray(num, float), 0.0)
    den = np.maximum(np.asarray(den, float), 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(den > 0, num / np.where(den > 0, den, 1.0), np.where(num > 0, fmax, 1.0))
    return np.clip(np.nan_to_num(r, nan=1.0, posinf=fmax), 1.0 / fmax if fmin is None else fmin,
                   fmax)


def _leaf_texel_means(sol, tm, values):
    """Mean of ``values`` (T, 3) per element (pulled up / pushed down the tree) and per leaf."""
    h = sol.hierarchy
    elem = texel_elements(h, tm)
    means, counts = element_means(values, elem, h.n, hierarchy=h)
    return means, counts, elem


def _neighbour_pairs(tm, elem):
    """Unique pairs of distinct leaves owning 4-adjacent texels of the same image."""
    p = _texel_pairs(tm)
    a, b = elem[p[:, 0]], elem[p[:, 1]]
    ok = a != b
    if not ok.any():
        return np.zeros((0, 2), np.int64)
    return np.unique(np.stack([np.minimum(a[ok], b[ok]), np.maximum(a[ok], b[ok])], 1), axis=0)


def _patch_means(tm, values, n_patches):
    """Mean texel value (p, 3) and texel count (p,) of every patch."""
    cnt = np.bincount(tm.patch, minlength=n_patches)
    means = np.stack([np.bincount(tm.patch, values[:, c], n_patches) for c in range(3)], axis=1)
    return means / np.maximum(cnt, 1)[:, None], cnt


def _lab_of(values, white):
    return linear_rgb_to_lab(np.clip(np.nan_to_num(values) / max(white, 1e-300), 0.0, None))


def _scene_with_rho(scene: SceneData, rho_patch) -> SceneData:
    """A shallow copy of ``scene`` with other patch reflectances (already cleaned: no re-split)."""
    new = object.__new__(SceneData)
    new.__dict__.update(scene.__dict__)
    new.rho = np.clip(np.asarray(rho_patch, float), 0.0, RHO_MAX)
    return new


def _visibility(att):
    return np.where(att >= 1 - VIS_TOL, VISIBLE, np.where(att <= VIS_TOL, INVISIBLE, PARTIAL))


# -- the pipeline ---------------------------------------------------------------------------------

class _Stage:
    def __init__(self, progress, timings):
        self.progress, self.timings, self.t0, self.name = progress, timings, None, None

    def __call__(self, frac, name):
        now = time.perf_counter()
        if self.name is not None:
            self.timings[self.name] = self.timings.get(self.name, 0.0) + now - self.t0
        self.name, self.t0 = name, now
        if self.progress is not None and name is not None:
            if self.progress(frac, name) is False:
                from ..radiosity.precompute import Cancelled
                raise Cancelled(name)


def shadow_free(scene: SceneData, options: ShadowFreeOptions | None = None, occluder="auto",
                progress=None, reuse=None) -> ShadowFreeResult:
    """Shadow-free texture T_final and per-lamp display maps M_k (see the module docstring).

    ``reuse``: the first solution of an earlier run on the same geometry, lamps and preset
    (``result.solution`` of a "texel" or "none" run): its mesh, links and form factors are kept
    and only the reflectances, exitances and maps are estimated again (photos edited)."""
    opt = options or ShadowFreeOptions()
    cache = {}              # direct light per texel, cast once (see _texel_direct)
    if opt.mode not in ("element", "texel", "none"):
        raise ValueError(f"unknown mode {opt.mode!r}")
    if scene.n_lamps == 0:
        raise ValueError("The scene has no lamps: nothing to relight")
    timings = {}
    stage = _Stage(progress, timings)
    if occluder == "auto":
        from ..geometry.raycast import make_occluder
        tris = scene.occluder_triangles()
        occluder = make_occluder(tris) if len(tris) else None

    stage(0.0, "Reading textures")
    shapes = [_texels(im).shape[:2] for im in scene.images]
    image_of = scene.image if scene.image is not None else np.full(scene.n_patches, -1)
    uv = scene.uv if scene.uv is not None else np.zeros((scene.n_patches, 4, 2))
    tm = rasterize_patches(uv, image_of, shapes)
    photo = tm.gather([_texels(im) for im in scene.images]).astype(np.float64)
    textured = image_of >= 0
    white = float(np.percentile(_lum(photo), 99)) if len(photo) else 1.0

    # 1. Initialisation: eq 4.1 per patch, first solution, exitances, per-leaf albedo.
    stage(0.02, "Estimating reflectances (eq 4.1)")
    patch_mean, cnt = _patch_means(tm, photo, scene.n_patches)
    textured &= cnt > 0
    lamp_patch = scene.lamp >= 0
    est_ids = np.flatnonzero(textured & ~lamp_patch)
    rho_patch = scene.rho.copy()
    area = scene.area_normal()[0]
    est = None
    if len(est_ids):
        est = estimate_reflectance(patch_mean[est_ids], area[est_ids], opt.rho_mean)
        rho_patch[est_ids] = est.rho
    scene1 = _scene_with_rho(scene, rho_patch)

    def sub_progress(lo, hi):
        if progress is None:
            return None
        return lambda f, msg: progress(lo + (hi - lo) * f, msg)

    if reuse is not None and opt.mode != "element":
        stage(0.05, "Reusing the radiosity mesh and links")
        sol = copy.copy(reuse)                 # the caller's solution stays as it was
        sol.system = copy.copy(reuse.system)
        sol.scene = scene1
        solve_basis(sol, scene1.rho[sol.system.patch])    # scene exitances, eq 4.1 reflectances
    else:
        stage(0.05, "First radiosity solution")
        sol = solve_radiosity(scene1, opt.preset, occluder=occluder, seed=opt.seed,
                              progress=sub_progress(0.05, 0.4))
    stage(0.4, "Lamp exitances and reflectances")
    fit = _fit_lamps(sol, tm, photo, textured, lamp_patch, est, opt, occluder, cache)
    scale_k, eq_k, nnls_k = fit
    misfit = photo_misfit(sol, tm, photo, textured)

    if opt.mode == "none":
        stage(0.9, "Display maps")
        result_tex, result_maps, cov = _drb97_maps(sol, tm, photo, scene)
        stage(1.0, None)
        return ShadowFreeResult(opt, tm, result_tex, result_maps, cov, scale_k, eq_k, nnls_k, sol,
                                None, {**_stats(sol, None), "photo_misfit": misfit}, timings)

    if opt.mode == "element" and opt.refine:
        stage(0.45, "Texture-based refinement")
        _refine_by_texture(sol, tm, photo, white, occluder, opt, scale_k)
        regather(sol, opt.seed + 1)
        _albedo_rounds(sol, tm, photo, textured, lamp_patch, opt, scale_k)

    if opt.mode == "texel":
        stage(0.6, "Per-texel irradiance")
        Hocc_k, HU_k = _texel_irradiance(sol, tm, scene, occluder, opt, scale_k, cache)
        Hocc = Hocc_k.sum(axis=0)
        # Removing occlusion never darkens (E-bar >= 0; sampling noise could say otherwise).
        factor = _ratio(HU_k.sum(axis=0), Hocc, fmin=1.0)
        t_final = photo * factor
        # D = H_occ x the clipped factor (= H_unocc unless clipped), so that T_final x sum M_k
        # gives the photo back exactly even where the factor hit its ceiling.
        maps = _maps_from(Hocc_k, Hocc * factor)
        stage(0.95, "Writing maps")
        tex, mp, cov = _to_images(tm, t_final, maps, scene)
        stage(1.0, None)
        stats = {**_stats(sol, None), "photo_misfit": misfit}
        return ShadowFreeResult(opt, tm, tex, mp, cov, scale_k, eq_k, nnls_k, sol, None, stats,
                                timings)

    # 3. First modification (eq 4.5, 4.6).
    stage(0.6, "Blocked irradiance and T_inter (eq 4.5, 4.6)")
    tr = _Transport(sol)
    Hocc_k, HU_k, Docc_k, DU_k = tr.irradiance(sol.basis)
    elem = texel_elements(sol.hierarchy, tm)

    def per_texel(leaf_vals):          # smooth per-texel values of the current solution
        return vertex_interpolate(sol.hierarchy, leaf_vals, tm, elem)

    HU_t = per_texel(HU_k.sum(0))
    Hocc_t = per_texel(Hocc_k.sum(0))
    t_inter = photo * _ratio(HU_t, Hocc_t, fmin=1.0)

    # 4. Second modification: frontier, references, rho_corr, T_final (eq 4.8, 4.9).
    stage(0.7, "Frontier and reference elements (eq 4.8, 4.9)")
    n_shadowed = n_ref = n_default = n_frontier = 0
    t_final = t_inter
    reference_info = None
    if opt.reference:
        corr, info, codes = _reference_correction(sol, tm, elem, t_inter, HU_k.sum(0), Docc_k,
                                                  DU_k, occluder, opt)
        n_shadowed, n_frontier, n_ref, n_default = info
        reference_info = {"hierarchy": sol.hierarchy, "leaves": sol.leaves.copy(), "codes": codes}
        t_final = t_inter * per_texel(corr)

    # 5. Fresh solution on T_final: B with visibility, D from its unoccluded gather.
    stage(0.75, "Fresh solution on T_final")
    first = sol
    pm, _ = _patch_means(tm, t_final, scene.n_patches)
    rho2 = scene.rho.copy()
    if len(est_ids):
        rho2[est_ids] = estimate_reflectance(pm[est_ids], area[est_ids], opt.rho_mean).rho
    sol = solve_radiosity(_scene_with_rho(scene, rho2), opt.preset, occluder=occluder,
                          seed=opt.seed + 2, progress=sub_progress(0.75, 0.9))
    if opt.refine:
        _refine_by_texture(sol, tm, t_final, white, occluder, opt, scale_k, colour=False)
        regather(sol, opt.seed + 3)
    _albedo_rounds(sol, tm, t_final, textured, lamp_patch, opt, scale_k, unoccluded=True)
    stage(0.92, "Display maps")
    tr = _Transport(sol)
    Hocc_k, HU_k, _, _ = tr.irradiance(sol.basis)
    elem = texel_elements(sol.hierarchy, tm)
    Hocc_kt = np.stack([per_texel(x) for x in Hocc_k])
    maps = _maps_from(Hocc_kt, per_texel(HU_k.sum(0)))
    tex, mp, cov = _to_images(tm, t_final, maps, scene)
    stage(1.0, None)
    stats = _stats(sol, first)
    stats.update(shadowed_leaves=n_shadowed, frontier_leaves=n_frontier, referenced=n_ref,
                 default_reference=n_default, photo_misfit=misfit)
    return ShadowFreeResult(opt, tm, tex, mp, cov, scale_k, eq_k, nnls_k, sol, first, stats,
                            timings, reference_info)


def photo_misfit(sol, tm, photo, textured):
    """Relative area-weighted RMS difference between the solution's leaf radiosity and the
    photo's leaf means (luminance, textured non-lamp leaves): how well the radiosity model
    explains the photograph (the panel's "estimated error")."""
    obs, counts = _leaf_photo(sol, tm, photo)
    patch = sol.system.patch
    use = textured[patch] & (sol.scene.lamp[patch] < 0) & (counts > 0)
    if not use.any():
        return float("nan")
    a = sol.system.leaf_area[use]
    b, o = _lum(sol.radiosity()[use]), _lum(obs[use])
    return float(np.sqrt(a @ (b - o) ** 2) / max(np.sqrt(a @ o ** 2), 1e-300))


def _stats(sol, first):
    out = {"elements": sol.hierarchy.n, "leaves": len(sol.leaves), "links": sol.links.n,
           "texture_splits": sol.counts.get("texture_splits", 0)}
    if first is not None:
        out.update(first_elements=first.hierarchy.n, first_links=first.links.n,
                   first_texture_splits=first.counts.get("texture_splits", 0))
    return out


# -- step 1: exitances and reflectances ---------------------------------------------------------

def _leaf_photo(sol, tm, values):
    means, counts, _ = _leaf_texel_means(sol, tm, values)
    return means[sol.leaves], counts[sol.leaves]


def _fit_lamps(sol, tm, photo, textured, lamp_patch, est, opt, occluder, cache):
    """Exitance factors (photo units per scene unit) by eq 4.2, by NNLS and by the shadow-edge
    fit; then per-leaf albedo rounds (the basis is solved with them).  Returns (scale used,
    eq 4.2, NNLS)."""
    scene = sol.scene
    k = scene.n_lamps
    lum_emission = _lum(scene.emission)
    area = scene.area_normal()[0]
    eq_k = np.ones(k)
    if est is not None:
        lamp_area = float(area[lamp_patch].sum())
        e_eq = equal_lamp_exitance(est.scene_intensity, est.rho_mean,
                                   float(area[textured & ~lamp_patch].sum()), lamp_area)
        for j in range(k):
            sel = scene.lamp == j
            e_j = float((area[sel] * lum_emission[sel]).sum() / max(area[sel].sum(), 1e-300))
            eq_k[j] = e_eq / max(e_j, 1e-300)
    nnls_k = _nnls(sol, tm, photo, textured, lamp_patch)
    if opt.exitance == "nnls" and np.any(nnls_k > 0):
        scale = nnls_k.copy()
    elif opt.exitance == "equal" or k == 1:
        scale = eq_k.copy()
    else:   # "edges"
        scale = (nnls_k if np.any(nnls_k > 0) else eq_k).copy()
        _albedo_rounds(sol, tm, photo, textured, lamp_patch, opt, scale)
        for _ in range(2):
            scale = _edge_fit(sol, tm, photo, occluder, opt, scale, cache)
            _albedo_rounds(sol, tm, photo, textured, lamp_patch, opt, scale)
        return scale, eq_k, nnls_k
    _albedo_rounds(sol, tm, photo, textured, lamp_patch, opt, scale)
    return scale, eq_k, nnls_k


def _texel_pairs(tm):
    """Index pairs (into the concatenated texel arrays) of 4-adjacent covered texels."""
    out = []
    off = tm.offsets
    for i, im in enumerate(tm.images):
        if len(im) == 0:
            continue
        hh, ww = im.shape
        grid = np.full(hh * ww, -1, np.int64)
        grid[im.texel_index] = off[i] + np.arange(len(im))
        grid = grid.reshape(hh, ww)
        for a, b in ((grid[:, :-1], grid[:, 1:]), (grid[:-1, :], grid[1:, :])):
            a, b = a.ravel(), b.ravel()
            ok = (a >= 0) & (b >= 0)
            out.append(np.stack([a[ok], b[ok]], 1))
    return np.concatenate(out) if out else np.zeros((0, 2), np.int64)


def _edge_fit(sol, tm, photo, occluder, opt, scale, cache):
    """Relative lamp exitances that make the reflectance photo / irradiance smoothest.

    Reflectance does not know where shadows fall: with the right exitance ratios the photo's
    shadow edges are explained by the irradiance and vanish from photo / H.  Minimises the
    total variation of log(photo / sum_k t_k H_k) over neighbouring texels (robust to genuine
    texture edges, which add a constant) over the k - 1 free ratios; irradiance per texel with
    ray-cast direct light, the overall scale is kept.
    """
    from scipy.optimize import minimize
    k = len(scale)
    if k < 2 or tm.n_texels == 0:
        return scale
    Hocc_k, _ = _texel_irradiance(sol, tm, sol.scene, occluder, opt, scale, cache)
    H = _lum(Hocc_k)                                                  # (k, T)
    pairs = _texel_pairs(tm)
    t_lum = _lum(photo)
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
    return scale * t


def _nnls(sol, tm, photo, textured, lamp_patch, current=None):
    """Exitance factors of the scene's lamps that best explain the photo (per-lamp basis)."""
    obs, counts = _leaf_photo(sol, tm, photo)
    patch = sol.system.patch
    use = textured[patch] & ~lamp_patch[patch] & (counts > 0)
    basis = sol.basis[:, use]
    if current is not None:                          # basis already scaled by ``current``
        basis = basis / np.where(current > 0, current, 1.0)[:, None, None]
    f = fit_lamp_exitance(basis, obs[use], sol.system.leaf_area[use])
    return np.asarray(f.exitance, float)


def _albedo_rounds(sol, tm, values, textured, lamp_patch, opt, scale, unoccluded=False):
    """rho per leaf = photo mean / irradiance, and the basis solved with it.

    The absolute scale of reflectance is not observable from a photo: the mean reflectance is
    held at rho^ (eq 4.1's assumption) and the exitance factors ``scale`` (updated in place)
    absorb the rest, so that the radiosity stays in photo units.  With ``unoccluded`` the
    irradiance ignores visibility (T_final is lit without shadows)."""
    obs, counts = _leaf_photo(sol, tm, values)
    patch = sol.system.patch
    use = textured[patch] & ~lamp_patch[patch] & (counts > 0)
    a = sol.system.leaf_area
    rho = sol.system.rho.copy()
    solve_basis(sol, rho, scale)
    for _ in range(max(opt.albedo_rounds, 1)):
        g = _Transport(sol).unocc if unoccluded else sol.system
        H = g.gather(sol.radiosity())
        with np.errstate(divide="ignore", invalid="ignore"):
            r = np.where(H > 1e-12 * max(H.max(), 1e-300), obs / np.where(H > 0, H, 1.0), np.nan)
        ok = use[:, None] & np.isfinite(r)
        r = np.where(ok, r, rho)
        c = _clipped_mean_scale(_lum(r[use]), a[use], opt.rho_mean)
        r[use] /= c
        scale *= c
        rho = np.where(use[:, None], np.clip(r, 0.0, RHO_MAX), rho)
        solve_basis(sol, rho, scale)
    return rho


def _clipped_mean_scale(lum, area, target, iterations=100):
    """c such that the area-weighted mean of min(lum / c, RHO_MAX) is ``target`` (eq 4.1's
    re-estimated mean: reflectances are clipped, so a few unlit leaves with huge photo /
    irradiance ratios cannot drag the scale).  Bisection on log c; 1 when undefined."""
    ok = np.isfinite(lum) & (lum > 0)
    lum, area = lum[ok], area[ok]
    if len(lum) == 0 or area.sum() <= 0 or not 0 < target < RHO_MAX:
        return 1.0
    w = area / area.sum()
    med = float(np.median(lum))
    lo, hi = np.log(med) - 30.0, np.log(med) + 30.0
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        if float(w @ np.minimum(lum / np.exp(mid), RHO_MAX)) > target:
            lo = mid
        else:
            hi = mid
    return float(np.exp(0.5 * (lo + hi)))


# -- step 2: texture-based refinement -----------------------------------------------------------

def _probe_attenuation(sol, elements, occluder, opt, scale, uv_points):
    """Per lamp attenuation (n, m, k) at parameter points ``uv_points`` (m, 2) of elements."""
    h = sol.hierarchy
    c = h.corners[elements]
    pts = bilinear_point(c[:, None], uv_points[None, :, 0], uv_points[None, :, 1])
    nrm = np.repeat(h.normal[elements], len(uv_points), axis=0)
    U, O = lamp_irradiance(sol.scene, pts.reshape(-1, 3), nrm, occluder, opt.probe_rays,
                           opt.seed + 7, scale)
    u, o = _lum(U), _lum(O)
    att = np.where(u > 0, o / np.where(u > 0, u, 1.0), 1.0)
    share = u / np.maximum(u.sum(axis=1, keepdims=True), 1e-300)
    m = len(uv_points)
    return att.reshape(len(elements), m, -1), share.reshape(len(elements), m, -1)


_CHILD_CENTRES = np.array([[0.25, 0.25], [0.75, 0.25], [0.75, 0.75], [0.25, 0.75]])
_CENTRE = np.array([[0.5, 0.5]])


def _refine_by_texture(sol, tm, values, white, occluder, opt, scale, colour=True):
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
        pairs = _neighbour_pairs(tm, elem)
        live = leaves[~lamp_patch[h.patch[leaves]]]
        att, share = _probe_attenuation(sol, live, occluder, opt, scale, _CENTRE)
        att, share = att[:, 0], share[:, 0]
        sig = share >= SIGNIFICANT_SHARE
        vis = np.where(sig, _visibility(att), VISIBLE)
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
                lab = _lab_of(means, white)
                differ |= lab_distance(lab[pa], lab[pb]) > opt.colour_threshold
            cand[pa[differ]] = True
            cand[pb[differ]] = True
        # Stop at the minimum element size and at about one texel per child.
        cand &= (h.area[: h.n] / 4 >= min_area) & (counts >= 4)
        ids = np.flatnonzero(cand)
        if len(ids) == 0:
            break
        # Probe the four children: split only where the visibility changes inside.
        catt, cshare = _probe_attenuation(sol, ids, occluder, opt, scale, _CHILD_CENTRES)
        csig = cshare.max(axis=1) >= SIGNIFICANT_SHARE
        cvis = _visibility(catt)
        change = (np.any((cvis != cvis[:, :1]) & csig[:, None], axis=(1, 2))
                  | np.any((catt.max(1) - catt.min(1)) * csig > opt.attenuation_threshold, axis=1))
        ids = ids[change]
        if len(ids) == 0:
            break
        h.split(ids)
        total_split += len(ids)
    sol.counts["texture_splits"] = total_split
    return total_split


# -- step 4: frontier and references -------------------------------------------------------------

def _camera_visible(sol, leaves, occluder):
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
    eps = 1e-6 * float(np.linalg.norm(np.ptp(h.corners[: sol.scene.n_patches].reshape(-1, 3), 0)))
    blocked = occluder.segments_occluded(c + eps * h.normal[leaves], np.broadcast_to(vp, c.shape))
    return facing & ~blocked


def _reference_correction(sol, tm, elem, t_inter, HU, Docc_k, DU_k, occluder, opt):
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
    du, do = _lum(DU_k), _lum(Docc_k)                           # (k, L)
    att = np.where(du > 0, do / np.where(du > 0, du, 1.0), 1.0).T
    share = (du / np.maximum(_lum(HU)[None], 1e-300)).T
    sig = share >= SIGNIFICANT_SHARE
    shadowed = np.any(sig & (att < 1 - VIS_TOL), axis=1) & ~lamp_leaf
    lit = ~np.any(sig & (att < 1 - VIS_TOL), axis=1) & ~lamp_leaf & np.any(sig, axis=1)
    means, counts = element_means(t_inter, elem, h.n, hierarchy=h)
    obs = means[leaves]
    has_tex = counts[leaves] > 0
    rho_inter = obs / np.maximum(HU, 1e-300)                    # physical albedo
    pairs = _neighbour_pairs(tm, elem)
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
        fidx = fidx[_camera_visible(sol, leaves[fidx], occluder)]
    corr = np.ones((L, 3))
    codes = np.full(L, -1, np.int8)
    codes[fidx] = 0
    sidx = np.flatnonzero(shadowed & has_tex)
    if len(sidx) == 0:
        return corr, (0, len(fidx), 0, 0), codes
    white = float(np.percentile(_lum(rho_inter[has_tex]), 99)) if has_tex.any() else 1.0
    lab = _lab_of(rho_inter, white)
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
    corr[si] = _ratio(rho_inter[ri], rho_inter[si])
    codes[sidx] = np.where(has_ref, 1, 2)
    return corr, (len(sidx), len(fidx), int(has_ref.sum()) - defaulted, defaulted), codes


# -- step 5 / texel mode: maps -------------------------------------------------------------------

def _maps_from(Hocc_k, HU, eps=DISPLAY_EPS):
    """M_k = H_occ,k / H_unocc per texel; 0 where H_unocc is below ``eps`` of its max (per
    channel, over every texel)."""
    HU = np.maximum(HU, 0.0)
    floor = np.maximum(eps * HU.max(axis=0, initial=0.0), 1e-300)
    lit = HU >= floor
    return np.where(lit[None], np.maximum(Hocc_k, 0.0) / np.where(lit, HU, 1.0)[None], 0.0)


def _texel_irradiance(sol, tm, scene, occluder, opt, scale, cache):
    """(Hocc_k, HU_k) per texel (k, T, 3): direct by ray casting, indirect interpolated."""
    Hocc_k, HU_k, Docc_k, DU_k = _Transport(sol).irradiance(sol.basis)
    elem = texel_elements(sol.hierarchy, tm)
    ind_occ = np.stack([vertex_interpolate(sol.hierarchy, o - d, tm, elem)
                        for o, d in zip(Hocc_k, Docc_k)])
    ind_un = np.stack([vertex_interpolate(sol.hierarchy, u - d, tm, elem)
                       for u, d in zip(HU_k, DU_k)])
    U1, O1 = _texel_direct(scene, tm, occluder, opt, cache)
    scale = np.asarray(scale, float)[None, :, None]
    U, O = U1 * scale, O1 * scale
    U, O = np.moveaxis(U, 1, 0), np.moveaxis(O, 1, 0)            # (k, T, 3)
    return np.maximum(O + ind_occ, 0.0), np.maximum(U + ind_un, 0.0)


def _texel_direct(scene, tm, occluder, opt, cache):
    """Direct irradiance (T, k, 3) from each lamp at unit exitance factor, unoccluded and with
    visibility, averaged over each texel's footprint.  Linear in the exitances, so it is cast
    once per (scene, texel map) and scaled afterwards (the shadow-edge fit and the maps reuse
    it); computed in chunks of texels so that the footprint points and their rays stay bounded
    (about 0.3 kB per texel and lamp are kept, whatever the texture size)."""
    if "direct" in cache:
        return cache["direct"]
    T, k = tm.n_texels, scene.n_lamps
    U = np.zeros((T, k, 3))
    O = np.zeros((T, k, 3))
    patch, u, v = tm.patch, tm.u, tm.v
    parts = [im for im in tm.images if len(im)]
    centre = np.concatenate([im.uv for im in parts]) if parts else np.zeros((0, 2))
    size = np.concatenate([np.repeat([[im.shape[1], im.shape[0]]], len(im), axis=0)
                           for im in parts]) if parts else np.zeros((0, 2))
    def chunk(c0):
        sl = slice(c0, c0 + TEXEL_CHUNK)
        pts, nrm, n_sub = _texel_points(scene, patch[sl], u[sl], v[sl], centre[sl], size[sl],
                                        opt.texel_samples)
        # the mean over each texel's footprint (a photo texel integrates it too)
        U[sl], O[sl] = lamp_irradiance(scene, pts.reshape(-1, n_sub, 3), nrm[::n_sub], occluder,
                                       opt.texel_rays, opt.seed + 11 + c0)

    # Chunks on two threads (numpy and Embree release the GIL); each has its own seed, so the
    # result does not depend on scheduling.
    starts = range(0, T, TEXEL_CHUNK)
    if len(starts) > 1:
        with ThreadPoolExecutor(2) as pool:
            list(pool.map(chunk, starts))
    else:
        for c0 in starts:
            chunk(c0)
    cache["direct"] = (U, O)
    return U, O


def _texel_points(scene, patch, u, v, centre, size, samples):
    """3D points (t * samples^2, 3) and normals over each texel's footprint (a samples x
    samples grid in UV around the texel centre ``centre`` (t, 2) of an image of ``size`` (t, 2)
    texels, mapped through the owning patch; points past the patch edge are clamped onto it).
    ``u``, ``v``: the patch parameters of the texel centres."""
    normals = scene.area_normal()[1][patch]
    if samples <= 1 or len(patch) == 0:
        pts = bilinear_point(scene.corners[patch][:, None], u[:, None], v[:, None])[:, 0]
        return pts, normals, 1
    from ..texture.mapping import inverse_bilinear, inverse_triangle, uv_patch_is_triangle
    uvc = scene.uv[patch]
    g = (np.arange(samples) + 0.5) / samples - 0.5
    off = np.stack(np.meshgrid(g, g, indexing="xy"), -1).reshape(-1, 2)        # (s^2, 2)
    q = (centre[:, None] + off[None] / size[:, None]).reshape(-1, 2)            # (t s^2, 2)
    rep = np.repeat(np.arange(len(patch)), len(off))
    tri = uv_patch_is_triangle(uvc)[rep]
    uu = np.empty(len(q))
    vv = np.empty(len(q))
    if (~tri).any():
        uu[~tri], vv[~tri], _ = inverse_bilinear(uvc[rep[~tri]], q[~tri])
    if tri.any():
        uu[tri], vv[tri] = inverse_triangle(uvc[rep[tri]], q[tri])[:2]
    uu = np.clip(np.nan_to_num(uu, nan=0.5), 0.0, 1.0)
    vv = np.clip(np.nan_to_num(vv, nan=0.5), 0.0, 1.0)
    pts = bilinear_point(scene.corners[patch][rep][:, None], uu[:, None], vv[:, None])[:, 0]
    return pts, normals[rep], len(off)


def ratio_maps(sol, tm, eps=DISPLAY_EPS):
    """The DRB97 display maps (texture correction off): M_k = B_k / sum_k B_k per texel (k, T, 3),
    from vertex-interpolated leaf radiosity; 0 below the floor (see _maps_from)."""
    elem = texel_elements(sol.hierarchy, tm)
    Bk = np.stack([vertex_interpolate(sol.hierarchy, np.maximum(b, 0.0), tm, elem)
                   for b in sol.basis])
    return _maps_from(Bk, Bk.sum(axis=0), eps)


def _drb97_maps(sol, tm, photo, scene):
    """Texture correction off: T = photo, M_k = B_k / sum_k B_k."""
    return _to_images(tm, photo, ratio_maps(sol, tm), scene)


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
            m[j], _ = dilate_seams(full.reshape(hh, ww, 3), im.coverage, seam_pixels)
        mp[i] = np.nan_to_num(m)
        cov[i] = im.coverage.copy()
    return mp, cov


def _to_images(tm, t_final, maps, scene):
    """T_final per image (the original texels outside the covered ones, dilated) and the maps."""
    tex = {}
    off = tm.offsets
    for i, im in enumerate(tm.images):
        if len(im) == 0:
            continue
        hh, ww = im.shape
        base = _texels(scene.images[i]).reshape(hh * ww, 3).copy()
        base[im.texel_index] = t_final[off[i]:off[i + 1]]
        t_img, _ = dilate_seams(base.reshape(hh, ww, 3), im.coverage, SEAM_PIXELS)
        tex[i] = np.nan_to_num(t_img).astype(np.float32)
    mp, cov = map_images(tm, maps)
    return tex, mp, cov
