"""Links between elements: initial linking, the BF/BFV refinement oracle, final form factors.

A link (r, s) carries light from source element s to receiver element r.  ``F`` is the
unoccluded form factor F_rs (receiver-area average), ``V`` the visibility attenuation in [0, 1]
so that the transport factor is F * V, and ``vis`` the type VISIBLE / PARTIAL / INVISIBLE.

Final form factors use a nested quadrature: a link's receiver is integrated over the Gauss
points of all its leaf descendants.  In a closed scene the exact point-to-polygon values at each
point sum to one over any partition of the sources, so energy is conserved whatever the link
levels; a leaf's far sources are read at its centre (within ~1 % of their mean over it), and
the rows of closed views are then made exactly one (radiosity.conserve).
"""
from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from contextlib import nullcontext
from dataclasses import dataclass

import numpy as np

from ..geometry.formfactor import point_kernel, point_to_polygon
from ..geometry.patch import bilinear_point
from ..geometry.raycast import ray_offset
from ..geometry.sampling import (R2, area_uniform_uv, gauss_cells, jacobian_coefficients,
                                 quadrature, stratified_unit_square)
from .hierarchy import Hierarchy
from .memory import give_back_memory, growable, resized

VISIBLE, PARTIAL, INVISIBLE = 0, 1, 2

# Oracle sample points on the receiver (parameter space): centre and near the corners, where F
# peaks.  Not on them: a corner point lies in the plane of a face that meets the receiver there,
# whose form factor from it is then 0 instead of its share (in a closed cube the oracle saw rows
# summing to about 0.4, estimated B at rho 0.99 60x too low, and refined the walls to the
# minimum element: 1.5 M links at medium for a uniform furnace, 30 now).
_ORACLE_UV = np.array([[0.5, 0.5], [0.05, 0.05], [0.95, 0.05], [0.95, 0.95], [0.05, 0.95]])
# Points closer than this fraction of the scene size to a plane count as on it.
_PLANE_TOL = 1e-9
# A (leaf, source) pair uses one quadrature point when the leaf's radius is below this fraction
# of its gap to the source (A_r F_rs = A_s F_sr then holds to about 1 % at the 95th percentile).
_FAR_RATIO = 0.15
# A near leaf's pair takes its form factor at the leaf's centre when the leaf's radius is below
# this fraction of its gap to the source (the centre's error is of order (radius / gap)^2).
# RenderPark's office at medium vs Mitsuba: 0.05 leaves every patch within 0.01 % of all points
# (final form factors 12 % faster); 0.15, the far leaves' rule, put the worst 5.1 -> 5.5 %.
_CENTRE_RATIO = 0.05
# a source with a corner this close to a leaf's plane (x the leaf's size) touches it
_TOUCHING = 1e-3
# A source that hovers over a leaf's plane (its nearest corner within _HOVER_HEIGHT x the
# leaf's radius, not touching) while the leaf's radius exceeds _HOVER_GAP x its gap to it (a
# reflector strip 3 cm from a fluorescent tube) varies on a scale the 3 x 3 points do not
# resolve: that pair's form factors are taken on _HOVER_FACTOR x as many points a side.
# RenderPark's classroom at medium vs Mitsuba 3: the fixtures' reflectors +9.5-11.4 % ->
# +0.3-1.9 %, the 12 largest patches 1.18 / 2.52 -> 0.97 / 2.85 % (their light +1.5 % before),
# for no measurable time there and 132 -> 141 s on the office (1.63 / 5.95 -> 1.61 / 5.96 %).
# Per pair, not per leaf: all of a leaf's near pairs on 6 x 6 points cost the office 30 %.
# Such a leaf's row mixes two quadratures, so its unoccluded sum is not exactly 1 by
# construction; where its view is closed conserve.py sets the row to 1 all the same.
_HOVER_HEIGHT = 0.1
_HOVER_GAP = 2.0
_HOVER_FACTOR = 2
# A small source standing on the leaf's plane at its edge, rising from it (a fixture's end cap
# on its reflector, a baseboard beside a floor leaf), sends its light into a band along that
# edge about as wide as the source is tall: 3 x 3 points a side miss it (the classroom's
# reflectors took 54 % too little from their end caps at medium, 20-24 % at high, the top
# strips 60 %; one floor leaf from a 0.1-high strip along its edge 16 %).  Such a pair takes
# ceil(_CONTACT_POINTS x the leaf's diameter / the source centre's height) points a side, at
# most _CONTACT_MAX (16: within 0.2 % on those pairs).  A source rises when the cosine between
# its normal and the leaf's is below _CONTACT_RISE (20 degrees or more: a proxy's nearly
# coplanar neighbours do not).
_CONTACT_POINTS = 0.7
_CONTACT_MAX = 16
_CONTACT_RISE = 0.94
# Chunk sizes for the vectorised oracle (links) and final form factors (sample points).
_CHUNK_LINKS = 100_000
_PARALLEL_LINKS = 20_000
_THREADS = min(2, os.cpu_count() or 1)
_CHUNK_POINTS = 100_000
_RAY_BATCH = 1 << 17          # visibility rays traced at once in a chunk
# Kronecker steps of the ray origins within their Gauss cell (the last two of the R4 sequence,
# Roberts 2018: independent of R2's, which place the same rays' ends on the source)
_ORIGIN_STEP = (0.6287067210378086, 0.53859725722361)


