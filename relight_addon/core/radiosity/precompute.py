"""Hierarchical radiosity on a SceneData: refine, solve, and per-lamp basis solutions.

The solution is kept as one basis B_k per lamp on the leaves, with fixed links, so that
B = sum_k I_k B_k for any lamp intensities I_k (light transport is linear in the exitances).

Lamps that are not patches (``scene.lights``: point, spot, sun, area with a spread) reach the
leaves as direct irradiance, averaged over each leaf's quadrature points with visibility rays;
a leaf's emission in lamp k's basis is then rho x that irradiance.  During refinement the
oracle sees their light on every element (mean and spread over five points), so that what they
light brightly or unevenly is split as a source like any other.
"""
from __future__ import annotations

import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from functools import partial

import numpy as np

from ..geometry.extent import bounding_diagonal
from ..geometry.patch import bilinear_point
from ..geometry.raycast import ray_offset
from ..geometry.sampling import quadrature
from ..lights import light_irradiance
from ..numerics import nonzero
from ..progress import Cancelled, report, reporting, tick  # noqa: F401  (Cancelled: callers')
from ..scene import SceneData
from .clusters import (build_cluster_tree, cluster_operator, cluster_transport,
                       cluster_visibility, link_clusters)
from .conserve import COVERAGE_RAYS, back_copies, conserve_rows, hemisphere_coverage
from .contacts import contact_segments, crossed_leaves, split_at_contacts
from .exposure import leaf_exposure
from .gather_rows import GatherRows
from .source_split import split_sources
from .hierarchy import Hierarchy
from .memory import give_back_memory
from .final_links import final_form_factors
from .links import (PARTIAL, LinkSet, close_pairs, facing, initial_pairs, no_timer,
                    oracle_estimates, visibility_types)
from .presets import Quality, get_preset
from .solver import LeafSystem, SolveInfo

MAX_REFINE_ROUNDS = 40
# Lamp patches link to every patch as elements, outside the clusters, while there are at
# most this many (a lamp of many faces is clustered like any surface: its lamp x patch links
# cost more than they give)
LAMP_PATCHES_MAX = 64
# Shadow boundaries stop one level above the minimum element size (their links multiply fast).
SHADOW_AREA_FACTOR = 4.0




@dataclass
class RadiositySolution:
    scene: SceneData
    quality: Quality
    hierarchy: Hierarchy
    links: LinkSet
    system: LeafSystem
    gather: object                    # GatherRows: per-leaf F and F*V of every link, by rows
    basis: np.ndarray                 # (k, L, 3) per-lamp leaf radiosity
    info: SolveInfo
    # Direct irradiance from scene.lights per lamp (k, L, 3) on the leaves, at unit exitance
    # factor, with visibility and without; None when the scene has no such lights.
    light_occ: np.ndarray | None = None
    light_unocc: np.ndarray | None = None
    emission_scale: np.ndarray | None = None     # (k,) factors the basis was solved with
    timings: dict = field(default_factory=dict)
    counts: dict = field(default_factory=dict)   # rays cast
    # What regather() needs to recompute the leaf transport after further subdivision.
    context: dict = field(default_factory=dict, repr=False)

    @property
    def leaves(self):
        return self.system.leaves

    @property
    def n_elements(self):
        return self.hierarchy.n

    def lamp_view(self, default=None):
        """(occluder, lift) the leaves' light from ``scene.lights`` is cast with: a proxy's full
        mesh from ``lift`` above the leaves (solve_radiosity's light_occluder), else the solve's
        own occluder, else ``default``."""
        occluder = self.context.get("light_occluder")
        if occluder is None:
            occluder = self.context.get("occluder")
        if occluder is None:
            occluder = default
        return occluder, float(self.context.get("light_lift", 0.0))

    def radiosity(self, intensities=None) -> np.ndarray:
        """Leaf radiosity (L, 3) for lamp intensity factors I_k (default: the scene's own,
        ``scene.lamp_intensity``: 1 for every lamp unless one is off as given)."""
        k = len(self.basis)
        I = self.scene.lamp_intensity if intensities is None else np.asarray(intensities, float)
        # One BLAS matrix-vector product, with I in the basis' dtype (benchmarks/bench_relight.py).
        return (I.astype(self.basis.dtype) @ self.basis.reshape(k, -1)).reshape(self.basis.shape[1:])

    def patch_radiosity(self, intensities=None) -> np.ndarray:
        """Area-weighted mean radiosity (p, 3) of each input patch."""
        B = self.radiosity(intensities)
        p = self.scene.n_patches
        a = self.system.leaf_area
        patch = self.system.patch
        out = np.stack([np.bincount(patch, a * B[:, c], p) for c in range(3)], axis=1)
        return out / nonzero(np.bincount(patch, a, p))[:, None]

    # Timings: "form_factors" and "visibility" are the point-to-polygon and ray-casting time
    # wherever they happen (oracle and final links); "refine" and "final_links" include them.
    def stats(self) -> dict:
        return {"patches": self.scene.n_patches, "elements": self.hierarchy.n,
                "leaves": len(self.leaves), "links": self.links.n,
                "iterations": self.info.iterations, "residual": self.info.residual,
                "gather_entries": int(self.system.M.nnz), **self.counts,
                **{f"t_{k}": v for k, v in self.timings.items()}}


