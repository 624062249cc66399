"""Shadow-free textures (seed 000 §4.2-4.3): the whole precompute on a SceneData, bpy-free.

Input: a SceneData whose patches carry the photographs (``images[i].texels`` linear RGB, UVs)
and the real lamps (emission in Blender units; only their ratios and geometry are trusted).
Output (:class:`ShadowFreeResult`): per image the texture ``T_final`` and one display map
``M_k`` per lamp, so that the relit texture is ``T_final x sum_k I_k M_k`` (``I_k`` = lamp
intensity relative to the photo).

The pipeline below reads top to bottom; each step's idea is a module of its own:

1. Initialisation (§4.2.1): reflectance per patch by eq 4.1 (``albedo``), a first hierarchical
   BFV solution (``radiosity.precompute``), lamp exitances (``exitance``: eq 4.2, NNLS and the
   shadow-edge fit, used by default), then per-leaf reflectance photo / irradiance.
2. ``mode="texel"`` (default, the seed's conclusion): the direct part of the occluded and
   unoccluded irradiance at every texel by ray casting to each lamp (``texel``), the indirect
   part interpolated from the solution; T_final = T x H_unocc / H_occ and M_k = H_occ,k / D with
   D = H_occ x the clipped factor, so the original lighting is reproduced exactly
   (``texel_maps``: block by block, so that photo-resolution textures fit in memory).
3. ``mode="element"`` (the seed's pipeline): texture-based refinement (``refine``, fig 4.7),
   blocked irradiance E-bar and T_inter (eq 4.5-4.6, ``transport``), optionally frontier and
   reference elements (``reference``, fig 4.11, eq 4.8-4.9), and a fresh solution on T_final
   whose B / D gives the maps (§4.3.3).
4. ``mode="none"``: the DRB97 baseline (no texture correction): T = photo, M_k = B_k / sum B.

Maps and textures become images in ``maps`` (with the floors that keep them finite).
"""
from __future__ import annotations

import copy
import time
from dataclasses import dataclass, field

import numpy as np

from ..numerics import safe_div
from ..radiosity.memory import give_back_memory
from ..progress import report, reporting, scope
from ..radiosity.precompute import regather, solve_basis, solve_radiosity
from ..radiosity.presets import PROXY_FACTOR, get_preset
from ..radiosity.proxy import build_proxy
from ..scene import SceneData
from ..texture.colour import luminance
from ..texture.mapping import patch_means, rasterize_patches, texel_elements, vertex_interpolate
from .albedo import albedo_rounds, estimate_reflectance
from .enclosure import dark_inside
from .exitance import fit_lamps, photo_misfit
from .orient import orient
from .maps import (clipped_ratio, map_images, maps_from,
                   ratio_maps, texels_of, texture_images)
from .proxy_texels import texels_on
from .reference import reference_correction
from .refine import refine_by_texture
from .texel import BUMPS, TexelLight, texel_light_for
from .texel_maps import texel_maps
from .transport import Transport, as_given


@dataclass
class ShadowFreeOptions:
    mode: str = "texel"                 # "texel" | "element" | "none" (DRB97)
    preset: str = "medium"
    exitance: str = "user"              # "user" | "photo" | "nnls" | "equal" (exitance.py)
    rho_mean: float = 0.5               # rho^, the mean reflectance (eq 4.1): the first guess
    fit_indirect: bool = True           # fit rho^ from the depth of the photo's shadows
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
    orient: bool = True                 # turn faces to their photographed side (orient.py)
    # meshes of more than PROXY_FACTOR x this many faces (scans) are solved on a decimated proxy
    # of about this many triangles (radiosity.proxy); 0: the preset's proxy_faces
    proxy_faces: int = 0
    seed: int = 0


