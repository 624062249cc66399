"""Contact lines: where an object touches a surface (a box standing on the floor, a cabinet
against a wall), the surface's light jumps from lit to none.

An element that straddles such a line averages both sides; its exposed fraction is known only
on its quadrature points (radiosity.exposure: a quarter at 2 x 2), and as a source it stands for
its exposed part at that fraction.  In a closed furnace with a box on the floor (rho 0.9,
medium) that left straddling leaves 5 % off and the faces that see them 1.3 %.  The lines are
known from the geometry alone: an edge of an occluding face that lies in the plane of another
face and crosses it.  Elements crossed by a line are split before the links are refined, down
to ``Quality.contact_levels`` below the preset's smallest element, so that what straddles is
small (discontinuity meshing of the zeroth order, by quadtree splits).

Gap lines: the same edges where the object does not touch but hovers within GAP_TOL of the
face (a box 1 mm above the floor, a cabinet 1 mm off a wall).  The face under it sees the
object's underside and little of the room, and an element across the outline that gathers at
one point (draft) takes either view for the whole element, while its exact entries are averaged
over it: no row conservation mends that (a furnace with boxes 1 mm above the floor:
benchmarks/results/furnace.md).  Draft splits there (Quality.gap_levels).
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..geometry.patch import quad_area_normal
from ..numerics import nonzero
from .hierarchy import Hierarchy
from .links import segment_ranges

_PLANE_TOL = 1e-4       # x scene size: an edge this close to a plane lies in it
GAP_TOL = 1e-3          # x scene size: an edge this close to a plane, not in it, hovers over it
_INSIDE_TOL = 1e-3      # x the element's diameter: a line along its border does not cross it
_EDGE_BLOCK = 2048


def contact_segments(scene, scale, gaps=False):
    """(segments (S, 2, 3), patch (S,)): edges of occluding faces that lie in the plane of
    another face (``patch``) and cross its inside; with ``gaps``, those that hover over it
    instead (within GAP_TOL of its plane, not both ends within its plane)."""
    corners = scene.corners
    p = len(corners)
    if p < 2:
        return np.zeros((0, 2, 3)), np.zeros(0, np.int64)
    _, normal = quad_area_normal(corners)
    tol = (GAP_TOL if gaps else _PLANE_TOL) * scale
    touch = _PLANE_TOL * scale
    edges = np.stack([corners, np.roll(corners, -1, axis=1)], axis=2)     # (p, 4, 2, 3)
    length = np.linalg.norm(edges[:, :, 1] - edges[:, :, 0], axis=2)
    occ = np.asarray(scene.occluder, bool)
    src, k = np.nonzero(occ[:, None] & (length > tol))
    seg = edges[src, k]                                                   # (e, 2, 3)
    if len(seg) == 0:
        return np.zeros((0, 2, 3)), np.zeros(0, np.int64)
    # candidate faces near each edge: the edge's ball meets the face's ball.  Faces are
    # grouped by size (radius within a factor 2), so that a few large faces (a floor) do not
    # widen the search for every small one (a scan's triangles).
    centre = corners.mean(axis=1)
    radius = np.linalg.norm(corners - centre[:, None], axis=2).max(axis=1)
    mid = seg.mean(axis=1)
    half = 0.5 * np.linalg.norm(seg[:, 1] - seg[:, 0], axis=1)
    size_class = np.floor(np.log2(np.maximum(radius, 1e-12 * scale))).astype(np.int64)
    ei_parts, fj_parts = [], []
    for c in np.unique(size_class):
        members = np.flatnonzero(size_class == c)
        tree = cKDTree(centre[members])
        reach = half + radius[members].max() + tol
        # edges in blocks, each block's pairs cut to those in a face's plane at once: on
        # RenderPark's office (50k edges) all the candidates together peaked at 2.2 GB
        for e0 in range(0, len(seg), _EDGE_BLOCK):
            near = tree.query_ball_point(mid[e0:e0 + _EDGE_BLOCK], reach[e0:e0 + _EDGE_BLOCK])
            counts = [len(x) for x in near]
            if not sum(counts):
                continue
            ei = e0 + np.repeat(np.arange(len(near)), counts)
            fj = members[np.concatenate([np.asarray(x, np.int64) for x in near])]
            keep = fj != src[ei]
            ei, fj = ei[keep], fj[keep]
            # both ends in the face's plane
            d = np.einsum("eij,ej->ei", seg[ei] - corners[fj][:, None, 0], normal[fj])
            keep = np.all(np.abs(d) <= tol, axis=1)
            if gaps:
                keep &= ~np.all(np.abs(d) <= touch, axis=1)
            ei_parts.append(ei[keep])
            fj_parts.append(fj[keep])
    if not ei_parts:
        return np.zeros((0, 2, 3)), np.zeros(0, np.int64)
    ei, fj = np.concatenate(ei_parts), np.concatenate(fj_parts)
    inside, a, b = _crossing(seg[ei, 0], seg[ei, 1], corners[fj], normal[fj],
                             _INSIDE_TOL * 2 * radius[fj])
    return np.stack([a[inside], b[inside]], axis=1), fj[inside]


def _crossing(a, b, quads, normals, tol):
    """(crosses, a', b'): the part a'-b' of segments a-b inside each convex planar quad
    (Cyrus-Beck clipping; empty parts have a' == b'), and whether it has length and passes
    inside the quad (its midpoint farther than ``tol`` from every edge).  A triangle's
    repeated corner (a, b, c, c) makes an edge of no length, which bounds nothing."""
    edge = np.roll(quads, -1, axis=1) - quads
    real = np.linalg.norm(edge, axis=2) > 1e-12                                  # (n, 4)
    inward = np.cross(normals[:, None], edge)
    inward /= nonzero(np.linalg.norm(inward, axis=2, keepdims=True))
    d = b - a
    t0, t1 = np.zeros(len(a)), np.ones(len(a))
    for k in range(4):
        num = np.einsum("ij,ij->i", a - quads[:, k], inward[:, k])     # >= 0 inside
        den = np.einsum("ij,ij->i", d, inward[:, k])
        with np.errstate(divide="ignore", invalid="ignore"):
            t = -num / den
        t0 = np.where((den > 0) & real[:, k], np.maximum(t0, t), t0)
        t1 = np.where((den < 0) & real[:, k], np.minimum(t1, t), t1)
        t1 = np.where((den == 0) & (num < 0) & real[:, k], t0, t1)      # parallel, outside
    t1 = np.maximum(t1, t0)
    a, b = a + t0[:, None] * d, a + t1[:, None] * d
    dist = np.einsum("ikj,ikj->ik", 0.5 * (a + b)[:, None] - quads, inward)
    dist = np.where(real, dist, np.inf)
    crosses = (np.linalg.norm(b - a, axis=1) > tol) & (dist.min(axis=1) > tol)
    return crosses, a, b


def split_at_contacts(h: Hierarchy, segments, seg_patch, min_area):
    """Split the leaves that a contact segment of their patch crosses until they are smaller
    than ``min_area``.  Returns the number of elements made.  A segment that does not cross an
    element crosses none of its children, so each level tests only its parents' pairs."""
    if len(segments) == 0:
        return 0
    n0 = h.n
    segments, li, si = _leaf_segment_pairs(h, segments, seg_patch)
    while len(li):
        big = h.area[li] > min_area
        li, si = li[big], si[big]
        if len(li) == 0:
            break
        li, si = _crossed(h, segments, li, si)
        if len(li) == 0:
            break
        h.split(np.unique(li))
        first_child = h.first_child[li]
        li = (first_child[:, None] + np.arange(4)).ravel()
        si = np.repeat(si, 4)
    return h.n - n0