class _CountingOccluder:
    """Counts the segments a ray caster tests, for the throughput figures in stats()."""

    def __init__(self, occluder):
        self.occluder = occluder
        self.rays = 0

    def segments_occluded(self, origins, ends):
        self.rays += len(origins)
        return self.occluder.segments_occluded(origins, ends)

    def first_hit(self, origins, directions, tmax=np.inf):
        self.rays += len(origins)
        return self.occluder.first_hit(origins, directions, tmax)

    @property
    def triangles(self):
        return self.occluder.triangles

    @property
    def patch_of_triangle(self):
        return getattr(self.occluder, "patch_of_triangle", None)


class _Timer(dict):
    @contextmanager
    def __call__(self, name):
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self[name] = self.get(name, 0.0) + time.perf_counter() - t0


def _lamp_emission(scene: SceneData, system: LeafSystem, light_occ=None) -> np.ndarray:
    """(L, 3, k): each lamp's emission on the leaves: its patches' exitance, and rho x the
    direct irradiance of its light on every leaf (``light_occ`` (k, L, 3)).  The part of a
    lamp patch under a touching object emits into it (exposure.py): the sources that gather
    from that patch's exposed part see (1 - a) E less than the exposed value counts."""
    k = scene.n_lamps
    patch_of_leaf = system.patch
    E = np.zeros((len(patch_of_leaf), 3, k))
    lamp = scene.lamp[patch_of_leaf]
    hit = lamp >= 0
    E[np.flatnonzero(hit), :, lamp[hit]] = scene.emission[patch_of_leaf[hit]]
    trapped = (1.0 - system.exposure)[:, None, None] * E
    if trapped.any():
        E = E - system.apply(trapped)
    if light_occ is not None:
        E += np.moveaxis(light_occ, 0, 2) * np.asarray(system.rho)[:, :, None]
    return E


def lights_on_elements(scene: SceneData, h: Hierarchy, elements, occluder, m, rays, seed,
                       scale, lift=0.0):
    """Direct irradiance (k, n, 3) per lamp from ``scene.lights`` averaged over the m x m
    quadrature points of each element: (with visibility, unoccluded); None without lights.
    Rays start ``lift`` above the usual offset (a proxy's leaves lit against the full mesh)."""
    if not len(scene.lights):
        return None, None
    k = scene.n_lamps
    # area-weighted: a triangle is a quad with two corners at one point, whose Gauss points
    # crowd towards that corner
    pts, w = quadrature(h.corners[elements], m)
    U, O = light_irradiance(scene.lights, pts, h.normal[elements], occluder, rays, seed,
                            scale, ray_offset(scale) + lift, weights=w)
    occ, unocc = np.zeros((k, len(elements), 3)), np.zeros((k, len(elements), 3))
    for i, lamp in enumerate(scene.lights.lamp):
        occ[lamp] += O[:, i]
        unocc[lamp] += U[:, i]
    return occ, unocc


# Where the oracle samples the lights on an element: centre and four points near the corners.
_LIGHT_PROBES = np.array([[0.5, 0.5], [0.1, 0.1], [0.9, 0.1], [0.9, 0.9], [0.1, 0.9]])


class _LightEstimates:
    """The oracle's view of ``scene.lights``: per element, the mean (3,) over the five probe
    points of the lights' direct irradiance (all lamps at their scene intensity) and its spread
    (max - min, brightest channel), computed once per element."""

    def __init__(self, scene, h, occluder, rays, rng, scale):
        self.scene, self.h, self.occluder, self.rays, self.scale = scene, h, occluder, rays, scale
        self.rng = rng
        self.mean = np.zeros((0, 3))
        self.spread = np.zeros(0)
        self.done = np.zeros(0, bool)

    def get(self, elements):
        h = self.h
        if len(self.done) < h.n:
            grow = h.n - len(self.done)
            self.mean = np.concatenate([self.mean, np.zeros((grow, 3))])
            self.spread = np.concatenate([self.spread, np.zeros(grow)])
            self.done = np.concatenate([self.done, np.zeros(grow, bool)])
        todo = np.unique(elements[~self.done[elements]])
        if len(todo):
            pts = bilinear_point(h.corners[todo][:, None], _LIGHT_PROBES[None, :, 0],
                                 _LIGHT_PROBES[None, :, 1])                  # (n, 5, 3)
            nrm = np.repeat(h.normal[todo], len(_LIGHT_PROBES), axis=0)
            _, O = light_irradiance(self.scene.lights, pts.reshape(-1, 3), nrm, self.occluder,
                                    self.rays, int(self.rng.integers(2**31)), self.scale,
                                    ray_offset(self.scale))
            per_point = O.sum(axis=1).reshape(len(todo), len(_LIGHT_PROBES), 3)
            self.mean[todo] = per_point.mean(axis=1)
            self.spread[todo] = (per_point.max(axis=1) - per_point.min(axis=1)).max(axis=1)
            self.done[todo] = True
        return self.mean[elements], self.spread[elements]