@dataclass
class ShadowFreeResult:
    options: ShadowFreeOptions
    texel_map: object             # TexelMap
    texture: dict                 # image index -> (H, W, 3) float32 T_final (dilated)
    maps: dict                    # image index -> (k, H, W, 3) float32 M_k (dilated)
    coverage: dict                # image index -> (H, W) bool
    lamps: object                 # LampEstimate: factors used, the photo's view, uncertainty
    solution: object              # the solution the maps come from
    first_solution: object | None = None
    stats: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)
    reference_info: dict | None = None   # frontier / reference codes per first-solution leaf
    photographed: np.ndarray | None = None   # (p,) patches whose reflectance the photo gives
    # texel mode: the irradiance the photo was lit by, per texel (T, 3), that every map divides
    # by (virtual lamps added later divide by it too), and the occluder the run used
    denominator: np.ndarray | None = None
    occluder: object = None
    # texel mode: per image (k, H, W) the part of each map that is the lamp's direct light
    # (maps.direct_fraction): a moving object's sphere shadow scales that part only
    direct: dict | None = None
    # the scene the texels belong to (oriented; the solution's may be a proxy of it) and the
    # texel map in the solution's patches (``texel_map`` itself unless a proxy was used)
    scene: SceneData | None = None
    solution_texels: object = None
    # with virtual objects: the result of the room alone, that an Update moving, adding or
    # deleting objects starts from again (None when this result is not its room plus objects)
    room: object = None

    def texel_light(self, scene=None, seed=0, occluder=None) -> TexelLight:
        """A TexelLight on this result's texels as the run had it (shading normals, ray
        offset, how the solution is read: a proxy's kernel), for ``scene``: the run's scene,
        or one with other lamps or objects (virtual ones, with their ``occluder``)."""
        proxy = self.solution.context.get("proxy") if self.solution is not None else None
        return texel_light_for(self.scene if scene is None else scene, self.texel_map,
                            self.occluder if occluder is None else occluder, self.options,
                            seed, proxy, self.solution_texels)

    @property
    def exitance_scale(self) -> np.ndarray:
        """(k,) factor on each lamp's scene exitance (photo units per scene unit)."""
        return self.lamps.scale

    def relit(self, intensities=None) -> dict:
        """T_final x sum_k I_k M_k per image (covered texels meaningful)."""
        out = {}
        for i, tex in self.texture.items():
            m = self.maps[i]
            I = np.ones(len(m)) if intensities is None else np.asarray(intensities, float)
            out[i] = (tex * np.tensordot(I.astype(np.float32), m, axes=1)).astype(np.float32)
        return out


class _Stage:
    """Progress reports (core/progress.py: a stage spans [frac, until] of the run) and
    per-stage timings."""

    def __init__(self, timings):
        self.timings, self.t0, self.name = timings, None, None

    def __call__(self, frac, name, until=None):
        now = time.perf_counter()
        if self.name is not None:
            self.timings[self.name] = self.timings.get(self.name, 0.0) + now - self.t0
        self.name, self.t0 = name, now
        if name is not None:
            report(frac, name, until)


def shadow_free(scene: SceneData, options: ShadowFreeOptions | None = None, occluder="auto",
                progress=None, reuse=None) -> ShadowFreeResult:
    """Shadow-free texture T_final and per-lamp display maps M_k (see the module docstring).

    ``reuse``: the first solution of an earlier run on the same geometry, lamps and preset
    (``result.solution`` of a "texel" or "none" run): its mesh, links and form factors are kept
    and only the reflectances, exitances and maps are estimated again (photos edited)."""
    opt = options or ShadowFreeOptions()
    if opt.mode not in ("element", "texel", "none"):
        raise ValueError(f"unknown mode {opt.mode!r}")
    if scene.virtual.any():
        # Virtual objects are not in the photo: the room is precomputed without them, then
        # their shadows and reflections are put into the maps (virtual.py).
        if opt.mode != "texel":
            raise ValueError("Virtual objects need Shadow Removal 'Per Texel'")
        from .virtual import add_objects
        room = shadow_free(scene.without_virtual(), options, occluder, progress, reuse)
        return add_objects(room, scene)
    if scene.n_lamps == 0:
        raise ValueError("The scene has no lamps: nothing to relight")
    with reporting(progress):
        return _shadow_free(scene, opt, occluder, reuse)


def _shadow_free(scene, opt, occluder, reuse):
    timings = {}
    stage = _Stage(timings)
    if occluder == "auto":
        occluder = scene.make_occluder()
    scene = dark_inside(scene, occluder)
    run = _read(scene, opt, occluder, reuse, stage, timings)
    _initialise(run, reuse)
    if opt.mode == "none":
        return _drb97(run)
    if opt.mode == "texel":
        return _per_texel(run)
    return _per_element(run)


@dataclass
class _Run:
    """One shadow-free run as its steps fill it in."""
    opt: ShadowFreeOptions
    stage: _Stage
    timings: dict
    scene: SceneData              # oriented (orient.py)
    orientation: object
    occluder: object
    tm: object                    # TexelMap of the scene's images
    photo: np.ndarray | None      # (T, 3) float32 texels of the photos
    proxy: object                 # radiosity.proxy.Proxy, or None
    rad_scene: SceneData          # what the radiosity is solved on: the scene or its proxy
    rad_tm: object                # the texels on it
    rad_image: np.ndarray
    rad_occluder: object
    texel_light: TexelLight
    # filled in by _initialise: the photographed patches, their area, eq 4.1's estimate, the
    # first solution, the lamps' exitances and the solution's misfit to the photo
    use_patch: np.ndarray | None = None
    est_ids: np.ndarray | None = None
    area: np.ndarray | None = None
    solution: object = None
    lamps: object = None
    misfit: float | None = None