@dataclass
class LinkSet:
    receiver: np.ndarray
    source: np.ndarray
    F: np.ndarray        # unoccluded form factor
    V: np.ndarray        # visibility attenuation
    vis: np.ndarray      # VISIBLE / PARTIAL / INVISIBLE
    spread: np.ndarray | None = None   # oracle only: variation of F over the receiver
    F_points: np.ndarray | None = None  # oracle only: (n, 5) F at the receiver's oracle points

    @property
    def n(self):
        return len(self.receiver)

    @staticmethod
    def empty():
        z = np.zeros(0)
        return LinkSet(np.zeros(0, np.int64), np.zeros(0, np.int64), z, z.copy(), np.zeros(0, np.int8),
                       z.copy(), np.zeros((0, len(_ORACLE_UV))))

    _FIELDS = ("receiver", "source", "F", "V", "vis", "spread", "F_points")

    def take(self, mask):
        return LinkSet(*(None if getattr(self, f) is None else getattr(self, f)[mask]
                         for f in self._FIELDS))

    @staticmethod
    def concat(parts):
        parts = [p for p in parts if p.n]
        if not parts:
            return LinkSet.empty()
        return LinkSet(*(None if any(getattr(p, f) is None for p in parts)
                         else np.concatenate([getattr(p, f) for p in parts])
                         for f in LinkSet._FIELDS))


def visibility_types(free, partial) -> np.ndarray:
    """VISIBLE / PARTIAL / INVISIBLE from a visible fraction and a partial flag per link."""
    return np.where(partial, PARTIAL, np.where(free == 0, INVISIBLE, VISIBLE)).astype(np.int8)


# pairs tested at a time: ~300 B of temporaries each (RenderPark's office: 2.6 GB at draft for
# its 2.5 M first links, when they were tested at once)
FACING_BLOCK = 1 << 18


def facing(h: Hierarchy, r: np.ndarray, s: np.ndarray, scale: float) -> np.ndarray:
    """Conservative test that s has some part in front of r and r some part in front of s."""
    tol = _PLANE_TOL * scale
    out = np.empty(len(r), bool)
    for a in range(0, len(r), FACING_BLOCK):
        rb, sb = r[a:a + FACING_BLOCK], s[a:a + FACING_BLOCK]
        s_front = np.einsum("nkj,nj->nk", h.corners[sb] - h.centroid[rb][:, None],
                            h.normal[rb]).max(axis=1)
        r_front = np.einsum("nkj,nj->nk", h.corners[rb] - h.centroid[sb][:, None],
                            h.normal[sb]).max(axis=1)
        out[a:a + FACING_BLOCK] = (s_front > tol) & (r_front > tol) & (h.patch[rb] != h.patch[sb])
    return out