# The oracle's thresholds are relative to the reflected radiosity that this fraction of the
# surface area reaches or exceeds: the brightest leaves' level, but not a hot spot's (a lamp
# shade's inside would leave the room unrefined)
BRIGHT_AREA = 0.001


def _bright_level(values, area):
    """The value (of ``values`` per leaf) reached or exceeded on BRIGHT_AREA of the total area."""
    if len(values) == 0:
        return 0.0
    order = np.argsort(-values, kind="stable")
    cum = np.cumsum(area[order])
    return float(values[order][min(np.searchsorted(cum, BRIGHT_AREA * cum[-1]), len(cum) - 1)])


def _oracle(h, links: LinkSet, b_est, b_var, b_scale, rho_max, q: Quality, min_area):
    """Which links to refine, and on which side.

    Gathering a link as F_rs * B_s (constant over the receiver, mean over the source) errs by
    about B_s * spread(F over the receiver) on the receiver side and F_rs * var(B over the
    source) on the source side; the source polygon itself is integrated exactly.  A partially
    visible link is refined while B_s F_rs exceeds the (smaller) BFV threshold.  Thresholds are
    relative to ``b_scale``, the reflected radiosity (B - E) of the brightest leaves
    (_bright_level), so that indirect light is refined as carefully as direct light however
    bright the lamps are.  With ``aggregate``
    the receiver side asks also that the sum of what the receiver gathers varies.
    """
    r, s = links.receiver, links.source
    ar, as_ = h.area[r], h.area[s]
    bs = b_est[s]
    rho_r = rho_max[h.patch[r]]                 # errors as they show in the receiver's radiosity
    err_recv = rho_r * bs * links.spread * links.V
    err_src = rho_r * b_var[s] * links.F * links.V
    shadow = (links.vis == PARTIAL) & (rho_r * bs * links.F > q.eps_bfv * b_scale)
    want_r = err_recv > q.eps_bf * b_scale
    if q.aggregate and links.F_points is not None:
        # Each leaf gathers every link on its own points (final_form_factors), so a receiver
        # needs splitting to show what it gathers only where the sum varies across it, not
        # where one link's share does: in a closed furnace the shares of the walls vary and
        # their sum does not.  (Also splitting near links whose source's radiosity is far from
        # the mean the receiver gathers, for their quadrature, made the Cornell box worse:
        # medium 0.86 % mean over seeds 0-4 against 0.67 % without.)
        varies = rho_max[h.view("patch")] * _gathered_variation(h, links, b_est) \
            > q.eps_bf * b_scale
        want_r &= varies[r]
    want_s = err_src > q.eps_bf * b_scale
    can_r = ar / 4 >= min_area
    can_s = as_ / 4 >= min_area
    # Shadow boundaries are resolved on the receiver: each receiver point already integrates the
    # visible part of the whole source with its own rays, so splitting the source there would
    # only multiply links.  Otherwise split the side whose error dominates.
    split_r = can_r & ((want_r & ((err_recv >= err_src) | ~can_s)) |
                       (shadow & (ar / 4 >= SHADOW_AREA_FACTOR * min_area)))
    split_s = ~split_r & can_s & want_s
    return split_r, split_s


def _gathered_variation(h, links: LinkSet, b_elem):
    """Per element (h.n,): max - min over its five oracle points of sum B_s F V over the links
    it receives (the variation of what it gathers at its own level)."""
    k = links.F_points.shape[1]
    total = np.zeros((h.n, k))
    weight = b_elem[links.source] * links.V
    for j in range(k):
        total[:, j] = np.bincount(links.receiver, weight * links.F_points[:, j], h.n)
    return total.max(axis=1) - total.min(axis=1)