def _read(scene, opt, occluder, reuse, stage, timings) -> _Run:
    """Faces turned to their photographed side, the photos' texels, the radiosity proxy of a
    dense mesh, and the per-texel light."""
    orientation = None
    if opt.orient:
        stage(0.0, "Turning faces to their photographed side", 0.01)
        orientation = orient(scene, occluder, opt.seed)
        scene = orientation.scene

    stage(0.01, "Reading the photos", 0.012)
    shapes = [texels_of(im).shape[:2] for im in scene.images]
    image_of = scene.image if scene.image is not None else np.full(scene.n_patches, -1)
    uv = scene.uv if scene.uv is not None else np.zeros((scene.n_patches, 4, 2))
    tm = rasterize_patches(uv, image_of, shapes)
    photo = tm.gather([texels_of(im) for im in scene.images])          # float32

    # A scan's dense mesh is solved on a decimated proxy (radiosity.proxy): the direct light
    # is still cast at every texel of the full mesh, the indirect light read on the proxy.
    proxy = _proxy(scene, opt, reuse, stage, orientation)
    if proxy is None:
        rad_scene, rad_tm, rad_occluder, rad_image = scene, tm, occluder, image_of
    else:
        if opt.mode == "element":
            raise ValueError(f"A mesh of {scene.n_patches} faces is solved on a proxy, which "
                             "needs Shadow Removal 'Per Texel'")
        stage(0.015, "Placing the photos' texels on the proxy", 0.02)
        rad_scene, rad_tm = proxy.scene, texels_on(proxy, scene, tm)
        rad_occluder = proxy.scene.make_occluder() if occluder is not None else None
        rad_image = np.where(np.bincount(rad_tm.patch, minlength=proxy.n_patches) > 0, 0, -1)
    texel_light = texel_light_for(scene, tm, occluder, opt, opt.seed, proxy, rad_tm)
    return _Run(opt, stage, timings, scene, orientation, occluder, tm, photo, proxy, rad_scene,
                rad_tm, rad_image, rad_occluder, texel_light)


def _initialise(run: _Run, reuse):
    """1. Initialisation (§4.2.1): eq 4.1 per patch, the first solution, the lamps' exitances
    and the per-leaf albedo."""
    opt, stage, proxy, orientation = run.opt, run.stage, run.proxy, run.orientation
    rad_scene, rad_tm, photo = run.rad_scene, run.rad_tm, run.photo
    stage(0.02, "Estimating the reflectances", 0.05)
    patch_mean, cnt = patch_means(rad_tm, photo, rad_scene.n_patches)
    use_patch = (run.rad_image >= 0) & (cnt > 0) & (rad_scene.lamp < 0)  # photographed surfaces
    est_ids = np.flatnonzero(use_patch)
    area = rad_scene.area_normal()[0]
    rho_patch = rad_scene.rho.copy()
    est = None
    if len(est_ids):
        est = estimate_reflectance(patch_mean[est_ids], area[est_ids], opt.rho_mean)
        rho_patch[est_ids] = est.rho
    del patch_mean
    backs = orientation.back_of if proxy is None and orientation is not None else \
        (proxy.back_of if proxy is not None else ())
    if len(backs):
        rho_patch[-len(backs):] = rho_patch[backs]          # backs reflect as their fronts
    scene1 = rad_scene.with_rho(rho_patch)

    if reuse is not None and opt.mode != "element":
        stage(0.05, "Reusing the light's mesh and links", 0.4)
        sol = copy.copy(reuse)                 # the caller's solution stays as it was
        sol.system = copy.copy(reuse.system)
        sol.scene = scene1
        solve_basis(sol, scene1.rho[sol.system.patch])    # scene exitances, eq 4.1 reflectances
    else:
        stage(0.05, "Solving the light in the room", 0.4)
        # A decimated proxy has no contact or gap lines to split at (radiosity.contacts): its
        # triangles lying on one another are the decimation's, not objects standing on a
        # surface.  With them, family room 5's 100k-triangle scan at medium pinned a lamp 15 %
        # off at exact powers (lamp off 0.51 / 0.55 -> 0.75 / 0.63 CIEDE2000).
        quality = get_preset(opt.preset)
        lamp_view = {}
        if proxy is not None:
            quality = quality.with_(contact_levels=0, gap_levels=0)
            lamp_view = proxy_lamp_view(proxy, run.occluder)
        with scope(0.05, 0.4):
            sol = solve_radiosity(scene1, quality, occluder=run.rad_occluder, seed=opt.seed,
                                  **lamp_view)
        sol.context["proxy"] = proxy
    stage(0.4, "Estimating the lamps from the photo", 0.6)
    run.lamps = fit_lamps(sol, rad_tm, photo, use_patch, est, opt, run.texel_light)
    run.misfit = photo_misfit(sol, rad_tm, photo, use_patch)
    run.solution, run.use_patch, run.est_ids, run.area = sol, use_patch, est_ids, area


