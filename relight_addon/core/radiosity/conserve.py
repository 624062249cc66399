"""Leaf rows that cannot create light (issue 10).

A leaf gathers sum_j F_ij V_ij of its hemisphere from the sources it is linked to.  The
unoccluded F is exact at each quadrature point, but the visibility of a partly hidden source is
estimated from a few rays per point, and its error is largest where a near surface hides most
of the view (boxes 1 mm apart, thin panels, clutter): the small visible parts of the hidden
sources come out at 0, 1/4, 1/2 ... of their whole form factor.  Rows reached 1.4 (2.0 at draft)
in a closed furnace, where they are exactly 1, and rho x row > 1 has no convergent iteration.

Here each leaf casts cosine-weighted rays over its hemisphere.  Where every ray meets the front
of a source (a patch that reflects or emits; not a back, a black surface or one touching the
leaf), the leaf's view is closed and its row must be exactly 1, whatever the number of rays:
the row is set to 1.  Elsewhere the fraction of such rays is only a binomial estimate, worse
than the row's own form factors (moving rows towards it one way only biased an open scene by
6 %), and rows are only bounded by 1.  The entries whose visibility was estimated (partly
visible links) take the change first; the exact ones (sources seen whole) only what those
cannot absorb.  The back copy of a two-sided face (core/relight/orient.py: it blocks no ray,
its front does) is what a ray meeting that front from behind sees: it is counted and changed
like the other sources (uncounted, the leaves by the office's venetian blinds gathered rows of
1.05-1.13, and leaves under them up to 1.39).  Sources that do not block rays and are no such
back (an area light's patch) are seen through: neither counted nor changed.  Cluster links
(far, approximate) are counted and kept.

Measured: a closed furnace with 2 cm cubes and thin panels 1 mm apart, rho 0.5-0.99, is exact
to 1e-14 at draft and medium (was up to 3.5x the exact value); the Cornell box is unchanged.
"""
from __future__ import annotations

import numpy as np

from ..geometry.extent import longest_side
from ..geometry.raycast import ray_offset
from ..geometry.sampling import cosine_directions

COVERAGE_RAYS = 64      # per leaf
MAX_GAIN = 4.0          # at most this factor on a leaf's estimated entries
CONTACT = 1e-5          # of the scene's size: a hit this close is a touching surface
CONSERVE_BLOCK = 1 << 20


def back_copies(scene):
    """(p,) int: for each patch that blocks rays and has a back copy (a two-sided face:
    coincident, facing the other way, blocking nothing, not a lamp), that copy's index; -1
    elsewhere."""
    out = np.full(scene.n_patches, -1)
    back = np.flatnonzero(~scene.occluder & (scene.lamp < 0) & (scene.rho.max(axis=1) > 0))
    if not len(back):
        return out
    # a back lies on its front (the same corners in reverse order, a triangle's repeated one
    # elsewhere): the same bounding box, blocking rays, with the opposite normal
    from scipy.spatial import cKDTree
    centre = np.concatenate([scene.corners.min(axis=1), scene.corners.max(axis=1)], axis=1)
    _, normal = scene.area_normal()
    size = longest_side(scene.corners)
    fronts = np.flatnonzero(scene.occluder)
    if not len(fronts):
        return out
    k = min(8, len(fronts))             # faces modelled twice (both ways) share the centre
    dist, nearest = cKDTree(centre[fronts]).query(centre[back], k=k)
    cand = fronts[np.minimum(nearest.reshape(len(back), k), len(fronts) - 1)]
    match = (dist.reshape(len(back), k) <= 1e-6 * size) & \
        (np.einsum("bkj,bj->bk", normal[cand], normal[back]) < -0.99)
    ok = match.any(axis=1)
    front_of_back = cand[np.arange(len(back)), np.argmax(match, axis=1)]
    out[front_of_back[ok]] = back[ok]
    return out