def _confirm_visibility(h, links: LinkSet, b_est, b_scale, rho_max, q: Quality, min_area,
                        occluder, rng, scale, timer):
    """Links judged all-visible or all-hidden by the oracle's few rays, tested again with
    ``q.confirm_rays`` times the rays where a shadow on them would be refined (the BFV criterion
    and room to split the receiver).  Four rays miss a shadow crossing a large element often
    enough that a Cornell-box block face came out 14 % dark at medium on two seeds of five (its
    floor link judged unoccluded, never refined).  Draft does without (no gain on its own
    error, which is larger)."""
    if occluder is None or links.n == 0 or q.confirm_rays <= 0:
        return links
    r, s = links.receiver, links.source
    check = ((links.vis != PARTIAL)
             & (rho_max[h.patch[r]] * b_est[s] * links.F > q.eps_bfv * b_scale)
             & (h.area[r] / 4 >= SHADOW_AREA_FACTOR * min_area))
    if not check.any():
        return links
    idx = np.flatnonzero(check)
    rays = q.confirm_rays * q.oracle_rays
    _, _, free, partial, _ = oracle_estimates(h, r[idx], s[idx], occluder, rays, rng, scale,
                                              timer)
    old = links.V[idx]
    V = links.V.copy()
    vis = links.vis.copy()
    V[idx] = (old * q.oracle_rays + free * rays) / (q.oracle_rays + rays)
    vis[idx] = visibility_types(V[idx], partial | ((V[idx] > 0) & (V[idx] < 1)))
    return LinkSet(r, s, links.F, V, vis, links.spread, links.F_points)


def _spread_within(h: Hierarchy, links: LinkSet, b_elem, rho_max, aggregate=False):
    """Estimated radiosity variation across each element, leaves included.

    A leaf's radiosity is one number, but as a source it stands for a surface whose radiosity
    varies by about rho * sum over its incoming links of B_s * spread(F): the same quantity the
    receiver side of the oracle bounds.  An element also inherits half of its parent's variation
    (a linear variation halves with the size).
    """
    if aggregate and links.F_points is not None:
        # the variation of the sum (see _oracle): shares that vary against each other cancel
        own = rho_max[h.view("patch")] * _gathered_variation(h, links, b_elem)
    else:
        own = np.bincount(links.receiver, rho_max[h.patch[links.receiver]]
                          * b_elem[links.source] * links.spread * links.V, h.n)
    total = own.copy()
    level = h.view("level")
    for lvl in range(1, int(level.max(initial=0)) + 1):
        ids = np.flatnonzero(level == lvl)
        total[ids] += 0.5 * total[h.parent[ids]]
    return total


def _spread_over_leaves(h: Hierarchy, system: LeafSystem, b_leaf):
    """max - min of the leaf values under every element."""
    pos, anc = h.ancestor_pairs(system.leaves)
    hi = np.full(h.n, -np.inf)
    lo = np.full(h.n, np.inf)
    np.maximum.at(hi, anc, b_leaf[pos])
    np.minimum.at(lo, anc, b_leaf[pos])
    return np.where(np.isfinite(hi), hi - lo, 0.0)


def solve_radiosity(scene: SceneData, quality="high", occluder="auto", solver=None, seed=0,
                    progress=None, light_occluder=None, light_lift=0.0) -> RadiositySolution:
    """Refine links with the BF/BFV oracle, compute accurate F and V, solve one basis per lamp.

    occluder: "auto" (Embree, else mathutils), None (no visibility: convex scenes, tests), or an
    object with ``segments_occluded(origins, ends)``.  progress(fraction, message) may raise
    Cancelled (or return False) to stop.  ``light_occluder``: what the leaves' light from
    ``scene.lights`` is cast against instead (a proxy's full mesh), from ``light_lift`` above
    them.

    Its phases: linking (the hierarchy, the first links, clusters: ``_initial_links``), the
    oracle's refinement (``_refine``), the final links' form factors and visibility
    (``_final_links``), the leaf system they gather with (``_gathering``: conserved rows,
    exposure, the lights' direct light), and the per-lamp solve.
    """
    with reporting(progress):
        return _solve_radiosity(scene, quality, occluder, solver, seed, light_occluder,
                                light_lift)