def _result(run: _Run, texture, maps, coverage, solution, first=None, stats=None,
            reference_info=None, denominator=None, direct=None) -> ShadowFreeResult:
    run.stage(1.0, None)
    scene, proxy, orientation = run.scene, run.proxy, run.orientation
    stats = {**_stats(solution, first), "photo_misfit": run.misfit, **(stats or {})}
    if proxy is not None:
        a = scene.area_normal()[0]
        stats.update(proxy_faces=proxy.n_patches, input_faces=scene.n_patches,
                     proxy_deviation=float(safe_div(a @ proxy.deviation, a.sum())))
    if orientation is not None:
        stats.update(flipped=orientation.per_group("flipped"),
                     two_sided=orientation.per_group("two_sided"))
    return ShadowFreeResult(run.opt, run.tm, texture, maps, coverage, run.lamps,
                            solution, first, stats, run.timings, reference_info, run.use_patch,
                            denominator, run.occluder, direct, scene, run.rad_tm)


def _drb97(run: _Run) -> ShadowFreeResult:
    """4. DRB97: the photo as it is, maps B_k / sum B."""
    run.stage(0.9, "Making the lamps' maps", 1.0)
    sol, tm, scene = run.solution, run.tm, run.scene
    mp, cov = map_images(tm, ratio_maps(sol, run.rad_tm, weights=scene.lamp_intensity))
    return _result(run, texture_images(tm, run.photo, scene.images), mp, cov, sol)


def _per_texel(run: _Run) -> ShadowFreeResult:
    """2. Per texel: direct light ray-cast at every texel, indirect from the solution."""
    run.stage(0.6, "Lighting every texel and making the maps", 1.0)
    run.photo = None                 # read again block by block: not held at the peak
    run.texel_light.release()
    give_back_memory()
    sol, scene = run.solution, run.scene
    out = texel_maps(run.texel_light, sol, run.lamps.scale, scene, scene.images)
    return _result(run, out.texture, out.maps, out.coverage, sol, denominator=out.denominator,
                   direct=out.direct)


def _per_element(run: _Run) -> ShadowFreeResult:
    """3. Per element (the seed's pipeline): texture-based refinement, T_inter and T_final
    (eq 4.5-4.9), then a fresh solution on T_final whose B / D gives the maps."""
    opt, sol, tm, photo = run.opt, run.solution, run.tm, run.photo
    white = float(np.percentile(luminance(photo), 99)) if len(photo) else 1.0
    if opt.refine:
        run.stage(0.45, "Refining where the photo's colours change", 0.6)
        refine_by_texture(sol, tm, photo, white, run.occluder, opt, run.lamps.scale)
        regather(sol, opt.seed + 1)
        albedo_rounds(sol, tm, photo, run.use_patch, run.lamps.rho_mean, opt.albedo_rounds,
                      run.lamps.scale)
    t_final, counts, reference_info = _t_final(run)
    first, sol = sol, _fresh_solution(run, t_final, white)
    run.stage(0.92, "Making the lamps' maps", 1.0)
    scene = run.scene
    Hocc_k, HU_k, _, _ = Transport(sol).irradiance(sol.basis)
    elem = texel_elements(sol.hierarchy, tm)

    def per_texel(leaf_vals):          # smooth per-texel values of the fresh solution
        return vertex_interpolate(sol.hierarchy, leaf_vals, tm, elem)
    maps = maps_from(np.stack([per_texel(x) for x in Hocc_k]), per_texel(as_given(HU_k, scene)))
    mp, cov = map_images(tm, maps)
    n_shadowed, n_frontier, n_ref, n_default = counts
    return _result(run, texture_images(tm, t_final, scene.images), mp, cov, sol, first,
                   dict(shadowed_leaves=n_shadowed, frontier_leaves=n_frontier,
                        referenced=n_ref, default_reference=n_default), reference_info)


