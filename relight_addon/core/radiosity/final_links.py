# SPDX-License-Identifier: GPL-3.0-or-later
"""Final form factors and visibility of the refined links (links.py makes and refines them).

Final form factors use a nested quadrature: a link's receiver is integrated over the Gauss
points of all its leaf descendants.  In a closed scene the exact point-to-polygon values at each
point sum to one over any partition of the sources, so energy is conserved whatever the link
levels; a leaf's far sources are read at its centre (within ~1 % of their mean over it), and
the rows of closed views are then made exactly one (radiosity.conserve).
"""
from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from ..geometry.formfactor import point_kernel, point_to_polygon
from ..geometry.patch import bilinear_point
from ..geometry.raycast import ray_offset
from ..geometry.sampling import R2, area_uniform_uv, gauss_cells, jacobian_coefficients, quadrature
from ..numerics import nonzero, safe_div
from ..progress import chunked
from .hierarchy import Hierarchy
from .links import (INVISIBLE, PARTIAL, VISIBLE, LeafGather, close_pairs, no_timer,
                    segment_ranges, visibility_estimated)
from .memory import give_back_memory, growable, resized

# A near leaf's pair takes its form factor at the leaf's centre when the leaf's radius is below
# this fraction of its gap to the source (the centre's error is of order (radius / gap)^2)
_CENTRE_RATIO = 0.05
# a source with a corner this close to a leaf's plane (x the leaf's size) touches it
_TOUCHING = 1e-3
# A source hovering over a leaf's plane (nearest corner within _HOVER_HEIGHT x the leaf's
# radius, not touching) while the leaf's radius exceeds _HOVER_GAP x its gap varies on a
# scale the m x m points miss: that pair takes _HOVER_FACTOR x as many points a side (per
# pair: per leaf costs too much; conserve.py closes the row that mixes two quadratures)
_HOVER_HEIGHT = 0.1
_HOVER_GAP = 2.0
_HOVER_FACTOR = 2
# A small source standing on the leaf's plane at its edge, rising from it (an end cap, a
# baseboard), lights a band along that edge about as wide as it is tall: that pair takes
# ceil(_CONTACT_POINTS x the leaf's diameter / the source centre's height) points a side, at
# most _CONTACT_MAX; it rises when the cosine between the normals is below _CONTACT_RISE
_CONTACT_POINTS = 0.7
_CONTACT_MAX = 16
_CONTACT_RISE = 0.94
# Chunk sizes (sample points) and threads of the final form factors.
_CHUNK_POINTS = 100_000
_THREADS = min(2, os.cpu_count() or 1)
_RAY_BATCH = 1 << 17          # visibility rays traced at once in a chunk
# Kronecker steps of the ray origins within their Gauss cell (the last two of the R4 sequence,
# Roberts 2018: independent of R2's, which place the same rays' ends on the source)
_ORIGIN_STEP = (0.6287067210378086, 0.53859725722361)


