"""Clusters of input patches, so that linking does not start from all pairs of patches.

Without clusters, hierarchical radiosity starts from one link per pair of facing patches:
O(P^2) links, which stops scenes with thousands of input faces.  Here a binary tree of patch
clusters (median splits of the centroids along the longest axis) is linked from the root down;
a pair of nodes that is well separated (radius sum < ``separation`` x distance) becomes one
cluster link, and only nearby pairs of single patches become ordinary element links.

A cluster link (X receives from Y, centres c_X, c_Y at distance d) transports light with a
separable (rank-one) approximation of the point-to-point kernel cos cos' / (pi r^2):

    H_l += V_XY d^2 / pi * cos(n_l, c_Y - x_l) / |c_Y - x_l|^2
                        * sum_i A_i cos(n_i, c_X - y_i) / |y_i - c_X|^2 * B_i

for every leaf l (centroid x_l) under X and every leaf i (centroid y_i) under Y, cosines clipped
at zero, V_XY the visible fraction of rays between the clusters.  It is exact when either point
sits at its cluster's centre, so its error is second order in radius / distance.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..geometry.patch import bilinear_point
from ..geometry.raycast import ray_offset
from ..geometry.sampling import area_uniform_uv, jacobian_coefficients
from ..numerics import nonzero
from .hierarchy import Hierarchy


VISIBILITY_CHUNK_RAYS = 1 << 20     # cluster-visibility rays sampled at once


@dataclass
class ClusterTree:
    order: np.ndarray      # patches in tree order: every node covers order[lo:hi]
    lo: np.ndarray
    hi: np.ndarray
    child: np.ndarray      # (n, 2) children node ids, -1 for single-patch nodes
    centre: np.ndarray     # (n, 3) centre of the bounding sphere of the node's corners
    radius: np.ndarray

    @property
    def n(self):
        return len(self.lo)

    def is_patch(self, nodes):
        return self.hi[nodes] - self.lo[nodes] == 1

    def patch_of(self, nodes):
        return self.order[self.lo[nodes]]


def build_cluster_tree(corners: np.ndarray, patches: np.ndarray) -> ClusterTree:
    """Binary tree over ``patches`` (ids into ``corners``), split at the median centroid."""
    centroid = corners.mean(axis=1)
    order = np.asarray(patches, np.int64).copy()
    lo, hi, child = [0], [len(order)], [[-1, -1]]
    stack = [0]
    while stack:
        node = stack.pop()
        a, b = lo[node], hi[node]
        if b - a <= 1:
            continue
        pts = centroid[order[a:b]]
        axis = int(np.argmax(np.ptp(pts, axis=0)))
        mid = (b - a) // 2
        part = np.argpartition(pts[:, axis], mid)
        order[a:b] = order[a:b][part]
        kids = []
        for ca, cb in ((a, a + mid), (a + mid, b)):
            lo.append(ca)
            hi.append(cb)
            child.append([-1, -1])
            kids.append(len(lo) - 1)
            stack.append(len(lo) - 1)
        child[node] = kids
    lo, hi, child = np.array(lo), np.array(hi), np.array(child, np.int64)
    # Bounding spheres: centre of the box of the node's corners, radius to its farthest corner.
    n = len(lo)
    box_lo = np.empty((n, 3))
    box_hi = np.empty((n, 3))
    for node in range(n - 1, -1, -1):             # children come after parents
        if child[node, 0] < 0:
            pc = corners[order[lo[node]]]
            box_lo[node], box_hi[node] = pc.min(axis=0), pc.max(axis=0)
        else:
            c0, c1 = child[node]
            box_lo[node] = np.minimum(box_lo[c0], box_lo[c1])
            box_hi[node] = np.maximum(box_hi[c0], box_hi[c1])
    centre = 0.5 * (box_lo + box_hi)
    radius = 0.5 * np.linalg.norm(box_hi - box_lo, axis=1)
    return ClusterTree(order, lo, hi, child, centre, radius)


def link_clusters(tree: ClusterTree, separation: float, visibility=None, max_rounds: int = 200):
    """Refine (root, root) into cluster links and nearby patch pairs.

    ``visibility(X, Y)`` (optional) gives the visible fraction between node pairs: a
    well-separated pair that is partly hidden is split further, since a cluster link carries
    one visibility value for all its leaves.  Returns (cluster receivers, cluster sources,
    cluster visibilities) and (patch receivers, patch sources) for pairs of single patches that
    are not well separated or are partly hidden.
    """
    X = np.array([0])
    Y = np.array([0])
    cx, cy, cv, px, py = [], [], [], [], []
    for _ in range(max_rounds):
        if len(X) == 0:
            break
        same = X == Y
        single_x, single_y = tree.is_patch(X), tree.is_patch(Y)
        # Self pairs: the four child pairs (a single patch does not light itself).
        sx = X[same & ~single_x]
        c = tree.child[sx]
        self_x = np.concatenate([c[:, 0], c[:, 1], c[:, 0], c[:, 1]])
        self_y = np.concatenate([c[:, 0], c[:, 1], c[:, 1], c[:, 0]])
        other = ~same
        X, Y, single_x, single_y = X[other], Y[other], single_x[other], single_y[other]
        dist = np.linalg.norm(tree.centre[X] - tree.centre[Y], axis=1)
        apart = tree.radius[X] + tree.radius[Y] < separation * dist
        both_patches = single_x & single_y
        done_patch = both_patches
        done_cluster = apart & ~both_patches
        if visibility is not None and done_cluster.any():
            idx = np.flatnonzero(done_cluster)
            vis = visibility(X[idx], Y[idx])
            partial = (vis > 0.0) & (vis < 1.0)
            done_cluster[idx[partial]] = False
            cv.append(vis[~partial])
        else:
            cv.append(np.ones(int(done_cluster.sum())))
        px.append(tree.patch_of(X[done_patch]))
        py.append(tree.patch_of(Y[done_patch]))
        cx.append(X[done_cluster])
        cy.append(Y[done_cluster])
        split = ~(done_patch | done_cluster)
        X, Y = X[split], Y[split]
        # Split the larger node (a single patch cannot be split).
        split_x = ~tree.is_patch(X) & ((tree.radius[X] >= tree.radius[Y]) | tree.is_patch(Y))
        kx = tree.child[X[split_x]]
        ky = tree.child[Y[~split_x]]
        X = np.concatenate([self_x, kx[:, 0], kx[:, 1], X[~split_x], X[~split_x]])
        Y = np.concatenate([self_y, Y[split_x], Y[split_x], ky[:, 0], ky[:, 1]])
    return (np.concatenate(cx), np.concatenate(cy), np.concatenate(cv), np.concatenate(px),
            np.concatenate(py))


def cluster_visibility(tree: ClusterTree, h: Hierarchy, X, Y, occluder, rays: int, rng, scale):
    """Visible fraction of ``rays`` segments between area-random points of clusters X and Y,
    counting only point pairs that face each other."""
    k = len(X)
    if k == 0 or occluder is None or rays <= 0:
        return np.ones(k)
    n_patch = int(tree.order.max()) + 1
    patch_area = h.area[:n_patch]
    cum = np.concatenate([[0.0], np.cumsum(patch_area[tree.order])])
    jac = jacobian_coefficients(h.corners[:n_patch])

    def sample(nodes):
        lo, hi = np.repeat(tree.lo[nodes], rays), np.repeat(tree.hi[nodes], rays)
        start = cum[lo]
        t = start + rng.random(len(nodes) * rays) * (cum[hi] - start)
        pos = np.clip(np.searchsorted(cum, t, side="right") - 1, lo, hi - 1)
        patch = tree.order[pos]
        u, v = area_uniform_uv(None, rng.random((len(patch), 1)), rng.random((len(patch), 1)),
                               tuple(j[patch] for j in jac))
        return patch, bilinear_point(h.corners[patch], u[:, 0], v[:, 0])

    eps = ray_offset(scale)
    out = np.empty(k)
    # in chunks of links: the samples' arrays (~0.5 kB a ray) would otherwise peak at GBs
    # (1.3 M cluster links x 8 rays on a 5,508-patch box at medium)
    step = max(1, VISIBILITY_CHUNK_RAYS // rays)
    for c0 in range(0, k, step):
        x, y = X[c0:c0 + step], Y[c0:c0 + step]
        pa, p = sample(x)
        pb, q = sample(y)
        d = q - p
        ok = (np.einsum("ij,ij->i", d, h.normal[pa]) > 0) & \
            (np.einsum("ij,ij->i", d, h.normal[pb]) < 0)
        blocked = occluder.segments_occluded(p + eps * h.normal[pa], q + eps * h.normal[pb]) & ok
        link = np.repeat(np.arange(len(x)), rays)
        tried = np.bincount(link, ok, len(x))
        free = np.bincount(link, ok & ~blocked, len(x))
        out[c0:c0 + len(x)] = np.where(tried > 0, free / np.maximum(tried, 1), 1.0)
    return out


OPERATOR_BLOCK = 1 << 18


class _Factors:
    """The two sparse factors of the cluster links' transport on the leaves, H += U @ (W @ B),
    entry by entry: U (L, k) holds a receiving leaf's cos(n_l, c_Y - x_l)+ / |c_Y - x_l|^2
    x V_XY d^2 / pi, W (k, L) a sending leaf's cos(n_i, c_X - y_i)+ / |y_i - c_X|^2 x A_i.
    Entries come grouped by link, a block at a time (their link, position and temporaries are
    ~200 B an entry at once: the office's 10 M entries at medium made its peak when whole)."""

    def __init__(self, tree: ClusterTree, h: Hierarchy, leaves: np.ndarray, X, Y, V):
        self.L, self.k = len(leaves), len(X)
        self.X, self.Y, self.tree = X, Y, tree
        # Leaves grouped by their patch's position in the tree order: each node's leaves are a
        # range (patches outside the tree, e.g. lamps, rank -1: under no node)
        rank = np.full(max(int(tree.order.max()), int(h.patch[leaves].max())) + 1, -1, np.int64)
        rank[tree.order] = np.arange(len(tree.order))
        leaf_rank = rank[h.patch[leaves]]
        self.by_rank = np.argsort(leaf_rank, kind="stable")
        # the first leaf of each rank (and one past the last): a node's leaves by lookup
        self.rank_start = np.searchsorted(leaf_rank[self.by_rank],
                                          np.arange(len(tree.order) + 1))
        self.leaf_centroid, self.leaf_normal = h.centroid[leaves], h.normal[leaves]
        self.leaf_area = h.area[leaves]
        # Separable kernel: 1/|x - y|^2 ~ d^2 / (|x - c_Y|^2 |y - c_X|^2), exact when either
        # point is at its cluster's centre, so the error is second order in radius / distance.
        self.d2 = np.sum((tree.centre[Y] - tree.centre[X]) ** 2, axis=1)
        self.V = V

    def receiving(self):
        return self.X, self.tree.centre[self.Y], self.d2 * self.V / np.pi, np.ones(self.L)

    def sending(self):
        return self.Y, self.tree.centre[self.X], np.ones(self.k), self.leaf_area

    def pointers(self, nodes):
        first = self.rank_start[self.tree.lo[nodes]]
        count = self.rank_start[self.tree.hi[nodes]] - first
        return first, np.concatenate([[0], np.cumsum(count)])

    def blocks(self, side, pointers=None):
        """(entries slice, link, leaf slot, value) of one factor (``receiving()`` or
        ``sending()``), a block at a time.  ``pointers``: ``self.pointers`` of its nodes, if
        made already."""
        nodes, centre, per_link, per_leaf = side
        first, indptr = pointers if pointers is not None else self.pointers(nodes)
        n = int(indptr[-1])
        for a in range(0, n, OPERATOR_BLOCK):
            b = min(a + OPERATOR_BLOCK, n)
            entry = np.arange(a, b)
            # each entry's link: the block's links repeated by their entries in it
            lo, hi = np.searchsorted(indptr, [a, b - 1], side="right") - 1
            in_block = (np.minimum(indptr[lo + 1:hi + 2], b) - np.maximum(indptr[lo:hi + 1], a))
            link = np.repeat(np.arange(lo, hi + 1), in_block)
            leaf = self.by_rank[first[link] + (entry - indptr[link])]
            x, nl, c = self.leaf_centroid[leaf], self.leaf_normal[leaf], centre[link]
            dx, dy, dz = c[:, 0] - x[:, 0], c[:, 1] - x[:, 1], c[:, 2] - x[:, 2]
            r2 = nonzero(dx * dx + dy * dy + dz * dz)
            cos = np.maximum(0.0, dx * nl[:, 0] + dy * nl[:, 1] + dz * nl[:, 2]) / np.sqrt(r2)
            yield slice(a, a + len(entry)), link, leaf, cos / r2 * per_link[link] * per_leaf[leaf]

    def compressed(self, side):
        """(index pointer, leaf slot, value) of one factor: only the leaf slots (4 B) and the
        values (8 B) are whole."""
        pointers = self.pointers(side[0])
        indptr = pointers[1]
        n = int(indptr[-1])
        slot = np.empty(n, np.int32 if self.L < 2**31 else np.int64)
        value = np.empty(n)
        for at, _, leaf, v in self.blocks(side, pointers):
            slot[at], value[at] = leaf, v
        return indptr, slot, value


def cluster_operator(tree: ClusterTree, h: Hierarchy, leaves: np.ndarray, X, Y, V):
    """Sparse factors (U, W) of the cluster links' transport on the leaves: H += U @ (W @ B)."""
    L = len(leaves)
    k = len(X)
    if k == 0:
        return sp.csr_matrix((L, 0)), sp.csr_matrix((0, L))
    f = _Factors(tree, h, leaves, X, Y, V)
    # Entries come grouped by link, so both factors are built directly in compressed form.
    ptr_r, leaf_r, u = f.compressed(f.receiving())
    U = sp.csc_matrix((u, leaf_r, ptr_r), shape=(L, k))
    del ptr_r, leaf_r, u
    ptr_s, leaf_s, w = f.compressed(f.sending())
    W = sp.csr_matrix((w, leaf_s, ptr_s), shape=(k, L))
    return U, W


def cluster_transport(tree: ClusterTree, h: Hierarchy, leaves: np.ndarray, X, Y, V, B):
    """U @ (W @ B) of ``cluster_operator`` without holding U or W: what every leaf gathers
    through the cluster links from the per-leaf values ``B`` (L,).  Costs what building the
    factors costs; conserve needs only this one product, before the leaf gather is stored as
    rows (with the factors held there too, the office at medium peaked 374 MB higher)."""
    L, k = len(leaves), len(X)
    if k == 0:
        return np.zeros(L)
    f = _Factors(tree, h, leaves, X, Y, V)
    per_link = np.zeros(k)
    for _, link, leaf, w in f.blocks(f.sending()):
        per_link += np.bincount(link, w * B[leaf], k)
    out = np.zeros(L)
    for _, link, leaf, u in f.blocks(f.receiving()):
        out += np.bincount(leaf, u * per_link[link], L)
    return out