def _solve_radiosity(scene, quality, occluder, solver, seed, light_occluder, light_lift):
    q = get_preset(quality)
    scene.validate_for_solve()
    rng = np.random.default_rng(seed)
    timer = _Timer()
    report(0.0, "Linking the surfaces", 0.05)
    with timer("setup"):
        start = _initial_links(scene, q, occluder, rng)
    h, occluder, scale, contacts = start.h, start.occluder, start.scale, start.contacts
    kept, b_est, b_scale = _refine(scene, q, start, rng, timer)

    report(0.7, f"Light between {kept.n:,} pairs of surface pieces", 0.9)
    receiver, source = kept.receiver, kept.source
    spread_links = _unresolved_shadows(h, kept, b_est, b_scale, start.rho_max, q,
                                       start.min_area, occluder, seed, scale, timer, contacts)
    del kept                            # the oracle's estimates: 77 B a link
    give_back_memory()
    with timer("final_links"):
        links, gather = _final_links(h, receiver, source, occluder, q, rng, scale, spread_links,
                                     contacts, timer)
    lamp_occluder = occluder if light_occluder is None else _CountingOccluder(light_occluder)
    system, gather, light_occ, light_unocc = _gathering(
        h, gather, start.clusters, occluder, seed, scale, scene, q, lamp_occluder, light_lift,
        rng, timer)
    report(0.9, "Solving the light of each lamp", 1.0)
    with timer("solve"):
        E = _lamp_emission(scene, system, light_occ)
        basis, info = system.solve(E, solver or q.solver, tol=q.tol)
    report(1.0, "Done")
    rays = occluder.rays if occluder is not None else 0
    if lamp_occluder is not occluder:            # the lights cast against another mesh
        rays += lamp_occluder.rays
    counts = {"rays": rays, "cluster_links": len(start.clusters[1])}
    context = {"occluder": occluder, "scale": scale, "clusters": start.clusters,
               "light_occluder": lamp_occluder, "light_lift": light_lift, "contacts": contacts,
               "spread_links": spread_links}
    return RadiositySolution(scene, q, h, links, system, gather, np.moveaxis(basis, 2, 0), info,
                             light_occ, light_unocc, np.ones(scene.n_lamps), dict(timer),
                             counts, context)


@dataclass
class _Start:
    """What the refinement starts from (``_initial_links``)."""
    h: Hierarchy                # split at the contact lines
    occluder: object            # counting the rays it casts (None: no visibility)
    scale: float                # the scene's bounding diagonal
    min_area: float             # the smallest element's area
    contacts: tuple | None      # contact_segments, where the preset uses them
    clusters: tuple             # (tree, cX, cY, cV): the cluster links of a large scene
    r0: np.ndarray              # the first links, receiver and source
    s0: np.ndarray
    rho_max: np.ndarray         # per patch, the brightest channel's reflectance and emission
    e_max: np.ndarray


def _initial_links(scene, q: Quality, occluder, rng) -> _Start:
    """The hierarchy, split at the contact lines, and the first links: patch to patch, or
    between clusters of patches (and every lamp patch to every patch) in a large scene."""
    scale = bounding_diagonal(scene.corners)
    if occluder == "auto":
        occluder = scene.make_occluder()
    if occluder is not None:
        occluder = _CountingOccluder(occluder)
    h = Hierarchy(scene)
    total_area = float(h.view("area").sum())
    min_area = q.min_area * total_area
    contacts = contact_segments(scene, scale) if q.contact_levels > 0 or q.jitter_origins \
        else None
    if q.contact_levels > 0:
        split_at_contacts(h, *contacts, min_area / 4 ** q.contact_levels)
    if q.gap_levels > 0:
        split_at_contacts(h, *contact_segments(scene, scale, gaps=True),
                          min_area / 4 ** q.gap_levels)
    rho_max = scene.rho.max(axis=1)
    e_max = scene.emission.max(axis=1)
    receives = rho_max > 0
    sends = (rho_max > 0) | (e_max > 0)
    tree = None
    cX = cY = np.zeros(0, np.int64)
    if scene.n_patches > q.cluster_above:
        # Far groups of patches exchange light through cluster links: no O(P^2) start.
        # The lamps stay out of the clusters: a cluster link carries one visibility for
        # all its leaves, which the direct light's shadows cannot afford, and the lamps'
        # links to every patch are few (lamp patches x patches) and refined as usual.
        is_lamp = scene.lamp >= 0
        if is_lamp.sum() > LAMP_PATCHES_MAX or is_lamp.all():
            is_lamp = np.zeros_like(is_lamp)      # (a lamp of many faces: clustered too)
        tree = build_cluster_tree(scene.corners, np.flatnonzero(~is_lamp))
        cX, cY, cV, r0, s0 = link_clusters(
            tree, q.separation,
            lambda X, Y: cluster_visibility(tree, h, X, Y, occluder, q.rays, rng, scale))
        lr, ls = initial_pairs(h, receives & ~is_lamp, sends & is_lamp, scale)
        mr, ms = initial_pairs(h, receives & is_lamp, sends, scale)
        r0, s0 = np.concatenate([r0, lr, mr]), np.concatenate([s0, ls, ms])
        keep = receives[r0] & sends[s0]
        r0, s0 = r0[keep], s0[keep]
        keep = facing(h, r0, s0, scale)
        r0, s0 = r0[keep], s0[keep]
    else:
        r0, s0 = initial_pairs(h, receives, sends, scale)
        cV = np.ones(0)
    return _Start(h, occluder, scale, min_area, contacts, (tree, cX, cY, cV), r0, s0, rho_max,
                  e_max)