def crossed_leaves(h: Hierarchy, segments, seg_patch) -> np.ndarray:
    """(h.n,) bool: the leaves that a contact segment of their patch crosses (part of them
    lies under the touching object)."""
    crossed = np.zeros(h.n, bool)
    if len(segments):
        segments, li, si = _leaf_segment_pairs(h, segments, seg_patch)
        crossed[_crossed(h, segments, li, si)[0]] = True
    return crossed


def _leaf_segment_pairs(h, segments, seg_patch):
    """(segments sorted by patch, leaf ids, segment ids): every leaf with each segment of its
    patch."""
    order = np.argsort(seg_patch, kind="stable")
    seg_patch = np.asarray(seg_patch)[order]
    segments = np.asarray(segments)[order]
    first = np.searchsorted(seg_patch, np.arange(int(h.patch[: h.n].max()) + 2))
    leaves = h.leaves()
    start = first[h.patch[leaves]]
    cnt = first[h.patch[leaves] + 1] - start
    return segments, np.repeat(leaves, cnt), segment_ranges(start, cnt)


def _crossed(h, segments, li, si):
    """The (leaf, segment) pairs of ``li``, ``si`` whose segment crosses the leaf."""
    quads = h.corners[li]
    diam = np.linalg.norm(quads[:, 2] - quads[:, 0], axis=1)
    hit, _, _ = _crossing(segments[si, 0], segments[si, 1], quads, h.normal[li],
                          _INSIDE_TOL * diam)
    return li[hit], si[hit]
