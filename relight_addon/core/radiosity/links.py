"""Links between elements: initial linking and the BF/BFV refinement oracle (the final form
factors of the refined links are final_links.py's).

A link (r, s) carries light from source element s to receiver element r.  ``F`` is the
unoccluded form factor F_rs (receiver-area average), ``V`` the visibility attenuation in [0, 1]
so that the transport factor is F * V, and ``vis`` the type VISIBLE / PARTIAL / INVISIBLE.
The leaf-level entries of the final links (``LeafGather``) are what the leaves gather from.
"""
from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from contextlib import nullcontext
from dataclasses import dataclass

import numpy as np

from ..geometry.formfactor import point_to_polygon
from ..geometry.patch import bilinear_point
from ..geometry.raycast import ray_offset
from ..geometry.sampling import area_uniform_uv, jacobian_coefficients, stratified_unit_square
from .hierarchy import Hierarchy

VISIBLE, PARTIAL, INVISIBLE = 0, 1, 2

# Oracle sample points on the receiver (parameter space): centre and near, not on, the
# corners, where F peaks (from a corner, a face meeting the receiver there has F = 0)
_ORACLE_UV = np.array([[0.5, 0.5], [0.05, 0.05], [0.95, 0.05], [0.95, 0.95], [0.05, 0.95]])
# Points closer than this fraction of the scene size to a plane count as on it.
_PLANE_TOL = 1e-9
# A (leaf, source) pair uses one quadrature point when the leaf's radius is below this fraction
# of its gap to the source: F hardly varies over the leaf there
_FAR_RATIO = 0.15
# Chunk sizes for the vectorised oracle (links).
_CHUNK_LINKS = 100_000
_PARALLEL_LINKS = 20_000
_THREADS = min(2, os.cpu_count() or 1)


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


# pairs tested at a time (~300 B of temporaries each)
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


def no_timer(name):
    return nullcontext()


def oracle_estimates(h: Hierarchy, r, s, occluder, rays: int, rng, scale: float, timer=no_timer):
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


def _oracle_chunk(h: Hierarchy, r, s, occluder, rays: int, rng, scale: float, timer=no_timer,
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


def segment_ranges(starts, counts):
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


def close_pairs(h, radius, leaf, source, ratio=_FAR_RATIO):
    """(n,) bool per (leaf, source) pair: the leaf's radius is above ``ratio`` x its gap to the
    source (F varies over the leaf: it needs its quadrature points)."""
    gap = np.linalg.norm(h.centroid[leaf] - h.centroid[source], axis=1) - radius[source]
    return radius[leaf] > ratio * gap