def _refine(scene, q: Quality, start: _Start, rng, timer):
    """The oracle's passes: links refined on a radiosity estimate solved on their own
    estimates, then on the refined links' (q.passes).  Returns the kept links, and the last
    estimate's per-element radiosity and brightness scale."""
    h, occluder, scale, min_area, rho_max = (start.h, start.occluder, start.scale,
                                             start.min_area, start.rho_max)
    lights = _LightEstimates(scene, h, occluder, q.oracle_rays, rng, scale) \
        if len(scene.lights) else None

    # Start from the patch-to-patch links and a first solution on them.
    with timer("refine"):
        F, spread, free, partial, Fp = oracle_estimates(h, start.r0, start.s0, occluder,
                                                        q.oracle_rays, rng, scale, timer)
    kept = LinkSet(start.r0, start.s0, F, free, visibility_types(free, partial), spread, Fp)
    start.r0 = start.s0 = None                     # (kept holds them: freed with it)
    del F, spread, free, partial, Fp
    with timer("solve"):
        b_est, b_var, b_scale = _estimate_radiosity(scene, q, start, lights, kept)
    fresh_r = fresh_s = np.zeros(0, np.int64)
    for pass_no in range(q.passes):
        report(0.05 + 0.6 * pass_no / q.passes,
               f"Refining where the light changes (pass {pass_no + 1} of {q.passes})",
               0.05 + 0.6 * (pass_no + 1) / q.passes)
        changed = False
        pending, kept = kept, None         # one copy of the links at a time (GBs on the office)
        kept_parts = []
        for round_no in range(MAX_REFINE_ROUNDS):
            # (rounds shrink as the links settle: about half the pass is done after 3)
            tick(1.0 - 0.5 ** (round_no / 3.0))
            if len(fresh_r):
                with timer("refine"):
                    F, spread, free, partial, Fp = oracle_estimates(
                        h, fresh_r, fresh_s, occluder, q.oracle_rays, rng, scale, timer)
                vis = visibility_types(free, partial)
                pending = LinkSet.concat([pending, LinkSet(fresh_r, fresh_s, F, free, vis, spread,
                                                           Fp)])
            if pending.n == 0:
                break
            with timer("refine"):
                pending = _confirm_visibility(h, pending, b_est, b_scale, rho_max, q, min_area,
                                              occluder, rng, scale, timer)
                split_r, split_s = _oracle(h, pending, b_est, b_var, b_scale, rho_max, q, min_area)
                kept_parts.append(pending.take(~(split_r | split_s)))
                if not (split_r.any() or split_s.any()):
                    fresh_r = fresh_s = np.zeros(0, np.int64)
                    break
                changed = True
                fresh_r, fresh_s, b_est, b_var = _split_links(h, pending, split_r, split_s,
                                                              b_est, b_var, scale)
                pending = LinkSet.empty()
        kept = LinkSet.concat(kept_parts)
        kept_parts = pending = None
        if pass_no + 1 == q.passes or not changed:
            break
        with timer("solve"):
            b_est, b_var, b_scale = _estimate_radiosity(scene, q, start, lights, kept)
    return kept, b_est, b_scale


def _split_links(h, links: LinkSet, split_r, split_s, b_est, b_var, scale):
    """Split the receivers ``split_r`` and sources ``split_s`` (bool per link) that the oracle
    chose: the new links from each split side's children, facing each other, and the
    estimates extended to the new elements (their parent's)."""
    r, s = links.receiver, links.source
    old_n = h.n
    fc_r = h.split(r[split_r])
    fc_s = h.split(s[split_s])
    parent = h.parent[old_n:h.n]
    b_est = np.concatenate([b_est, b_est[parent]])
    b_var = np.concatenate([b_var, b_var[parent]])
    four = np.arange(4)
    nr = np.concatenate([(fc_r[:, None] + four).ravel(), np.repeat(r[split_s], 4)])
    ns = np.concatenate([np.repeat(s[split_r], 4), (fc_s[:, None] + four).ravel()])
    ok = facing(h, nr, ns, scale)
    return nr[ok], ns[ok], b_est, b_var


def _estimate_radiosity(scene, q: Quality, start: _Start, lights, links: LinkSet):
    """Solve on the oracle's estimates: per element, the radiosity estimate (brightest
    channel), its variation over the element's leaves (the error of gathering from the
    element's mean radiosity), and the brightness the thresholds are relative to."""
    h, rho_max = start.h, start.rho_max
    tree, cX, cY, cV = start.clusters
    system = LeafSystem.from_links(h, links.receiver, links.source, links.F * links.V,
                                   scene.rho)
    if len(cX):
        system.add_clusters(*cluster_operator(tree, h, system.leaves, cX, cY, cV))
    E = scene.emission[system.patch]
    if lights is not None:
        light_mean, light_spread = lights.get(system.leaves)
        E = E + system.rho * light_mean
    B, _ = system.solve(E, "gmres", tol=1e-4)
    b_leaf = B.max(axis=1)
    b_elem = system.P_up @ b_leaf
    # (B - E: the reflected part of every leaf, emitters' included: in a furnace where
    # every face emits, the emission alone would make the thresholds 1 / (1 - rho) too fine)
    reflected = (B - scene.emission[system.patch]).max(axis=1)
    spread = np.maximum(_spread_over_leaves(h, system, b_leaf),
                        _spread_within(h, links, b_elem, rho_max, q.aggregate))
    if lights is not None:          # a leaf's own light varies across it
        spread[system.leaves] = np.maximum(spread[system.leaves],
                                           rho_max[system.patch] * light_spread)
    b_scale = _bright_level(reflected, system.leaf_area)
    if b_scale <= 0:
        b_scale = float(start.e_max.max())
    return b_elem, spread, max(b_scale, 1e-300)