def hemisphere_coverage(h, leaves, occluder, scene, rays, rng, scale, backs, at_centre=None):
    """Per leaf (L,): the fractions of cosine-weighted rays from random points of the leaf that
    first meet the front of a source of ``scene`` (a patch that reflects or emits, or the back
    copy of a two-sided face met from behind: ``backs``, from ``back_copies``), and that meet
    anything else (a back, a black surface, a surface touching the leaf).  ``occluder`` knows
    the patch of each triangle (``patch_of_triangle``).  ``at_centre`` (L,) bool: leaves that
    gather at their centre (every leaf at draft), whose rays all leave from it: their row is
    that point's view (a floor leaf by a box on the floor, its centre in the open: rays from
    random points under the box left it unclosed, and one ray that found a panel in front of
    the ceiling cost its row 23 %, its neighbours 26 % at rho 0.99)."""
    L = len(leaves)
    front = np.zeros(L)
    other = np.zeros(L)
    if L == 0 or occluder is None or rays <= 0:
        return front, other
    patch_of = np.asarray(occluder.patch_of_triangle)
    _, normal = scene.area_normal()                  # the scene's own sides (after orienting)
    source = (scene.rho.max(axis=1) > 0) | (scene.emission.max(axis=1) > 0)
    backed = backs >= 0                       # met from behind, their back copy is the source
    c = h.corners[leaves]
    n = h.normal[leaves]
    eps = ray_offset(scale)
    chunk = max(1, (1 << 20) // rays)
    # the rays are traced a quarter of a chunk at a time: a chunk's ~300 B of temporaries a
    # ray made the peak of the office at medium (the random numbers stay drawn per chunk)
    part = max(1, chunk // 4)
    for a in range(0, L, chunk):
        b = min(a + chunk, L)
        draws = rng.random((4, b - a, rays, 1))
        for a2 in range(a, b, part):
            b2 = min(a2 + part, b)
            u, v, x1, x2 = draws[:, a2 - a:b2 - a]
            if at_centre is not None:
                u = np.where(at_centre[a2:b2, None, None], 0.5, u)
                v = np.where(at_centre[a2:b2, None, None], 0.5, v)
            cc = c[a2:b2, None]
            P = (cc[..., 0, :] + u * (cc[..., 1, :] - cc[..., 0, :])
                 + v * (cc[..., 3, :] - cc[..., 0, :])
                 + u * v * (cc[..., 0, :] - cc[..., 1, :] + cc[..., 2, :] - cc[..., 3, :]))
            D = cosine_directions(n[a2:b2, None], x1, x2)
            O = P + eps * n[a2:b2, None]
            t, prim = occluder.first_hit(O.reshape(-1, 3), D.reshape(-1, 3))
            hit = prim >= 0
            p = patch_of[np.maximum(prim, 0)]
            facing = np.einsum("ij,ij->i", normal[p], D.reshape(-1, 3)) < 0
            faces = hit & np.where(facing, source[p], backed[p])
            # a surface touching the leaf (a box standing on it) is no source of its row either
            faces &= t >= CONTACT * scale
            front[a2:b2] = faces.reshape(b2 - a2, rays).mean(axis=1)
            other[a2:b2] = (hit & ~faces).reshape(b2 - a2, rays).mean(axis=1)
    return front, other


def conserve_rows(leaves, cluster_gather, gather, front, other, rays, occluder_patch,
                  element_patch):
    """Scale ``gather.FV`` (a LeafGather; in place) so that every leaf's row meets its hemisphere
    coverage ``front`` (see the module's docstring); returns the per-leaf factor on the
    estimated entries.  ``leaves``: the leaf ids, the rows' order; ``cluster_gather``: what
    each leaf gathers through the cluster links from a per-leaf vector (a function: e.g.
    clusters.cluster_transport) or None.  ``occluder_patch`` (per patch): whether
    its entries are counted (it blocks rays, or it is the back copy of a face that does:
    ``back_copies``); others (an area light's patch) are seen through the surfaces the
    coverage counts: neither counted nor changed.  Cluster links (far, approximate) are counted
    and kept.  ``element_patch``: the patch of each element."""
    L = len(leaves)
    occluder_patch = np.asarray(occluder_patch, bool)
    # each entry's row by a lookup, not a search (51 M entries on the office at medium)
    slot_of = np.full(len(element_patch), -1, np.int64)
    slot_of[leaves] = np.arange(L)

    def entries(a):
        """The block of entries from ``a``: their leaf slots, whether they are counted, and
        whether their visibility was estimated.  In blocks: ~70 B of temporaries an entry
        peaked at GBs on RenderPark's office at medium (51 M entries)."""
        FV = gather.FV[a:a + CONSERVE_BLOCK]
        counted = occluder_patch[element_patch[gather.source[a:a + CONSERVE_BLOCK]]]
        estimated = counted & (FV > 0) & gather.estimated[a:a + CONSERVE_BLOCK]
        return slot_of[gather.leaf[a:a + CONSERVE_BLOCK]], counted, estimated

    blocks = range(0, len(gather.leaf), CONSERVE_BLOCK)
    fixed, estim = np.zeros(L), np.zeros(L)
    for a in blocks:
        slot, counted, estimated = entries(a)
        FV = gather.FV[a:a + CONSERVE_BLOCK]
        fixed += np.bincount(slot, np.where(counted & ~estimated, FV, 0.0), L)
        estim += np.bincount(slot, np.where(estimated, FV, 0.0), L)
    from_clusters = np.zeros(L)
    if cluster_gather is not None:
        from_clusters = cluster_gather(occluder_patch[element_patch[leaves]].astype(float))
    rows = fixed + estim + from_clusters
    # Every ray met a source's front: the target is exact (a closed view), the row must be 1.
    # Elsewhere the coverage is only a binomial estimate, worse than the row's own form factors
    # (moving rows that are off it one way only biased an open scene by 6 %): only the bound.
    closed = (front == 1.0) & (other == 0.0)
    want = np.where(closed, 1.0, np.minimum(rows, 1.0)) - from_clusters
    alpha = np.where(estim > 0, np.clip((want - fixed) / np.where(estim > 0, estim, 1.0),
                                        0.0, MAX_GAIN), 1.0)
    rest = want - fixed - alpha * estim
    exact_moves = closed | (rows > 1.0)
    beta = np.where(exact_moves & (fixed > 0),
                    np.clip(1.0 + rest / np.where(fixed > 0, fixed, 1.0), 0.0, MAX_GAIN), 1.0)
    for a in blocks:
        slot, counted, estimated = entries(a)
        gather.FV[a:a + CONSERVE_BLOCK] *= np.where(estimated, alpha[slot],
                                                    np.where(counted, beta[slot], 1.0))
    return alpha
