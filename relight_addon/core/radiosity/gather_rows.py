"""The leaf gather stored row by row: what the solver multiplies with, and nothing twice.

The form factors arrive as (leaf, source, F, F V) entries in link order (links.LeafGather):
RenderPark's office at medium has 51 M of them for 3.7 M links, and kept both that way (32 B an
entry) and as the solver's sparse matrix (12 B, and a copy of it when the rows were rescaled)
they made most of a 5.1 GB peak.  Here they are sorted once into compressed rows over the leaves
(CSR: one pointer per leaf, no leaf id per entry), duplicates summed, and the solver's matrix is
built on these very arrays, so scaling a row scales the operator: 16 B an entry (a 4-byte source
id, F V in float64 for the solve, the unoccluded F in float32: it only feeds the shadow-free
ratios, where 1e-7 is far below any photo's noise).  Measured on the office at medium: peak
RSS 5.1 -> 3.5 GB, the solution bit for bit the same (benchmarks/results/mgf.md).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

INDEX = np.int32        # element ids: a hierarchy of 2^31 elements would not fit in memory anyway


@dataclass
class GatherRows:
    leaves: np.ndarray      # (L,) leaf element ids, the rows' order (Hierarchy.leaves())
    indptr: np.ndarray      # (L + 1,) entries of row i: indptr[i]:indptr[i + 1]
    source: np.ndarray      # (n,) int32 source element id (a source leaf for ray-level entries)
    F: np.ndarray           # (n,) float32 unoccluded form factor
    FV: np.ndarray          # (n,) float64 with visibility: the solver's matrix holds this array
    near: np.ndarray | None = None      # (h.n,) bool, as LeafGather.near

    @classmethod
    def from_entries(cls, leaves, gather, n_elements: int):
        """Rows of a LeafGather (its arrays are released as they are sorted: ``gather`` is left
        empty).  Entries with the same leaf and source are summed."""
        slot_of = np.full(n_elements, -1, INDEX)
        slot_of[leaves] = np.arange(len(leaves), dtype=INDEX)
        slot = slot_of[gather.leaf]
        gather.leaf = None
        shape = (len(leaves), n_elements)
        source = gather.source.astype(INDEX, copy=False)
        F = gather.F.astype(np.float32)
        gather.source = gather.F = None
        # scipy sorts into rows by counting (no argsort) and sums duplicates in place; the same
        # pattern sorts the same way for any data, so F's rows line up with F V's
        fv = sp.coo_matrix((gather.FV, (slot, source)), shape=shape).tocsr()
        gather.FV = None
        f = sp.coo_matrix((F, (slot, source)), shape=shape).tocsr()
        del slot, source, F
        if not (np.array_equal(f.indptr, fv.indptr) and np.array_equal(f.indices, fv.indices)):
            raise AssertionError("the unoccluded rows did not sort like the occluded ones")
        return cls(np.asarray(leaves), fv.indptr, fv.indices.astype(INDEX, copy=False),
                   f.data, fv.data, gather.near)

    @property
    def n_entries(self) -> int:
        return len(self.source)

    def slots(self, a: int = 0, b: int | None = None):
        """Row (leaf slot) of the entries a:b."""
        b = self.n_entries if b is None else b
        return np.searchsorted(self.indptr, np.arange(a, b), side="right") - 1

    @property
    def leaf(self):
        """Leaf element id of every entry (built on demand: 8 B an entry)."""
        return self.leaves[self.slots()]

    def matrix(self, values, n_elements: int):
        """The (L, n_elements) CSR matrix of ``values`` (one per entry) on these rows; it holds
        ``values`` itself, so changing it in place changes the matrix."""
        M = sp.csr_matrix((values, self.source, self.indptr),
                          shape=(len(self.leaves), n_elements), copy=False)
        M.has_sorted_indices = True
        M.has_canonical_format = True
        return M

    def restrict(self, keep):
        """The rows of the entries where ``keep`` (bool per entry): a new GatherRows."""
        before = np.concatenate([[0], np.cumsum(keep, dtype=np.int64)])    # kept before each entry
        indptr = before[self.indptr].astype(self.indptr.dtype)
        return GatherRows(self.leaves, indptr, self.source[keep], self.F[keep], self.FV[keep],
                          self.near)