def _final_links(h, receiver, source, occluder, q: Quality, rng, scale, spread_links, contacts,
                 timer=no_timer):
    """The links' final form factors and visibility (final_links.py) as the preset asks for
    them, their leaf entries split over near sources' children (source_split.py): (LinkSet,
    LeafGather)."""
    F, V, vis, gather = final_form_factors(h, receiver, source, occluder,
                                           q.quadrature, q.rays, rng, scale, with_leaves=True,
                                           timer=timer, ff_m=q.ff_quadrature,
                                           jitter=q.jitter_origins,
                                           partial_rays=q.partial_rays,
                                           spread_links=spread_links,
                                           spread_rays=q.spread_rays,
                                           partial_point_rays=q.partial_point_rays,
                                           fixed=_fixed_origin_leaves(h, contacts, q))
    give_back_memory()          # the form factors' threads' freed arrays (memory.py)
    split_sources(h, gather, q.quadrature, q.split_near, q.split_levels)
    give_back_memory()
    return LinkSet(receiver, source, F, V, vis), gather


def _gathering(h, gather, clusters, occluder, seed, scale, scene, q: Quality, lamp_occluder,
               light_lift, rng, timer=no_timer):
    """The leaf system the final links gather with (conserved rows, then the exposure of
    leaves under touching objects) and the lights' direct light on its leaves: (system,
    GatherRows, light_occ, light_unocc)."""
    with timer("conserve"):
        system, gather = _final_system(h, gather, clusters, occluder, seed, scale, scene,
                                       q.quadrature)
    tick()
    with timer("exposure"):
        _expose(h, system, gather, occluder, seed, scale, scene, q)
    tick()
    with timer("lights"):
        light_occ, light_unocc = lights_on_elements(scene, h, system.leaves, lamp_occluder,
                                                    q.quadrature, q.rays,
                                                    int(rng.integers(2**31)), scale, light_lift)
    return system, gather, light_occ, light_unocc


def regather(solution: RadiositySolution, seed=0, rho_leaf=None, emission_scale=None):
    """Recompute the leaf gather after leaves were split outside the oracle (texture-based
    refinement), keeping the links, and solve the per-lamp basis again.

    rho_leaf (L, 3): per-leaf reflectance (default: the patch's); emission_scale (k,): factor on
    each lamp's exitance.  Updates ``solution`` in place and returns it.
    """
    h, q, ctx = solution.hierarchy, solution.quality, solution.context
    rng = np.random.default_rng(seed)
    links = solution.links
    occluder, scale = ctx.get("occluder"), ctx.get("scale", 1.0)
    solution.links, gather = _final_links(h, links.receiver, links.source, occluder, q, rng,
                                          scale, ctx.get("spread_links"), ctx.get("contacts"))
    lamp_occluder, lift = solution.lamp_view()
    (solution.system, solution.gather, solution.light_occ,
     solution.light_unocc) = _gathering(h, gather, ctx.get("clusters", (None, (), (), ())),
                                        occluder, seed, scale, solution.scene, q, lamp_occluder,
                                        lift, rng)
    solve_basis(solution, rho_leaf, emission_scale)
    return solution


def _final_system(h, gather, clusters, occluder, seed, scale, scene, m):
    """The leaf system of the final form factors: rows conserved, then stored once (gather_rows:
    the solver's matrix shares their arrays).  Returns (system, GatherRows); empties ``gather``."""
    leaves = h.leaves()
    tree, cX, cY, cV = clusters
    # the cluster links' factors are built once the entries are rows: conserve needs only
    # their row sums, and the factors held beside the entries made the office's peak
    cluster_gather = partial(cluster_transport, tree, h, leaves, cX, cY, cV) if len(cX) else None
    _conserve(h, leaves, cluster_gather, gather, occluder, seed, scale, scene, m)
    rows = GatherRows.from_entries(leaves, gather, h.n)
    give_back_memory()
    system = LeafSystem.from_rows(h, rows, scene.rho)
    if len(cX):
        system.add_clusters(*cluster_operator(tree, h, leaves, cX, cY, cV))
    return system, rows


