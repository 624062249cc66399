"""Leaf-level linear system of hierarchical radiosity and its solvers.

With fixed links the solution on the leaves satisfies  B = E + rho * K B  with
K = P_down G P_up:  P_up pulls leaf radiosities to every element as area averages, G gathers
along the links (F V per link), P_down pushes each element's irradiance down to its leaves.
K is never formed; it is applied as two sparse products (M = P_down G and P_up).

Solvers: Jacobi and block Gauss-Seidel gathering (seed 003), progressive shooting (reference, on
an explicit K, small scenes), and GMRES / BiCGSTAB.  Jacobi converges like rho_max^n, so it stalls
as rho -> 1; the Krylov solvers do not.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..numerics import nonzero, safe_div
from .hierarchy import Hierarchy


# Measured: rho 0.99 furnaces with clutter converge in 21-69 iterations once no row exceeds 1.
GMRES_RESTARTS = 10
# The cluster links' share of a gather is taken this many bytes of per-link values at a time:
# W @ B has a row per cluster link (1.44 M on RenderPark's classroom at medium), and with the
# 24 lamps x 3 channels solved together it held 0.83 GB, the peak of the whole precompute.
CLUSTER_GATHER_BYTES = 64 * 2**20


@dataclass
class SolveInfo:
    method: str
    iterations: int
    residual: float                      # ||E + rho K B - B|| / ||E||
    history: list = field(default_factory=list)
    converged: bool = True


class LeafSystem:
    """The operator B -> rho * K B on the leaves of a hierarchy.

    Built on the leaves' gather, a (leaves, elements) matrix: the irradiance of a leaf is the sum
    over its row of transport * (mean radiosity of the source element).  ``from_rows`` takes the
    final gather's rows (gather_rows); ``from_links`` expands a link set to that form by pushing
    each link down to the leaves under its receiver (the classic push of a hierarchy).
    """

    def __init__(self, h: Hierarchy, M, rho_patch: np.ndarray):
        """``M``: the (leaves, elements) CSR matrix of the leaves' gather, rows in
        ``h.leaves()`` order."""
        self.leaves = h.leaves()
        L = len(self.leaves)
        n = h.n
        pos, anc = h.ancestor_pairs(self.leaves)
        area = h.view("area")
        self.leaf_area = area[self.leaves]
        self.patch = h.patch[self.leaves]
        # Pull: element value = area-weighted mean over its leaves.
        self.P_up = sp.csr_matrix((safe_div(self.leaf_area[pos], area[anc]), (anc, pos)),
                                  shape=(n, L))
        self.M = M
        self.rho = rho_patch[self.patch]                    # (L, 3)
        self.U = self.W = None                              # cluster links: H += U (W B)
        self.exposure = np.ones(L)                          # see set_exposure

    @classmethod
    def from_rows(cls, h: Hierarchy, rows, rho_patch, values=None):
        """On a gather stored by rows (gather_rows.GatherRows), its F V by default: the matrix
        holds the rows' own array (no copy), so scaling it in place scales the operator."""
        return cls(h, rows.matrix(rows.FV if values is None else values, h.n), rho_patch)

    @classmethod
    def from_links(cls, h: Hierarchy, receiver, source, transport, rho_patch):
        leaves = h.leaves()
        pos, anc = h.ancestor_pairs(leaves)
        P_down = sp.csr_matrix((np.ones(len(pos)), (pos, anc)), shape=(len(leaves), h.n))
        G = sp.csr_matrix((transport, (receiver, source)), shape=(h.n, h.n))
        M = P_down @ G
        M.sum_duplicates()          # canonical (sorted) rows, as built from entries before
        return cls(h, M, rho_patch)

    def set_exposure(self, h: Hierarchy, exposure):
        """Sources at the radiosity of their exposed part (radiosity.exposure): an element's
        value is its leaves' power over their exposed area, a leaf's B / a."""
        self.exposure = np.asarray(exposure, float)
        pos, anc = h.ancestor_pairs(self.leaves)
        exposed = np.bincount(anc, self.leaf_area[pos] * self.exposure[pos], h.n)
        area = np.bincount(anc, self.leaf_area[pos], h.n)
        seen = exposed > 1e-9 * area
        P_up = sp.csr_matrix((np.where(seen[anc], self.leaf_area[pos], 0.0)
                              / np.where(seen[anc], exposed[anc], 1.0),
                              (anc, pos)), shape=(h.n, len(self.leaves)))
        # An element that its quadrature found buried whole (a leaf gathering at its centre
        # decides by that point alone) may still be reached by a ray that lands on a part of
        # it out in the open: that ray sees the radiosity of the exposed surface around it,
        # the value of its nearest ancestor with an exposed part (0 when the patch is buried).
        hidden = np.flatnonzero(~seen)
        if len(hidden):
            up = hidden.copy()
            for _ in range(int(h.level[: h.n].max(initial=0)) + 1):
                move = (up >= 0) & ~seen[np.maximum(up, 0)]
                if not move.any():
                    break
                up[move] = h.parent[up[move]]
            ok = up >= 0
            S = sp.csr_matrix((np.ones(int(ok.sum())), (hidden[ok], up[ok])), shape=(h.n, h.n))
            P_up = P_up + S @ P_up
        self.P_up = P_up.tocsr()
        return self

    def add_clusters(self, U, W):
        """Add the low-rank transport of cluster links (see clusters.cluster_operator)."""
        if U.shape[1]:
            self.U, self.W = U, W
        return self

    @property
    def n_leaves(self):
        return len(self.leaves)

    def gather(self, B):
        """Irradiance on every leaf, K B, for B of shape (L, c)."""
        H = self.M @ (self.P_up @ B)
        if self.U is not None:
            step = max(1, CLUSTER_GATHER_BYTES // (8 * self.W.shape[0]))
            for a in range(0, B.shape[1], step):
                H[:, a:a + step] += self.U @ (self.W @ B[:, a:a + step])
        return H

    def apply(self, B):
        """rho * K B for B of shape (L, 3) or (L, 3, k)."""
        shp = B.shape
        flat = B.reshape(shp[0], -1)
        KB = self.gather(flat).reshape(shp)
        rho = self.rho if B.ndim == 2 else self.rho[..., None]
        return rho * KB

    def residual(self, B, E):
        return float(safe_div(np.linalg.norm(E + self.apply(B) - B), np.linalg.norm(E)))

    # -- solvers -----------------------------------------------------------------------------
    def solve(self, E, method="gmres", tol=1e-8, maxiter=None):
        """Solve (I - rho K) B = E for E of shape (L, 3) or (L, 3, k)."""
        E = np.asarray(E, float)
        if not np.any(E):
            return np.zeros_like(E), SolveInfo(method, 0, 0.0)
        solver = {"jacobi": self._jacobi, "gauss_seidel": self._gauss_seidel,
                  "gmres": self._krylov, "bicgstab": self._krylov,
                  "shooting": self._shooting}.get(method)
        if solver is None:
            raise ValueError(f"Unknown solver {method!r}")
        B, info = solver(E, tol, maxiter, method)
        if not np.all(np.isfinite(B)):
            raise FloatingPointError(f"{method} produced non-finite radiosity")
        info.residual = self.residual(B, E)
        return B, info

    def _jacobi(self, E, tol, maxiter, method):
        B = E.copy()
        hist = []
        maxiter = maxiter or 10_000
        norm_e = nonzero(np.linalg.norm(E))
        for it in range(1, maxiter + 1):
            new = E + self.apply(B)
            change = np.linalg.norm(new - B) / norm_e
            B = new
            hist.append(change)
            if change < tol:
                return B, SolveInfo(method, it, 0.0, hist)
        return B, SolveInfo(method, maxiter, 0.0, hist, converged=False)

    def _gauss_seidel(self, E, tol, maxiter, method, blocks=64):
        """Block Gauss-Seidel: leaves grouped by patch; each block gathers from the newest B."""
        shp = E.shape
        Ef = E.reshape(shp[0], -1)
        rho = np.broadcast_to(self.rho[..., None], shp).reshape(shp[0], -1) if E.ndim == 3 else self.rho
        order = np.argsort(self.patch, kind="stable")
        cuts = np.linspace(0, len(order), min(blocks, len(order)) + 1).astype(int)
        groups = [order[a:b] for a, b in zip(cuts[:-1], cuts[1:]) if b > a]
        P_up_csc = self.P_up.tocsc()
        cols = [P_up_csc[:, g] for g in groups]
        rows = [self.M[g] for g in groups]
        B = Ef.copy()
        elem = self.P_up @ B
        clustered = self.U is not None
        if clustered:
            W_csc = self.W.tocsc()
            wcols = [W_csc[:, g] for g in groups]
            U_csr = self.U.tocsr()
            urows = [U_csr[g] for g in groups]
            far = self.W @ B
        hist = []
        norm_e = nonzero(np.linalg.norm(Ef))
        maxiter = maxiter or 10_000
        for it in range(1, maxiter + 1):
            change = 0.0
            for i, (g, col, row) in enumerate(zip(groups, cols, rows)):
                H = row @ elem
                if clustered:
                    H = H + urows[i] @ far
                new = Ef[g] + rho[g] * H
                delta = new - B[g]
                B[g] = new
                elem += col @ delta
                if clustered:
                    far += wcols[i] @ delta
                change += float(np.sum(delta * delta))
            change = np.sqrt(change) / norm_e
            hist.append(change)
            if change < tol:
                return B.reshape(shp), SolveInfo(method, it, 0.0, hist)
        return B.reshape(shp), SolveInfo(method, maxiter, 0.0, hist, converged=False)

    def _krylov(self, E, tol, maxiter, method):
        shp = E.shape
        size = E.size

        def matvec(x):
            X = x.reshape(shp)
            return (X - self.apply(X)).ravel()

        A = spla.LinearOperator((size, size), matvec=matvec, dtype=float)
        hist = []
        b = E.ravel()
        if method == "gmres":
            # at most GMRES_RESTARTS x 60 iterations: a system that needs more has no
            # convergent physics (rho x row near 1) and is reported, not run on
            x, code = spla.gmres(A, b, x0=b.copy(), rtol=tol, atol=0.0, restart=60,
                                 maxiter=maxiter or GMRES_RESTARTS, callback=hist.append,
                                 callback_type="pr_norm")
        else:
            x, code = spla.bicgstab(A, b, x0=b.copy(), rtol=tol, atol=0.0,
                                    maxiter=maxiter or 60 * GMRES_RESTARTS,
                                    callback=lambda xk: hist.append(
                                        float(np.linalg.norm(b - A @ xk) / np.linalg.norm(b))))
        return x.reshape(shp), SolveInfo(method, len(hist), 0.0, hist, converged=code == 0)

    def explicit_K(self):
        """K as a dense (L, L) array: only for small reference solves."""
        K = self.M @ self.P_up
        if self.U is not None:
            K = K + self.U @ self.W
        return np.asarray(K.todense())

    def _shooting(self, E, tol, maxiter, method):
        """Progressive refinement (Southwell): shoot the leaf with most unshot power first."""
        K = self.explicit_K()
        shp = E.shape
        Ef = E.reshape(shp[0], -1)
        rho = np.broadcast_to(self.rho[..., None], shp).reshape(shp[0], -1) if E.ndim == 3 else self.rho
        B = Ef.copy()
        unshot = Ef.copy()
        area = self.leaf_area[:, None]
        total = max(float(np.sum(area * Ef)), 1e-300)
        hist = []
        maxiter = maxiter or 200 * len(Ef)
        for it in range(1, maxiter + 1):
            power = (area * unshot).sum(axis=1)
            j = int(np.argmax(power))
            if power[j] <= tol * total:
                return B.reshape(shp), SolveInfo(method, it - 1, 0.0, hist)
            dB = rho * (K[:, j:j + 1] * unshot[j][None, :])
            B += dB
            unshot += dB
            unshot[j] = 0.0
            hist.append(power[j] / total)
        return B.reshape(shp), SolveInfo(method, maxiter, 0.0, hist, converged=False)
