"""Gather entries spread over their source's children by form factor, not by area.

A link whose source is an element above the leaves gathers that element's mean radiosity: its
transport is spread over the source's leaves in proportion to their area.  The true weight of
each part is its own form factor from the receiver, and where that varies across the source it
varies with the radiosity: a room's corner is dark (the ceiling lamp sees it at a grazing
angle) and is also seen at a grazing angle from the far side of the ceiling, so the mean
radiosity under-counts the bright middle of the wall.  Each such error is below the oracle's
threshold, but they all have the same sign: in the Cornell box every surface came out low, by
0.9 % on average (the ceiling by 1.8 %), against Mitsuba.

Here an entry (leaf, source element) is split into one per child of the source, with the
children's exact point-to-polygon form factors at the leaf's own quadrature points (their sum
is the element's: the contour integral is additive), the visibility factor kept; ``levels``
times, while the source is near (its radius above ``near`` x its distance to the leaf), where
the form factor varies across it.  Entries of source leaves, and those whose rays gathered from
the source leaves they reached (partly visible links), are left as they are.

Where the leaf's points are farther apart than a child is wide (a leaf gathering at its centre,
larger than the children), each child's share is taken the other way round, A_c F(c's centre ->
the leaf's polygon) (reciprocity: A_l F_lc = A_c F_cl), exact over the leaf: its point alone
gives shares that alias a source's near part.  In a closed cube at rho 0.99 with one wall
emitting (draft) the point shares put 30 % more or less on the leaves nearest to a whole wall's
centre (2 x 2 points: 13-19 %), each wall's light landing where that wall's points looked, and
the emitted power came out 1.1 % off; the reciprocal shares leave 0.02 %.
"""
from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from ..geometry.formfactor import point_to_polygon
from ..geometry.sampling import quadrature
from .memory import give_back_memory, resized

_CHUNK = 5_000           # entries whose children's form factors are computed at once (20,000
                         # in two threads: +84 MB on the office's peak at medium, no faster)
_PICK_BLOCK = 1 << 20
_THREADS = min(2, os.cpu_count() or 1)


def split_sources(h, gather, m: int, near: float, levels: int):
    """Split ``gather``'s entries (a LeafGather; in place) over their sources' children (see
    the module docstring).  ``m``: the quadrature of the leaves ``gather.near`` marks (the
    others gather at their centre).  Returns the number of entries split."""
    if levels <= 0 or len(gather.leaf) == 0:
        return 0
    radius = h.radius()
    on_points = gather.near if gather.near is not None else np.zeros(h.n, bool)
    total = 0
    for _ in range(levels):
        # in blocks: the distances' temporaries (~60 B an entry) peaked at GBs on RenderPark's
        # office at medium
        pick = np.concatenate([a + _to_split(h, gather, a, a + _PICK_BLOCK, radius, near)
                               for a in range(0, len(gather.leaf), _PICK_BLOCK)])
        if len(pick) == 0:
            break
        # The first child takes its parent's place and the other three are appended, each
        # field grown in place (memory.resized): the picks' own values are never copied out
        # whole, nor the kept entries moved (the picks, a keep mask and the moves made the
        # office's peak at medium).
        n_old = len(gather.leaf)
        for key in ("leaf", "source", "F", "FV", "estimated"):
            setattr(gather, key, resized(getattr(gather, key), n_old + 3 * len(pick)))

        def fill(c):
            """The children's entries of the picks ``c`` (a slice)."""
            at = pick[c]
            leaf = gather.leaf[at]
            child = h.first_child[gather.source[at]]
            F, FV = gather.F[at], gather.FV[at]
            share = _child_shares(h, leaf, child, on_points, m, radius)   # (n, 4)
            gather.source[at] = child
            gather.F[at], gather.FV[at] = F * share[:, 0], FV * share[:, 0]
            rest = slice(n_old + 3 * c.start, n_old + 3 * (c.start + len(at)))
            gather.leaf[rest] = np.repeat(leaf, 3)
            gather.source[rest] = (child[:, None] + np.arange(1, 4)).ravel()
            gather.F[rest] = (F[:, None] * share[:, 1:]).ravel()
            gather.FV[rest] = (FV[:, None] * share[:, 1:]).ravel()
            # a child's F V / F is its parent's: so is whether its visibility was estimated
            gather.estimated[rest] = np.repeat(gather.estimated[at], 3)
        chunks = [slice(i, i + _CHUNK) for i in range(0, len(pick), _CHUNK)]
        if len(chunks) > 1 and _THREADS > 1:
            with ThreadPoolExecutor(_THREADS) as pool:
                list(pool.map(fill, chunks))
        else:
            for c in chunks:
                fill(c)
        total += len(pick)
        give_back_memory()      # the threads' shares, freed into their heaps (~200 MB a level)
    return total


def _to_split(h, gather, a, b, radius, near):
    """Offsets (from ``a``) of the entries a:b to split: a source with children, seen, near."""
    src = gather.source[a:b]
    # the distances only for the entries of seen sources with children (after the first level
    # most sources are leaves)
    cand = np.flatnonzero((h.first_child[src] >= 0) & (gather.FV[a:b] > 0))
    src = src[cand]
    d = h.centroid[gather.leaf[a:b][cand]] - h.centroid[src]
    return cand[radius[src] > near * np.sqrt(np.einsum("ij,ij->i", d, d))]


def _child_shares(h, leaf, first_child, on_points, m, radius):
    """(n, 4): each child's part of its parent's form factor from the leaf (its quadrature
    points where ``on_points``, else its centre; the reciprocal A_c F(child's centre -> leaf)
    where those points are farther apart than a child is wide: ``radius``, Hierarchy.radius);
    a quarter each where the parent's is 0."""
    n = len(leaf)
    F = np.zeros((n, 4))
    kids = first_child[:, None] + np.arange(4)                         # (n, 4)
    spacing = radius[leaf] / np.where(on_points[leaf] & (m > 1), m, 1)
    reciprocal = spacing > radius[first_child]
    rows = np.flatnonzero(reciprocal)
    if len(rows):
        k = kids[rows].reshape(-1)
        f = point_to_polygon(h.centroid[k], h.normal[k],
                             np.repeat(h.corners[leaf[rows]], 4, axis=0),
                             np.repeat(h.normal[leaf[rows]], 4, axis=0))
        F[rows] = (f * h.area[k]).reshape(len(rows), 4)
    for use_points in (True, False):
        rows = np.flatnonzero((on_points[leaf] == use_points) & ~reciprocal)
        if len(rows) == 0:
            continue
        if use_points and m > 1:
            pts, w = quadrature(h.corners[leaf[rows]], m)              # (r, mm, 3), (r, mm)
        else:
            pts, w = h.centroid[leaf[rows]][:, None], np.ones((len(rows), 1))
        mm = pts.shape[1]
        k = np.repeat(kids[rows][:, :, None], mm, axis=2).reshape(-1)  # (r * 4 * mm,)
        f = point_to_polygon(np.repeat(pts[:, None], 4, axis=1).reshape(-1, 3),
                             np.repeat(h.normal[leaf[rows]], 4 * mm, axis=0),
                             h.corners[k], h.normal[k]).reshape(len(rows), 4, mm)
        F[rows] = (f * w[:, None, :]).sum(axis=2)
    total = F.sum(axis=1, keepdims=True)
    return np.where(total > 0, F / np.where(total > 0, total, 1.0), 0.25)