def initial_pairs(h: Hierarchy, receives: np.ndarray, sends: np.ndarray, scale: float,
                  block: int = 2048):
    """All facing (receiver patch, source patch) pairs, generated in blocks to bound memory."""
    recv = np.flatnonzero(receives)
    send = np.flatnonzero(sends)
    rs, ss = [], []
    for start in range(0, len(recv), max(1, block * block // max(len(send), 1))):
        rb = recv[start:start + max(1, block * block // max(len(send), 1))]
        r = np.repeat(rb, len(send))
        s = np.tile(send, len(rb))
        ok = facing(h, r, s, scale)
        rs.append(r[ok])
        ss.append(s[ok])
    if not rs:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    return np.concatenate(rs), np.concatenate(ss)


def _no_timer(name):
    return nullcontext()


def oracle_estimates(h: Hierarchy, r, s, occluder, rays: int, rng, scale: float, timer=_no_timer):
    """Cheap per-link estimates used by the refinement oracle.

    Returns (F_est, F_spread, visible_fraction, partial, F_points): the mean and the max - min
    of the exact point-to-polygon form factor at five receiver points, visibility from ``rays``
    jittered segments between random points of the two elements, and the five values (n, 5).
    """
    n = len(r)
    if n > _CHUNK_LINKS or (n > _PARALLEL_LINKS and _THREADS > 1):
        # Chunks bound peak memory on large link sets and keep both cores busy (numpy and
        # Embree release the GIL); each chunk draws from its own random stream.
        size = min(_CHUNK_LINKS, -(-n // _THREADS))
        starts = range(0, n, size)
        seeds = rng.integers(0, 2**63 - 1, size=len(starts))
        jobs = [(slice(i, i + size), np.random.default_rng(int(sd))) for i, sd in zip(starts, seeds)]
        jac = jacobian_coefficients(h.view("corners"))      # per element, once for all chunks
        with ThreadPoolExecutor(_THREADS) as pool:
            parts = list(pool.map(lambda job: _oracle_chunk(
                h, r[job[0]], s[job[0]], occluder, rays, job[1], scale, timer, jac), jobs))
        return tuple(np.concatenate(p) for p in zip(*parts))
    return _oracle_chunk(h, r, s, occluder, rays, rng, scale, timer)


def _oracle_chunk(h: Hierarchy, r, s, occluder, rays: int, rng, scale: float, timer=_no_timer,
                  jac=None):
    """oracle_estimates on one chunk; ``jac``: jacobian_coefficients of every element."""
    n = len(r)
    if n == 0:
        z = np.zeros(0)
        return z, z.copy(), z.copy(), np.zeros(0, bool), np.zeros((0, len(_ORACLE_UV)))
    k = len(_ORACLE_UV)
    pts = bilinear_point(h.corners[r][:, None], _ORACLE_UV[None, :, 0], _ORACLE_UV[None, :, 1])
    with timer("form_factors"):
        F = point_to_polygon(pts.reshape(-1, 3), np.repeat(h.normal[r], k, axis=0),
                             np.repeat(h.corners[s], k, axis=0), np.repeat(h.normal[s], k, axis=0))
    F_points = F.reshape(n, k)
    spread = F_points.max(axis=1) - F_points.min(axis=1)
    F = F_points.mean(axis=1)
    if occluder is None or rays <= 0:
        return F, spread, np.ones(n), np.zeros(n, bool), F_points
    ur, vr = stratified_unit_square(n, rays, rng)
    us, vs = stratified_unit_square(n, rays, rng)
    if jac is None:
        jac = jacobian_coefficients(h.view("corners"))
    ur, vr = area_uniform_uv(None, ur, vr, tuple(j[r] for j in jac))
    us, vs = area_uniform_uv(None, us, vs, tuple(j[s] for j in jac))
    p = bilinear_point(h.corners[r][:, None], ur, vr)             # (n, rays, 3)
    q = bilinear_point(h.corners[s][:, None], us, vs)
    nr, ns = h.normal[r][:, None], h.normal[s][:, None]       # broadcast over the rays
    counts = _mutually_in_front(q - p, nr, ns)
    # lifted off their surfaces so that they do not hit their own element
    eps = ray_offset(scale)
    p, q = (p + eps * nr).reshape(-1, 3), (q + eps * ns).reshape(-1, 3)
    with timer("visibility"):
        blocked = occluder.segments_occluded(p, q).reshape(n, rays) & counts
    tried = counts.sum(axis=1)
    n_blocked = blocked.sum(axis=1)
    free = np.where(tried > 0, 1.0 - n_blocked / np.maximum(tried, 1), 1.0)
    partial = (n_blocked > 0) & (n_blocked < tried)
    return F, spread, free, partial, F_points


def _mutually_in_front(d, nr, ns):
    """Whether sample pairs (p on r, q on s, d = q - p; normals nr, ns broadcast against d's
    rows) can exchange light at all.

    F already clips each source to the part in front of the receiver point; a visibility ray to
    a source point behind that plane would only measure the clipping again (and hit the
    receiver's own object), so such samples are left out of the visible fraction."""
    return ((d[..., 0] * nr[..., 0] + d[..., 1] * nr[..., 1] + d[..., 2] * nr[..., 2] > 0)
            & (d[..., 0] * ns[..., 0] + d[..., 1] * ns[..., 1] + d[..., 2] * ns[..., 2] < 0))


def _segment_ranges(starts, counts):
    """Concatenation of ranges [start, start + count) (vectorised)."""
    total = int(counts.sum())
    if total == 0:
        return np.zeros(0, np.int64)
    offsets = np.cumsum(counts) - counts
    return np.repeat(starts - offsets, counts) + np.arange(total)


def visibility_estimated(F, FV):
    """Entries whose visibility was estimated by rays (conserve.conserve_rows rescales only
    those): partly hidden (F V below F beyond rounding), or gathered ray by ray (F = 0)."""
    return (FV > 0) & ((F == 0) | (FV < F * (1.0 - 1e-9)))


@dataclass
class LeafGather:
    """Leaf-level transport of a link set: for every (link, leaf under its receiver) pair, the
    leaf's own form factor to the link's source (unoccluded, and with visibility)."""
    leaf: np.ndarray       # leaf element id
    source: np.ndarray     # source element id (a source leaf for ray-level entries)
    # unoccluded, integrated over the leaf's own Gauss points; float32, as in the rows kept
    # (gather_rows): whether an entry's visibility was estimated is told by ``estimated``,
    # decided where F and F V are made in float64 (51 M entries on RenderPark's office at
    # medium: 3 B an entry less at the peak)
    F: np.ndarray
    FV: np.ndarray         # with visibility (sums of entries per leaf give its transport)
    # (h.n,) bool: the leaves integrated on their m x m Gauss points (the others at their centre)
    near: np.ndarray | None = None
    estimated: np.ndarray | None = None    # bool per entry: visibility_estimated(F, FV)

    def __post_init__(self):
        if self.estimated is None:
            self.estimated = visibility_estimated(np.asarray(self.F, float),
                                                  np.asarray(self.FV, float))
        self.F = np.asarray(self.F).astype(np.float32, copy=False)

    @classmethod
    def of(cls, leaf, source, F, FV, near=None):
        """Element ids in 4 bytes (51 M entries on RenderPark's office at medium)."""
        return cls(np.asarray(leaf).astype(np.int32, copy=False),
                   np.asarray(source).astype(np.int32, copy=False), F, FV, near)


def _finer_form_factors(h, f, w, pts, pts_w, normal, src):
    """The point form factors ``f`` (n, mm) (weights ``w``) of n (leaf, source) pairs scaled to
    their mean over the finer points ``pts`` (n, k, 3) (weights ``pts_w``).  Pairs that the m x m
    points do not see (f all 0) keep 0: their rays test nothing (a leaf under a box sees the
    box's sides from behind at its centre, from the front at its outer points).

    A source standing on the leaf's plane whose own plane crosses the leaf (a box's side over a
    floor leaf it straddles) keeps the m x m values: the fine points behind it are under the
    object, which the leaf's exposure (radiosity.exposure, judged on the m x m points) already
    takes out, and their zeros took it out twice (clutter furnace, box on the floor, no contact
    lines, medium with 3 x 3: leaves off by up to 7 % and straddling ones 23 % at rho 0.99).
    A source in the open crossing the leaf's plane (a fluorescent tube under the ceiling seen
    by a wall leaf that reaches above it) needs the fine points most: RenderPark's classroom
    at medium, walls 3-8 % dark at 2 x 2."""
    n, k = pts.shape[:2]
    fine = np.empty((n, k))
    step = max(1, _CHUNK_POINTS // (4 * k))    # the sources' corners repeated per point: 96 B
    for a in range(0, n, step):
        b = min(a + step, n)
        fine[a:b] = point_to_polygon(pts[a:b].reshape(-1, 3), np.repeat(normal[a:b], k, axis=0),
                                     np.repeat(h.corners[src[a:b]], k, axis=0),
                                     np.repeat(h.normal[src[a:b]], k, axis=0)).reshape(-1, k)
    F_fine = (fine * pts_w).sum(axis=1) / np.maximum(pts_w.sum(axis=1), 1e-300)
    F_m = (f * w).sum(axis=1) / np.maximum(w.sum(axis=1), 1e-300)
    ratio = np.where(F_m > 0, F_fine / np.where(F_m > 0, F_m, 1.0), 1.0)
    crossing = ~((fine > 0).all(axis=1) & (f > 0).all(axis=1))
    size = np.linalg.norm(pts.max(axis=1) - pts.min(axis=1), axis=1)
    height = np.einsum("nkj,nj->nk", h.corners[src] - pts[:, :1], normal)
    touching = np.abs(height).min(axis=1) <= _TOUCHING * size
    return f * np.where(crossing & touching, 1.0, ratio)[:, None]


def _heights(h, leaf, source):
    """(n, 4) heights of each source's corners over its leaf's plane."""
    return np.einsum("nkj,nj->nk", h.corners[source] - h.centroid[leaf][:, None], h.normal[leaf])


def _hovering(h, radius, leaf, source):
    """(n,) bool per (leaf, source) pair: the source is near the leaf (its radius above
    _HOVER_GAP x the gap) and comes closer to the leaf's plane than _HOVER_HEIGHT x the leaf's
    radius without touching it."""
    near = close_pairs(h, radius, leaf, source, _HOVER_GAP)
    lowest = np.abs(_heights(h, leaf[near], source[near])).min(axis=1)
    r = radius[leaf[near]]
    near[near] = (lowest > _TOUCHING * 2 * r) & (lowest < _HOVER_HEIGHT * r)
    return near


def _edge_contact_points(h, radius, leaf, source):
    """(n,) points a side per (leaf, source) pair: where the source touches the leaf's plane
    near the leaf, rises from it, and lies wholly in front of the leaf (its plane meets the leaf
    at an edge at most: a box side crossing the leaf is not one), the count its centre's height
    calls for (_CONTACT_POINTS); 0 elsewhere."""
    points = np.zeros(len(leaf), np.int64)
    near = np.flatnonzero(close_pairs(h, radius, leaf, source, 1.0))   # within the leaf's reach
    lf, src = leaf[near], source[near]
    r = radius[lf]
    height = _heights(h, lf, src)
    centre = np.einsum("nj,nj->n", h.centroid[src] - h.centroid[lf], h.normal[lf])
    side = _heights(h, src, lf)                 # the leaf's corners over the source's plane
    tol = _TOUCHING * 2 * r
    rises = np.abs(np.einsum("nj,nj->n", h.normal[lf], h.normal[src])) < _CONTACT_RISE
    standing = (np.abs(height).min(axis=1) <= tol) & rises & (side.min(axis=1) >= -tol) \
        & (centre > 0)
    k = np.ceil(_CONTACT_POINTS * 2 * r[standing] / centre[standing])
    points[near[standing]] = np.minimum(k, _CONTACT_MAX).astype(np.int64)
    return points


def close_pairs(h, radius, leaf, source, ratio=_FAR_RATIO):
    """(n,) bool per (leaf, source) pair: the leaf's radius is above ``ratio`` x its gap to the
    source (F varies over the leaf: it needs its quadrature points)."""
    gap = np.linalg.norm(h.centroid[leaf] - h.centroid[source], axis=1) - radius[source]
    return radius[leaf] > ratio * gap


def _pair_form_factors(h, P, lr, ls, link_of, leaf_ids, near_pairs, far_pairs, slot, mm,
                       radius, q_w, ff_pts, ff_w, hover_m=0):
    """Unoccluded form factors at a chunk's points ``P``: the m x m points of its near leaves'
    pairs (``near_pairs``, first), then the centres of its far leaves' pairs.  A near leaf's
    pair with a far source takes the value at the leaf's centre on all its points: F is smooth
    there, and on RenderPark's office 58 % of the pairs are such (a wall's leaves, near some
    source each, gathering from a small far one through one link).  With
    ``ff_pts`` the near pairs' values are their mean over those finer points, the pairs whose
    source hovers over the leaf (_hovering) over ``hover_m`` x ``hover_m`` points, those whose
    source stands on the leaf's edge over as many as it calls for (_edge_contact_points)."""
    nn = len(near_pairs) * mm
    pair_src, pair_recv = ls[link_of], lr[link_of]
    close = close_pairs(h, radius, leaf_ids[near_pairs], pair_src[near_pairs], _CENTRE_RATIO)
    on_points = near_pairs[close]                                # then one value a pair:
    at_centre = np.concatenate([near_pairs[~close], far_pairs])  # near leaves', far leaves'
    point_of = (np.flatnonzero(close)[:, None] * mm + np.arange(mm)).ravel()
    where = np.concatenate([P[point_of], h.centroid[leaf_ids[at_centre]]])
    src = np.concatenate([np.repeat(pair_src[on_points], mm), pair_src[at_centre]])
    recv = np.concatenate([np.repeat(pair_recv[on_points], mm), pair_recv[at_centre]])
    value = point_to_polygon(where, h.normal[recv], h.corners[src], h.normal[src])
    n_points = len(point_of)
    if n_points and ff_pts is not None:
        at = slot[close]
        on = value[:n_points].reshape(-1, mm)         # a view: the masks write into value
        # points a side per pair beyond the leaf's own finer points (0: those do)
        finer = _edge_contact_points(h, radius, leaf_ids[on_points], pair_src[on_points])
        finer[_hovering(h, radius, leaf_ids[on_points], pair_src[on_points])] = hover_m
        finer[finer * finer <= ff_pts.shape[1]] = 0
        for k in np.unique(finer):
            sel = finer == k
            pts, w = (ff_pts[at[sel]], ff_w[at[sel]]) if k == 0 else \
                quadrature(h.corners[leaf_ids[on_points[sel]]], int(k))
            on[sel] = _finer_form_factors(h, on[sel], q_w[at[sel]], pts, w,
                                          h.normal[pair_recv[on_points[sel]]],
                                          pair_src[on_points[sel]])
    f = np.empty(len(P))
    f_near = f[:nn].reshape(-1, mm)
    f_near[close] = value[:n_points].reshape(-1, mm)
    far_from = n_points + len(near_pairs) - len(on_points)      # the far leaves' values
    f_near[~close] = value[n_points:far_from, None]
    f[nn:] = value[far_from:]
    return f


def final_form_factors(h: Hierarchy, r, s, occluder, m: int, rays: int, rng, scale: float,
                       with_leaves: bool = False, timer=_no_timer, ff_m: int = 0,
                       jitter: bool = False, fixed=None, partial_rays: int = 0,
                       spread_links=None, spread_rays: int = 0):
    """Accurate F (unoccluded) and V per link by nested quadrature over the receiver's leaves.

    Each Gauss point of each leaf under the receiver gets the exact point-to-polygon form factor
    to the source and max(1, ceil(rays / points)) visibility rays to area-uniform source points.
    With ``ff_m`` > m, the form factors of a leaf near its sources are their mean over its
    ff_m x ff_m Gauss points (scaled onto its m x m points, whose rays still judge the
    visibility): one point on a leaf as large as its distance to the source errs by 20 %, and
    unlike the visibility the unoccluded form factor costs no rays.
    With ``jitter`` the rays of a near leaf's point leave from spots spread over the point's
    Gauss cell (the part of the leaf the point stands for) instead of from the point: a thin
    occluder close to the leaf (a fluorescent tube between two reflector strips 10 cm wide)
    hides a different part of the source from each spot, and a few fixed points see under it
    (RenderPark's classroom: the reflectors read their partner 19 % bright at 2 x 2 points).
    Without ``jitter``, the near leaves of the links ``spread_links`` (n,) bool alone are cast
    so; either way theirs take ``spread_rays`` rays a leaf at least: shadows the refinement
    could not resolve.
    Except on the leaves ``fixed`` (h.n,) bool: those crossed by a contact line, whose exposure
    (radiosity.exposure) is judged on the points, so their rays too must leave from there.
    With ``with_leaves`` also returns the per-leaf values (a LeafGather): gathering with them,
    instead of pushing the link's mean down, removes the receiver-side error of the hierarchy,
    at no extra cost since they are the same sums.
    """
    n = len(r)
    F = np.zeros(n)
    Fv = np.zeros(n)
    seen_free = np.zeros(n, bool)
    seen_blocked = np.zeros(n, bool)
    parts = []
    if n == 0:
        empty = LeafGather.of(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0), np.zeros(0))
        out = (F, np.ones(0), np.zeros(0, np.int8))
        return out + (empty,) if with_leaves else out

    leaves = h.leaves()
    pos, anc = h.ancestor_pairs(leaves)
    order = np.argsort(anc, kind="stable")
    anc_sorted = anc[order]
    leaf_of = leaves[pos[order]]                       # leaves grouped by ancestor id
    first = np.searchsorted(anc_sorted, np.arange(h.n))
    count = np.searchsorted(anc_sorted, np.arange(h.n), side="right") - first

    q_pts, q_w = quadrature(h.corners[leaves], m)      # (L, m*m, 3), (L, m*m)
    if ff_m > m:
        ff_pts, ff_w = quadrature(h.corners[leaves], ff_m)
    jac = jacobian_coefficients(h.view("corners"))     # per element, for area-uniform sampling
    # Bilinear map in power form, P = a + u (b - a) + v (d - a) + u v (a - b + c - d), its four
    # vectors side by side (a ray's source reads them in one gather)
    cs = h.view("corners")
    bilinear = np.stack([cs[:, 0], cs[:, 1] - cs[:, 0], cs[:, 3] - cs[:, 0],
                         cs[:, 0] - cs[:, 1] + cs[:, 2] - cs[:, 3]], axis=1)
    jac = np.stack(jac, axis=1)
    eps = ray_offset(scale)
    radius = h.radius()
    leaf_slot = np.full(h.n, -1, np.int64)
    leaf_slot[leaves] = np.arange(len(leaves))
    mm = m * m
    if spread_links is not None and not spread_links.any():
        spread_links = None
    if jitter or spread_links is not None:    # the Gauss cells along u and v: [lo, lo + width)
        lo, width = gauss_cells(m)

    pts_per_link = count[r] * mm
    # chunks of about equal rays: a spread link's points cast spread_rays / rays times as many
    # (kept whole, a chunk's free rays held RenderPark's classroom at high 430 MB over)
    work = pts_per_link.astype(float)
    if spread_links is not None and spread_rays > rays > 0:
        work[spread_links] *= spread_rays / rays
    link_chunks = np.split(np.arange(n), np.flatnonzero(np.diff(np.cumsum(work) // _CHUNK_POINTS)) + 1)

    # A leaf far from every source it gathers from (relative to its size) needs one point: F is
    # smooth there.  The leaf's points (and their rays) are the same for all its sources, so
    # that its visibility and exposure are judged where it gathers; a near leaf's far sources
    # take its form factor at its centre (below).
    leaf_near = np.zeros(h.n, bool)
    for links in link_chunks:
        lr, ls = r[links], s[links]
        leaf_ids = leaf_of[_segment_ranges(first[lr], count[lr])]
        leaf_near[leaf_ids[close_pairs(h, radius, leaf_ids, np.repeat(ls, count[lr]))]] = True

    # The (link, leaf) pairs' entries are written in place, chunk by chunk (each chunk's are a
    # known range): kept as chunks' arrays and joined they doubled the office's peak.  The rays'
    # entries of partly visible links (their count unknown ahead) are appended after them.
    pair_start = np.concatenate([[0], np.cumsum(count[r])])
    n_pair_entries = int(pair_start[-1]) if with_leaves else 0
    # (growable: the rays' entries and the source split grow these fields in place)
    gather = LeafGather(growable(n_pair_entries, np.int32), growable(n_pair_entries, np.int32),
                        growable(n_pair_entries, np.float32), growable(n_pair_entries, float),
                        leaf_near, growable(n_pair_entries, bool))

    def process(links, chunk_rng):
        """One chunk of links; writes its rows of F, Fv, seen_* and its pairs' gather entries,
        returns its rays' gather entries."""
        chunk_parts = []
        at = slice(pair_start[links[0]], pair_start[links[-1] + 1])
        lr, ls = r[links], s[links]
        nleaf = count[lr]
        leaf_ids = leaf_of[_segment_ranges(first[lr], nleaf)]           # per (link, leaf) pair
        link_of = np.repeat(np.arange(len(links)), nleaf)
        n_pairs = len(leaf_ids)
        near = leaf_near[leaf_ids]
        near_pairs = np.flatnonzero(near)
        far_pairs = np.flatnonzero(~near)
        slot = leaf_slot[leaf_ids[near_pairs]]
        P = np.concatenate([q_pts[slot].reshape(-1, 3), h.centroid[leaf_ids[far_pairs]]])
        W = np.concatenate([q_w[slot].reshape(-1), h.area[leaf_ids[far_pairs]]])
        pair_pt = np.concatenate([np.repeat(near_pairs, mm), far_pairs])
        link_pt = link_of[pair_pt]
        src = ls[link_pt]
        points_per_link = np.bincount(link_pt, minlength=len(links))
        spread = np.zeros(len(P), bool)     # points whose rays leave from over their cell
        if jitter or spread_links is not None:
            open_leaf = np.ones(len(near_pairs), bool) if fixed is None else \
                ~fixed[leaf_ids[near_pairs]]
            if not jitter:
                open_leaf &= spread_links[links][link_of[near_pairs]]
            spread[:len(near_pairs) * mm] = np.repeat(open_leaf, mm)
        with timer("form_factors"):
            f = _pair_form_factors(h, P, lr, ls, link_of, leaf_ids, near_pairs, far_pairs,
                                   slot, mm, radius, q_w, ff_pts if ff_m > m else None,
                                   ff_w if ff_m > m else None, _HOVER_FACTOR * ff_m)
        if occluder is None or rays <= 0:
            free_frac = np.ones(len(P))
        else:
            per_pt = np.maximum(1, -(-rays // np.maximum(points_per_link, 1)))  # ceil, per link
            ray_count = per_pt[link_pt]
            if spread_links is not None:
                boost = spread & spread_links[links][link_pt]
                ray_count[boost] = np.maximum(ray_count[boost], -(-spread_rays // mm))
            recv_of_pt = lr[link_pt]
            # The rays of one point follow an R2 low-discrepancy sequence with a random shift
            # (Cranley-Patterson), so few rays still cover the source evenly.
            shift = chunk_rng.random((len(P), 2))
            origin_shift = chunk_rng.random((len(P), 2)) if spread.any() else None
            tried = np.zeros(len(P))
            free_w = np.zeros(len(P))
            n_free = np.zeros(len(links))          # rays per link: free, blocked
            n_blocked = np.zeros(len(links))
            free_rays = []

            def cast(pts, ray_count, first):
                """Rays first .. first + ray_count - 1 of each point of ``pts``."""
                ray_end = np.cumsum(ray_count)
                ray_start = ray_end - ray_count
                # in batches of whole points' rays (bit for bit the same sums): a chunk's rays
                # and their ~250 B of temporaries each, in two threads, were the office's peak
                # at medium
                bounds = np.unique(np.searchsorted(ray_end, np.arange(0, ray_end[-1], _RAY_BATCH),
                                                   side="right"))
                for pt_a, pt_b in zip(bounds, list(bounds[1:]) + [len(pts)]):
                    at = np.repeat(np.arange(pt_a, pt_b), ray_count[pt_a:pt_b])
                    ray_pt = pts[at]
                    j = first[at] + np.arange(ray_start[pt_a], ray_end[pt_b - 1]) - ray_start[at]
                    trace(ray_pt, j)

            def trace(ray_pt, j):
                ray_src = src[ray_pt]
                xi_u = np.mod(j * R2[0] + shift[ray_pt, 0], 1.0)[:, None]
                xi_v = np.mod(j * R2[1] + shift[ray_pt, 1], 1.0)[:, None]
                u, v = area_uniform_uv(None, xi_u, xi_v, tuple(jac[ray_src].T))
                uu, vv = u[:, :1], v[:, :1]
                b = bilinear[ray_src]
                Q = b[:, 1] * uu                # a + u eu + v ev + u v tw, in place
                Q += b[:, 0]
                term = b[:, 2] * vv
                Q += term
                np.multiply(b[:, 3], uu * vv, out=term)
                Q += term
                b = term = None
                n_recv = h.normal[recv_of_pt[ray_pt]]
                n_src = h.normal[ray_src]
                Pr = P[ray_pt]
                moved = np.flatnonzero(spread[ray_pt])
                if len(moved):
                    rp, jm = ray_pt[moved], j[moved]
                    cu, cv = (rp % mm) % m, (rp % mm) // m
                    ou = lo[cu] + width[cu] * np.mod(jm * _ORIGIN_STEP[0] + origin_shift[rp, 0], 1.0)
                    ov = lo[cv] + width[cv] * np.mod(jm * _ORIGIN_STEP[1] + origin_shift[rp, 1], 1.0)
                    Pr[moved] = bilinear_point(h.corners[leaf_ids[near_pairs[rp // mm]]], ou, ov)
                kernel = point_kernel(n_recv, n_src, Q - Pr)
                counts = kernel > 0
                # lifted off their surfaces so as not to hit their own elements
                p0, q0 = Pr + eps * n_recv, Q + eps * n_src
                with timer("visibility"):
                    blocked = occluder.segments_occluded(p0, q0)
                free = counts & ~blocked
                blocked &= counts
                # Visible fraction weighted by the point-to-point kernel (a ratio estimator):
                # the area fraction alone is biased where the hidden part of the source is
                # nearer.
                tried[:] += np.bincount(ray_pt, kernel, len(P))
                free_w[:] += np.bincount(ray_pt, kernel * free, len(P))
                link_ray = link_pt[ray_pt]
                n_free[:] += np.bincount(link_ray, free, len(links))
                n_blocked[:] += np.bincount(link_ray, blocked, len(links))
                if with_leaves:
                    free_rays.append((ray_pt[free], kernel[free], u[free, 0], v[free, 0]))

            cast(np.arange(len(P)), ray_count, np.zeros(len(P), np.int64))
            if partial_rays > rays:
                # links whose rays were partly blocked: a shadow's edge crosses them, and their
                # visible fraction is the noisiest; they take partial_rays rays in all
                more = (n_blocked > 0) & (n_free > 0)
                extra = np.maximum(1, -(-partial_rays // np.maximum(points_per_link, 1)))[link_pt] \
                    - ray_count
                pts = np.flatnonzero(more[link_pt] & (extra > 0))
                if len(pts):
                    cast(pts, extra[pts], ray_count[pts])
            if spread.any():
                # one visible fraction per (leaf, source) pair: its rays leave from spots over
                # the whole leaf, so their kernel-weighted fraction is that of the integral of
                # F over the leaf, which the points' form factors give exactly (per cell it is
                # not: a Gauss point's weight is not its cell's share of that integral)
                pj = pair_pt[spread]
                tried[spread] = np.bincount(pj, tried[spread], n_pairs)[pj]
                free_w[spread] = np.bincount(pj, free_w[spread], n_pairs)[pj]
            free_frac = np.where(tried > 0, free_w / np.where(tried > 0, tried, 1.0), 1.0)
            seen_free[links] |= n_free > 0
            seen_blocked[links] |= n_blocked > 0
        wsum = np.bincount(link_pt, W, len(links))
        F[links] = np.bincount(link_pt, W * f, len(links)) / np.maximum(wsum, 1e-300)
        Fv[links] = np.bincount(link_pt, W * f * free_frac, len(links)) / np.maximum(wsum, 1e-300)
        if not with_leaves:
            return chunk_parts
        pw = np.maximum(np.bincount(pair_pt, W, n_pairs), 1e-300)
        pair_F = np.bincount(pair_pt, W * f, n_pairs) / pw
        if occluder is None or rays <= 0:
            gather.leaf[at], gather.source[at] = leaf_ids, ls[link_of]
            gather.F[at] = gather.FV[at] = pair_F
            gather.estimated[at] = False
            return chunk_parts
        # Partially visible links gather from the source leaf each free ray lands in, rather
        # than from the source's mean radiosity: a hidden part of a source is often dark too
        # (floor under a box), and the mean would count that darkness a second time.
        partial_link = (n_blocked > 0) & (n_free > 0)
        by_ray = partial_link[link_pt] & (tried > 0)
        pair_FV = np.bincount(pair_pt, np.where(by_ray, 0.0, W * f * free_frac), n_pairs) / pw
        gather.leaf[at], gather.source[at] = leaf_ids, ls[link_of]
        gather.F[at], gather.FV[at] = pair_F, pair_FV
        gather.estimated[at] = visibility_estimated(pair_F, pair_FV)
        ray_pt, kernel, u, v = (np.concatenate(c) for c in zip(*free_rays))
        use = by_ray[ray_pt]
        if use.any():
            rp = ray_pt[use]
            # a ray's share of its point's F V (of its pair's when the rays' origins spread)
            weight = np.where(spread[rp], pair_F[pair_pt[rp]] * kernel[use] / tried[rp],
                              W[rp] * f[rp] * kernel[use] / tried[rp] / pw[pair_pt[rp]])
            src_leaf = h.locate(src[rp], u[use], v[use])
            # summed per (leaf, source leaf) now, as the rows would (gather_rows): one entry a
            # free ray kept the classroom at high with 128 rays on partial links at 5.7 GB
            key, at_key = np.unique(leaf_ids[pair_pt[rp]].astype(np.int64) * h.n + src_leaf,
                                    return_inverse=True)
            chunk_parts.append(LeafGather.of(key // h.n, key % h.n, np.zeros(len(key)),
                                             np.bincount(at_key, weight, len(key))))
        return chunk_parts

    # Chunks are independent: numpy and Embree release the GIL, so two threads keep both cores
    # busy.  Each chunk has its own random stream, so results do not depend on scheduling.
    link_chunks = [c for c in link_chunks if len(c)]
    seeds = rng.integers(0, 2**63 - 1, size=len(link_chunks))
    jobs = [(c, np.random.default_rng(int(sd))) for c, sd in zip(link_chunks, seeds)]
    if len(jobs) > 1 and _THREADS > 1:
        with ThreadPoolExecutor(_THREADS) as pool:
            results = list(pool.map(lambda job: process(*job), jobs))
    else:
        results = [process(*job) for job in jobs]
    parts = [p for chunk in results for p in chunk]

    if occluder is None or rays <= 0:
        seen_free[:] = True
    V = np.where(F > 0, Fv / np.where(F > 0, F, 1.0), np.where(seen_blocked & ~seen_free, 0.0, 1.0))
    V = np.clip(V, 0.0, 1.0)
    vis = np.where(seen_blocked, np.where(seen_free, PARTIAL, INVISIBLE), VISIBLE).astype(np.int8)
    if not with_leaves:
        return F, V, vis
    # the rays' entries after the pairs', one field at a time, each grown in place (joined,
    # the office's 51 M entries were held twice while a field was copied)
    n_entries = n_pair_entries + sum(len(p.leaf) for p in parts)
    for key in ("leaf", "source", "F", "FV", "estimated"):
        field = resized(getattr(gather, key), n_entries)
        at = n_pair_entries
        for p in parts:
            part = getattr(p, key)
            field[at:at + len(part)] = part
            at += len(part)
            setattr(p, key, None)
        setattr(gather, key, field)
        give_back_memory()      # the parts' pages (small arrays, freed into the heap)
    return F, V, vis, gather