def final_form_factors(h: Hierarchy, r, s, occluder, m: int, rays: int, rng, scale: float,
                       with_leaves: bool = False, timer=no_timer, ff_m: int = 0,
                       jitter: bool = False, fixed=None, partial_rays: int = 0,
                       spread_links=None, spread_rays: int = 0, partial_point_rays: int = 1):
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
    A link whose first rays were partly blocked takes ``partial_rays`` in all and at least
    ``partial_point_rays`` a point: a link of a large element spreads its rays over the points
    of all its leaves, one each, and a leaf in a shadow's penumbra then reads lit or dark from
    a single ray (the Cornell box's draft: a floor leaf in the tall box's shadow read 2.3x
    its light, and the box's side facing it 42 % too bright).
    Except on the leaves ``fixed`` (h.n,) bool: those crossed by a contact line, whose exposure
    (radiosity.exposure) is judged on the points, so their rays too must leave from there.
    With ``with_leaves`` also returns the per-leaf values (a LeafGather): gathering with them,
    instead of pushing the link's mean down, removes the receiver-side error of the hierarchy,
    at no extra cost since they are the same sums.

    Its phases: the leaves' quadrature (``_quadrature``), chunks of links of about equal work
    (``_link_chunks``), the leaves near a source (``_near_leaves``), then chunk by chunk on two
    threads (``_FinalLinks.chunk``) the points, their form factors, their visibility rays and
    the chunk's rows and leaf entries, last V, the visibility types and the rays' entries
    (``_FinalLinks.finish``).
    """
    n = len(r)
    if n == 0:
        empty = LeafGather.of(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0), np.zeros(0))
        out = (np.zeros(0), np.ones(0), np.zeros(0, np.int8))
        return out + (empty,) if with_leaves else out
    if spread_links is not None and not spread_links.any():
        spread_links = None
    quad = _quadrature(h, m, ff_m, scale, cells=jitter or spread_links is not None)
    link_chunks = _link_chunks(quad.count[r] * quad.mm, rays, spread_links, spread_rays)
    run = _FinalLinks(h, quad, r, s, occluder, rays, _near_leaves(h, quad, r, s, link_chunks),
                      with_leaves, timer, jitter, fixed, partial_rays, spread_links, spread_rays,
                      partial_point_rays)
    return run.finish(_run_chunks(run.chunk, link_chunks, rng))


@dataclass
class _Quadrature:
    """The leaves' side of the final links: the leaves under every element, their Gauss points,
    and the tables a ray's source point is read from."""
    leaf_of: np.ndarray       # leaves grouped by ancestor id
    first: np.ndarray         # (h.n,) where each element's leaves start in leaf_of
    count: np.ndarray         # (h.n,) and how many they are
    leaf_slot: np.ndarray     # (h.n,) a leaf's row in q_pts (-1: not a leaf)
    q_pts: np.ndarray         # (L, m*m, 3) Gauss points
    q_w: np.ndarray           # (L, m*m) their weights
    ff_pts: np.ndarray | None  # finer points for the form factors (ff_m > m), and weights
    ff_w: np.ndarray | None
    hover_m: int              # points a side of a hovering source's pairs
    jac: np.ndarray           # per element, for area-uniform sampling
    bilinear: np.ndarray      # per element, the bilinear map in power form
    radius: np.ndarray
    eps: float                # ray offset
    m: int
    mm: int
    lo: np.ndarray | None     # the Gauss cells along u and v: [lo, lo + width)
    width: np.ndarray | None


def _quadrature(h, m, ff_m, scale, cells) -> _Quadrature:
    """The leaves' quadrature (``cells``: with their Gauss cells, where rays leave from spots
    spread over them)."""
    leaves = h.leaves()
    pos, anc = h.ancestor_pairs(leaves)
    order = np.argsort(anc, kind="stable")
    anc_sorted = anc[order]
    leaf_of = leaves[pos[order]]                       # leaves grouped by ancestor id
    first = np.searchsorted(anc_sorted, np.arange(h.n))
    count = np.searchsorted(anc_sorted, np.arange(h.n), side="right") - first

    q_pts, q_w = quadrature(h.corners[leaves], m)      # (L, m*m, 3), (L, m*m)
    ff_pts = ff_w = None
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
    lo = width = None
    if cells:
        lo, width = gauss_cells(m)
    return _Quadrature(leaf_of, first, count, leaf_slot, q_pts, q_w, ff_pts, ff_w,
                       _HOVER_FACTOR * ff_m, jac, bilinear, radius, eps, m, m * m, lo, width)


def _link_chunks(points_per_link, rays, spread_links, spread_rays):
    """The links in chunks of about equal rays: a spread link's points cast spread_rays / rays
    times as many (kept whole, a chunk's free rays held RenderPark's classroom at high 430 MB
    over)."""
    work = points_per_link.astype(float)
    if spread_links is not None and spread_rays > rays > 0:
        work[spread_links] *= spread_rays / rays
    return np.split(np.arange(len(work)),
                    np.flatnonzero(np.diff(np.cumsum(work) // _CHUNK_POINTS)) + 1)


def _near_leaves(h, quad, r, s, link_chunks):
    """(h.n,) bool: the leaves near some source they gather from (relative to their size).

    A leaf far from every source needs one point: F is smooth there.  The leaf's points (and
    their rays) are the same for all its sources, so that its visibility and exposure are
    judged where it gathers; a near leaf's far sources take its form factor at its centre
    (_pair_form_factors)."""
    leaf_near = np.zeros(h.n, bool)
    for links in link_chunks:
        lr, ls = r[links], s[links]
        leaf_ids = quad.leaf_of[segment_ranges(quad.first[lr], quad.count[lr])]
        leaf_near[leaf_ids[close_pairs(h, quad.radius, leaf_ids,
                                       np.repeat(ls, quad.count[lr]))]] = True
    return leaf_near


def _run_chunks(process, link_chunks, rng):
    """``process(links, rng)`` of every chunk.  Chunks are independent: numpy and Embree release
    the GIL, so two threads keep both cores busy.  Each chunk has its own random stream, so
    results do not depend on scheduling."""
    link_chunks = [c for c in link_chunks if len(c)]
    seeds = rng.integers(0, 2**63 - 1, size=len(link_chunks))
    jobs = [(c, np.random.default_rng(int(sd))) for c, sd in zip(link_chunks, seeds)]
    return chunked(lambda job: process(*job), jobs, _THREADS)


@dataclass
class _Chunk:
    """A chunk of links and its sample points: the m x m Gauss points of its near (link, leaf)
    pairs, then the centres of its far ones."""
    links: np.ndarray
    at: slice                 # its pairs' range of the gather entries
    lr: np.ndarray            # receivers and sources of its links
    ls: np.ndarray
    leaf_ids: np.ndarray      # per (link, leaf) pair
    link_of: np.ndarray       # the pair's link (in the chunk)
    near_pairs: np.ndarray
    far_pairs: np.ndarray
    slot: np.ndarray          # the near pairs' leaves' quadrature rows
    P: np.ndarray             # the points, their weights, pair, link and source
    W: np.ndarray
    pair_pt: np.ndarray
    link_pt: np.ndarray
    src: np.ndarray
    points_per_link: np.ndarray
    spread: np.ndarray        # points whose rays leave from over their cell

    @property
    def n_pairs(self):
        return len(self.leaf_ids)


@dataclass
class _Rays:
    """A chunk's visibility rays as they are cast: per point the kernel-weighted rays tried and
    free, per link the rays free and blocked, and the free rays themselves (for the leaf
    entries of partly visible links)."""
    shift: np.ndarray
    origin_shift: np.ndarray | None
    recv_of_pt: np.ndarray
    tried: np.ndarray
    free_w: np.ndarray
    n_free: np.ndarray
    n_blocked: np.ndarray
    free_rays: list
    free_frac: np.ndarray | None = None


class _FinalLinks:
    """The final links' F, V and leaf entries, chunk by chunk."""

    def __init__(self, h, quad, r, s, occluder, rays, leaf_near, with_leaves, timer, jitter,
                 fixed, partial_rays, spread_links, spread_rays, partial_point_rays=1):
        self.h, self.quad, self.r, self.s, self.occluder, self.rays = h, quad, r, s, occluder, rays
        self.leaf_near, self.with_leaves, self.timer = leaf_near, with_leaves, timer
        self.jitter, self.fixed, self.partial_rays = jitter, fixed, partial_rays
        self.spread_links, self.spread_rays = spread_links, spread_rays
        self.partial_point_rays = max(1, int(partial_point_rays))
        n = len(r)
        self.F = np.zeros(n)
        self.Fv = np.zeros(n)
        self.seen_free = np.zeros(n, bool)
        self.seen_blocked = np.zeros(n, bool)
        # The (link, leaf) pairs' entries are written in place, chunk by chunk (each chunk's are
        # a known range): kept as chunks' arrays and joined they doubled the office's peak.  The
        # rays' entries of partly visible links (their count unknown ahead) are appended after.
        self.pair_start = np.concatenate([[0], np.cumsum(quad.count[r])])
        self.n_pair_entries = int(self.pair_start[-1]) if with_leaves else 0
        # (growable: the rays' entries and the source split grow these fields in place)
        k = self.n_pair_entries
        self.gather = LeafGather(growable(k, np.int32), growable(k, np.int32),
                                 growable(k, np.float32), growable(k, float), leaf_near,
                                 growable(k, bool))

    def chunk(self, links, chunk_rng):
        """One chunk of links; writes its rows of F, Fv, seen_* and its pairs' gather entries,
        returns its rays' gather entries."""
        q = self.quad
        c = self._points(links)
        with self.timer("form_factors"):
            f = _pair_form_factors(self.h, c.P, c.lr, c.ls, c.link_of, c.leaf_ids, c.near_pairs,
                                   c.far_pairs, c.slot, q.mm, q.radius, q.q_w, q.ff_pts, q.ff_w,
                                   q.hover_m)
        rays = None
        if self.occluder is None or self.rays <= 0:
            free_frac = np.ones(len(c.P))
        else:
            rays = self._visibility(c, chunk_rng)
            free_frac = rays.free_frac
            self.seen_free[links] |= rays.n_free > 0
            self.seen_blocked[links] |= rays.n_blocked > 0
        wsum = np.bincount(c.link_pt, c.W, len(links))
        self.F[links] = safe_div(np.bincount(c.link_pt, c.W * f, len(links)), wsum)
        self.Fv[links] = safe_div(np.bincount(c.link_pt, c.W * f * free_frac, len(links)), wsum)
        if not self.with_leaves:
            return []
        return self._leaf_entries(c, f, free_frac, rays)

    def _points(self, links) -> _Chunk:
        h, q = self.h, self.quad
        at = slice(self.pair_start[links[0]], self.pair_start[links[-1] + 1])
        lr, ls = self.r[links], self.s[links]
        nleaf = q.count[lr]
        leaf_ids = q.leaf_of[segment_ranges(q.first[lr], nleaf)]        # per (link, leaf) pair
        link_of = np.repeat(np.arange(len(links)), nleaf)
        near = self.leaf_near[leaf_ids]
        near_pairs = np.flatnonzero(near)
        far_pairs = np.flatnonzero(~near)
        slot = q.leaf_slot[leaf_ids[near_pairs]]
        P = np.concatenate([q.q_pts[slot].reshape(-1, 3), h.centroid[leaf_ids[far_pairs]]])
        W = np.concatenate([q.q_w[slot].reshape(-1), h.area[leaf_ids[far_pairs]]])
        pair_pt = np.concatenate([np.repeat(near_pairs, q.mm), far_pairs])
        link_pt = link_of[pair_pt]
        src = ls[link_pt]
        points_per_link = np.bincount(link_pt, minlength=len(links))
        spread = np.zeros(len(P), bool)     # points whose rays leave from over their cell
        if self.jitter or self.spread_links is not None:
            open_leaf = np.ones(len(near_pairs), bool) if self.fixed is None else \
                ~self.fixed[leaf_ids[near_pairs]]
            if not self.jitter:
                open_leaf &= self.spread_links[links][link_of[near_pairs]]
            spread[:len(near_pairs) * q.mm] = np.repeat(open_leaf, q.mm)
        return _Chunk(links, at, lr, ls, leaf_ids, link_of, near_pairs, far_pairs, slot, P, W,
                      pair_pt, link_pt, src, points_per_link, spread)

    def _visibility(self, c: _Chunk, chunk_rng) -> _Rays:
        """The chunk's visibility rays: max(1, ceil(rays / points)) a point (spread_rays a
        spread leaf at least), partial_rays on links whose rays were partly blocked."""
        mm = self.quad.mm
        per_pt = np.maximum(1, -(-self.rays // np.maximum(c.points_per_link, 1)))  # ceil, per link
        ray_count = per_pt[c.link_pt]
        if self.spread_links is not None:
            boost = c.spread & self.spread_links[c.links][c.link_pt]
            ray_count[boost] = np.maximum(ray_count[boost], -(-self.spread_rays // mm))
        recv_of_pt = c.lr[c.link_pt]
        # The rays of one point follow an R2 low-discrepancy sequence with a random shift
        # (Cranley-Patterson), so few rays still cover the source evenly.
        shift = chunk_rng.random((len(c.P), 2))
        origin_shift = chunk_rng.random((len(c.P), 2)) if c.spread.any() else None
        rays = _Rays(shift, origin_shift, recv_of_pt, np.zeros(len(c.P)), np.zeros(len(c.P)),
                     np.zeros(len(c.links)), np.zeros(len(c.links)), [])

        self._cast(c, rays, np.arange(len(c.P)), ray_count, np.zeros(len(c.P), np.int64))
        if self.partial_rays > self.rays or self.partial_point_rays > 1:
            # links whose rays were partly blocked: a shadow's edge crosses them, and their
            # visible fraction is the noisiest; they take partial_rays rays in all and
            # partial_point_rays a point at least
            more = (rays.n_blocked > 0) & (rays.n_free > 0)
            extra = np.maximum(self.partial_point_rays,
                               -(-self.partial_rays // np.maximum(c.points_per_link, 1))
                               )[c.link_pt] - ray_count
            pts = np.flatnonzero(more[c.link_pt] & (extra > 0))
            if len(pts):
                self._cast(c, rays, pts, extra[pts], ray_count[pts])
        tried, free_w, spread = rays.tried, rays.free_w, c.spread
        if spread.any():
            # one visible fraction per (leaf, source) pair: its rays leave from spots over
            # the whole leaf, so their kernel-weighted fraction is that of the integral of
            # F over the leaf, which the points' form factors give exactly (per cell it is
            # not: a Gauss point's weight is not its cell's share of that integral)
            pj = c.pair_pt[spread]
            tried[spread] = np.bincount(pj, tried[spread], c.n_pairs)[pj]
            free_w[spread] = np.bincount(pj, free_w[spread], c.n_pairs)[pj]
        rays.free_frac = np.where(tried > 0, free_w / np.where(tried > 0, tried, 1.0), 1.0)
        return rays

    def _cast(self, c: _Chunk, rays: _Rays, pts, ray_count, first):
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
            self._trace(c, rays, ray_pt, j)

    def _trace(self, c: _Chunk, rays: _Rays, ray_pt, j):
        """The rays ``j`` of the points ``ray_pt``: to area-uniform points of the source, each
        weighted by the point-to-point kernel."""
        h, q = self.h, self.quad
        m, mm, lo, width = q.m, q.mm, q.lo, q.width
        shift, origin_shift = rays.shift, rays.origin_shift
        ray_src = c.src[ray_pt]
        xi_u = np.mod(j * R2[0] + shift[ray_pt, 0], 1.0)[:, None]
        xi_v = np.mod(j * R2[1] + shift[ray_pt, 1], 1.0)[:, None]
        u, v = area_uniform_uv(None, xi_u, xi_v, tuple(q.jac[ray_src].T))
        uu, vv = u[:, :1], v[:, :1]
        b = q.bilinear[ray_src]
        Q = b[:, 1] * uu                # a + u eu + v ev + u v tw, in place
        Q += b[:, 0]
        term = b[:, 2] * vv
        Q += term
        np.multiply(b[:, 3], uu * vv, out=term)
        Q += term
        b = term = None
        n_recv = h.normal[rays.recv_of_pt[ray_pt]]
        n_src = h.normal[ray_src]
        Pr = c.P[ray_pt]
        moved = np.flatnonzero(c.spread[ray_pt])
        if len(moved):
            rp, jm = ray_pt[moved], j[moved]
            cu, cv = (rp % mm) % m, (rp % mm) // m
            ou = lo[cu] + width[cu] * np.mod(jm * _ORIGIN_STEP[0] + origin_shift[rp, 0], 1.0)
            ov = lo[cv] + width[cv] * np.mod(jm * _ORIGIN_STEP[1] + origin_shift[rp, 1], 1.0)
            Pr[moved] = bilinear_point(h.corners[c.leaf_ids[c.near_pairs[rp // mm]]], ou, ov)
        kernel = point_kernel(n_recv, n_src, Q - Pr)
        counts = kernel > 0
        # lifted off their surfaces so as not to hit their own elements
        p0, q0 = Pr + q.eps * n_recv, Q + q.eps * n_src
        with self.timer("visibility"):
            blocked = self.occluder.segments_occluded(p0, q0)
        free = counts & ~blocked
        blocked &= counts
        # Visible fraction weighted by the point-to-point kernel (a ratio estimator):
        # the area fraction alone is biased where the hidden part of the source is
        # nearer.
        n_points, n_links = len(c.P), len(c.links)
        rays.tried[:] += np.bincount(ray_pt, kernel, n_points)
        rays.free_w[:] += np.bincount(ray_pt, kernel * free, n_points)
        link_ray = c.link_pt[ray_pt]
        rays.n_free[:] += np.bincount(link_ray, free, n_links)
        rays.n_blocked[:] += np.bincount(link_ray, blocked, n_links)
        if self.with_leaves:
            rays.free_rays.append((ray_pt[free], kernel[free], u[free, 0], v[free, 0]))

    def _leaf_entries(self, c: _Chunk, f, free_frac, rays):
        """Writes the chunk's (link, leaf) pairs' gather entries; returns those of its rays."""
        h, g, at = self.h, self.gather, c.at
        W, pair_pt, n_pairs = c.W, c.pair_pt, c.n_pairs
        pw = nonzero(np.bincount(pair_pt, W, n_pairs))
        pair_F = np.bincount(pair_pt, W * f, n_pairs) / pw
        if rays is None:
            g.leaf[at], g.source[at] = c.leaf_ids, c.ls[c.link_of]
            g.F[at] = g.FV[at] = pair_F
            g.estimated[at] = False
            return []
        # Partially visible links gather from the source leaf each free ray lands in, rather
        # than from the source's mean radiosity: a hidden part of a source is often dark too
        # (floor under a box), and the mean would count that darkness a second time.
        partial_link = (rays.n_blocked > 0) & (rays.n_free > 0)
        tried = rays.tried
        by_ray = partial_link[c.link_pt] & (tried > 0)
        pair_FV = np.bincount(pair_pt, np.where(by_ray, 0.0, W * f * free_frac), n_pairs) / pw
        g.leaf[at], g.source[at] = c.leaf_ids, c.ls[c.link_of]
        g.F[at], g.FV[at] = pair_F, pair_FV
        g.estimated[at] = visibility_estimated(pair_F, pair_FV)
        chunk_parts = []
        ray_pt, kernel, u, v = (np.concatenate(x) for x in zip(*rays.free_rays))
        use = by_ray[ray_pt]
        if use.any():
            rp = ray_pt[use]
            # a ray's share of its point's F V (of its pair's when the rays' origins spread)
            weight = np.where(c.spread[rp], pair_F[pair_pt[rp]] * kernel[use] / tried[rp],
                              W[rp] * f[rp] * kernel[use] / tried[rp] / pw[pair_pt[rp]])
            src_leaf = h.locate(c.src[rp], u[use], v[use])
            # summed per (leaf, source leaf) now, as the rows would (gather_rows): one entry a
            # free ray kept the classroom at high with 128 rays on partial links at 5.7 GB
            key, at_key = np.unique(c.leaf_ids[pair_pt[rp]].astype(np.int64) * h.n + src_leaf,
                                    return_inverse=True)
            chunk_parts.append(LeafGather.of(key // h.n, key % h.n, np.zeros(len(key)),
                                             np.bincount(at_key, weight, len(key))))
        return chunk_parts

    def finish(self, results):
        """(F, V, vis) per link (and the LeafGather with ``with_leaves``), from the chunks'
        results (their rays' gather entries)."""
        parts = [p for chunk in results for p in chunk]
        F, Fv, seen_free, seen_blocked = self.F, self.Fv, self.seen_free, self.seen_blocked
        if self.occluder is None or self.rays <= 0:
            seen_free[:] = True
        V = np.where(F > 0, Fv / np.where(F > 0, F, 1.0),
                     np.where(seen_blocked & ~seen_free, 0.0, 1.0))
        V = np.clip(V, 0.0, 1.0)
        vis = np.where(seen_blocked, np.where(seen_free, PARTIAL, INVISIBLE),
                       VISIBLE).astype(np.int8)
        if not self.with_leaves:
            return F, V, vis
        # the rays' entries after the pairs', one field at a time, each grown in place (joined,
        # the office's 51 M entries were held twice while a field was copied)
        gather, n_pair_entries = self.gather, self.n_pair_entries
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
    F_fine = safe_div((fine * pts_w).sum(axis=1), pts_w.sum(axis=1))
    F_m = safe_div((f * w).sum(axis=1), w.sum(axis=1))
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