def _conserve(h, leaves, cluster_gather, gather, occluder, seed, scale, scene, m):
    """No leaf gathers more than the part of its hemisphere that sees sources (conserve.py).
    Needs a ray caster that knows its triangles' patches (``SceneData.make_occluder``).  ``m``:
    the quadrature of the leaves ``gather.near`` marks; the others gather at their centre."""
    if occluder is None or getattr(occluder, "patch_of_triangle", None) is None:
        return
    rng = np.random.default_rng([int(seed), 0xC0E5])      # its own stream: the rest is unchanged
    backs = back_copies(scene)
    at_centre = np.ones(len(leaves), bool) if gather.near is None or m <= 1 \
        else ~gather.near[leaves]
    front, back = hemisphere_coverage(h, leaves, occluder, scene, COVERAGE_RAYS, rng, scale,
                                      backs, at_centre)
    counted = scene.occluder.copy()
    counted[backs[backs >= 0]] = True
    conserve_rows(leaves, cluster_gather, gather, front, back, COVERAGE_RAYS, counted, h.patch)


def _fixed_origin_leaves(h, contacts, q):
    """The leaves a contact line crosses, whose rays stay on their points when the others'
    origins spread (None without spread origins or contact lines)."""
    if contacts is None or not (q.jitter_origins or q.spread_rays):
        return None
    return crossed_leaves(h, *contacts)


def _unresolved_shadows(h, links: LinkSet, b_est, b_scale, rho_max, q: Quality, min_area,
                        occluder, seed, scale, timer, contacts):
    """(n,) bool: the links whose near pairs cast ``q.spread_rays`` rays a leaf from spots
    spread over it (final_links.final_form_factors; None when the preset has none): bright enough
    for the BFV criterion (_oracle's ``shadow``), close to their receiver, whose area leaves no
    room to refine a shadow, and partly visible to the oracle's rays, or to confirm_rays x
    as many more where those all agreed (like _confirm_visibility's, which skips such links:
    8 rays saw all of a reflector's partner free on two seeds of three).  There a few fixed
    points judge a visibility that varies across the leaf: RenderPark's classroom's
    reflectors, one leaf each at medium, read their partner, a sixth of it hidden by the tube
    between them, 20 % bright (no ray from the four points met the tube).
    Not with fixed points and no contact lines (a proxy's solve): a leaf partly under an
    object standing on it, whose exposure is judged on its points (radiosity.exposure), is
    not told apart there (the clutter furnace's box on the floor, medium without contact
    lines: its straddling leaves 9.6 % off, 7.6 % with fixed points)."""
    if not q.spread_rays or links.n == 0 or occluder is None \
            or (contacts is None and not q.jitter_origins):
        return None
    r, s = links.receiver, links.source
    spread = ((rho_max[h.patch[r]] * b_est[s] * links.F > q.eps_bfv * b_scale)
              & (h.area[r] / 4 < SHADOW_AREA_FACTOR * min_area)
              & close_pairs(h, h.radius(), r, s))
    check = np.flatnonzero(spread & (links.vis != PARTIAL))
    spread &= links.vis == PARTIAL
    if len(check) and q.confirm_rays > 0:
        rng = np.random.default_rng([int(seed), 0x5B4E])   # its own stream: the rest unchanged
        _, _, _, partial, _ = oracle_estimates(h, r[check], s[check], occluder,
                                               q.confirm_rays * q.oracle_rays, rng, scale, timer)
        spread[check] = partial
    return spread


def _expose(h, system, gather, occluder, seed, scale, scene, q):
    """Leaves partly under a touching object are sources at their exposed part's radiosity
    (exposure.py)."""
    rng = np.random.default_rng([int(seed), 0xE905])      # its own stream: the rest is unchanged
    system.set_exposure(h, leaf_exposure(h, system.leaves, gather.near, occluder, scene,
                                         q.quadrature, rng, scale))


def solve_basis(solution: RadiositySolution, rho_leaf=None, emission_scale=None):
    """Solve the per-lamp basis again on the current leaf system, with optional per-leaf
    reflectances and per-lamp exitance factors (links and form factors unchanged)."""
    system = solution.system
    if rho_leaf is not None:
        system.rho = np.asarray(rho_leaf, float)
    scale = np.ones(solution.scene.n_lamps) if emission_scale is None else \
        np.asarray(emission_scale, float).copy()
    E = _lamp_emission(solution.scene, system, solution.light_occ)
    basis, info = system.solve(E * scale[None, None, :], solution.quality.solver,
                               tol=solution.quality.tol)
    solution.basis = np.moveaxis(basis, 2, 0)
    solution.info = info
    solution.emission_scale = scale
    return solution