def _t_final(run: _Run):
    """The first modification (eq 4.5, 4.6: blocked irradiance, T_inter), then the second
    (frontier, references, rho_corr, T_final: eq 4.8, 4.9) when ``opt.reference``: (T_final,
    (shadowed, frontier, referenced, default-referenced leaves), reference info)."""
    opt, sol, tm, scene = run.opt, run.solution, run.tm, run.scene
    run.stage(0.6, "Removing the photographed shadows", 0.7)
    Hocc_k, HU_k, Docc_k, DU_k = Transport(sol).irradiance(sol.basis)
    elem = texel_elements(sol.hierarchy, tm)

    def per_texel(leaf_vals):          # smooth per-texel values of the current solution
        return vertex_interpolate(sol.hierarchy, leaf_vals, tm, elem)

    HU = as_given(HU_k, scene)
    t_inter = run.photo * clipped_ratio(per_texel(HU), per_texel(as_given(Hocc_k, scene)),
                                        fmin=1.0)
    run.stage(0.7, "Reference surfaces for the shadows' edges", 0.75)
    counts = (0, 0, 0, 0)
    t_final = t_inter
    reference_info = None
    if opt.reference:
        corr, counts, codes = reference_correction(sol, tm, elem, t_inter, HU, Docc_k,
                                                   DU_k, run.occluder, opt)
        reference_info = {"hierarchy": sol.hierarchy, "leaves": sol.leaves.copy(), "codes": codes}
        t_final = t_inter * per_texel(corr)
    return t_final, counts, reference_info


def _fresh_solution(run: _Run, t_final, white):
    """§4.3.3: a fresh solution on the reflectances of T_final (B with visibility, D from its
    unoccluded gather), refined by texture and its albedo re-estimated as the first was."""
    opt, tm, scene, orientation = run.opt, run.tm, run.scene, run.orientation
    scale_k, est_ids, area = run.lamps.scale, run.est_ids, run.area
    run.stage(0.75, "Solving again on the shadow-free textures", 0.9)
    pm, _ = patch_means(tm, t_final, scene.n_patches)
    rho2 = scene.rho.copy()
    if len(est_ids):
        rho2[est_ids] = estimate_reflectance(pm[est_ids], area[est_ids], run.lamps.rho_mean).rho
    if orientation is not None and len(orientation.back_of):
        rho2[-len(orientation.back_of):] = rho2[orientation.back_of]
    with scope(0.75, 0.9):
        sol = solve_radiosity(scene.with_rho(rho2), opt.preset, occluder=run.occluder,
                              seed=opt.seed + 2)
    if opt.refine:
        refine_by_texture(sol, tm, t_final, white, run.occluder, opt, scale_k, colour=False)
        regather(sol, opt.seed + 3)
    albedo_rounds(sol, tm, t_final, run.use_patch, run.lamps.rho_mean, opt.albedo_rounds,
                  scale_k, unoccluded=True)
    return sol


def proxy_lamp_view(proxy, occluder):
    """How a proxy's leaves see the lights (sun, point, spot): against the full mesh, from
    above its bumps and the proxy's distance to it.  The proxy's own triangles let light
    through where the decimation moved a border: on family room 3's scan (100k triangles),
    6.6 % more sun came through its window (and 1.4 % onto a wall the sun cannot reach) than
    on the clean room, and its indirect light came out 7 % bright at high (lamp off 0.83 ->
    0.75 CIEDE2000 against the full mesh)."""
    if occluder is None:
        return {}
    deviation = float(np.percentile(proxy.deviation, 95)) if len(proxy.deviation) else 0.0
    return {"light_occluder": occluder,
            "light_lift": BUMPS * proxy.roughness + 2.0 * deviation}


def _proxy(scene, opt, reuse, stage, orientation):
    """The radiosity proxy of a scene with more faces than the preset solves (None when it
    has not), or the one ``reuse`` was solved on."""
    if reuse is not None and opt.mode != "element":
        return reuse.context.get("proxy")
    faces = opt.proxy_faces or get_preset(opt.preset).proxy_faces
    surfaces = int(np.count_nonzero(scene.lamp < 0))
    if surfaces <= PROXY_FACTOR * faces:
        return None
    stage(0.012, f"Decimating {surfaces:,} faces to a proxy of {faces:,}", 0.015)
    return build_proxy(scene, faces, None if orientation is None else orientation.back_of)


def _stats(sol, first):
    out = {"elements": sol.hierarchy.n, "leaves": len(sol.leaves), "links": sol.links.n,
           "texture_splits": sol.counts.get("texture_splits", 0)}
    if first is not None:
        out.update(first_elements=first.hierarchy.n, first_links=first.links.n,
                   first_texture_splits=first.counts.get("texture_splits", 0))
    return out
