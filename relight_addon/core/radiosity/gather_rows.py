"""The leaf gather stored row by row: what the solver multiplies with, and nothing twice.

The form factors arrive as (leaf, source, F, F V) entries in link order (links.LeafGather):
RenderPark's office at medium has 51 M of them for 3.7 M links, and kept both that way (32 B an
entry) and as the solver's sparse matrix (12 B, and a copy of it when the rows were rescaled)
they made most of a 5.1 GB peak.  Here they are sorted once into compressed rows over the leaves
(CSR: one pointer per leaf, no leaf id per entry), duplicates summed, and the solver's matrix is
built on these very arrays, so scaling a row scales the operator: 16 B an entry (a 4-byte source
id, F V in float64 for the solve, the unoccluded F in float32: it only feeds the shadow-free
ratios, where 1e-7 is far below any photo's noise).  Measured on the office at medium: peak
RSS 5.1 -> 3.5 GB, the solution bit for bit the same (benchmarks/results/mgf.md).  The sort
itself goes range of rows by range of rows, the entries shrinking behind it (from_entries):
sorted at once, the entries (20 B) and the rows being made (12 B) were the office's peak.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .memory import give_back_memory, resized

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
    def from_entries(cls, leaves, gather, n_elements: int, ranges: int | None = None,
                     block: int = 1 << 21):
        """Rows of a LeafGather (its arrays are released as they are sorted: ``gather`` is left
        empty).  Entries with the same leaf and source are summed.

        The entries are moved, a block at a time from their end (each field shrunk in place
        behind them), into ``ranges`` ranges of rows of about equal entry counts, and each
        range is sorted on its own into the rows' arrays: the entries and the rows are never
        both held whole (32 B an entry at once, the office's peak, where 20 are needed).  By
        default one range per 4 M entries, up to 16: a small gather (the Cornell box's 70k
        entries) is sorted at once, in half the time."""
        L = len(leaves)
        slot_of = np.full(n_elements, -1, INDEX)
        slot_of[leaves] = np.arange(L, dtype=INDEX)
        n = len(gather.leaf)
        if ranges is None:
            ranges = int(min(16, 1 + n // (1 << 22)))
        per_row = np.zeros(L, np.int64)
        for a in range(0, n, block):
            per_row += np.bincount(slot_of[gather.leaf[a:a + block]], minlength=L)
        bounds = np.unique(np.concatenate([[0], np.searchsorted(
            np.cumsum(per_row), np.linspace(0, n, ranges + 1)[1:-1]), [L]])).astype(INDEX)
        fields = ("source", "F", "FV")
        pieces = [[] for _ in range(len(bounds) - 1)]
        gather.estimated = None
        end = n
        while end > 0:
            a = max(0, end - block)
            slot = slot_of[gather.leaf[a:end]]
            part = np.searchsorted(bounds, slot, side="right") - 1
            order = np.argsort(part, kind="stable")
            cut = np.searchsorted(part[order], np.arange(len(pieces) + 1))
            cols = [slot] + [getattr(gather, k)[a:end] for k in fields]
            for r in np.flatnonzero(np.diff(cut)):
                take = order[cut[r]:cut[r + 1]]
                pieces[r].append([c[take] for c in cols])
            del slot, part, order, cols
            for key in ("leaf",) + fields:
                setattr(gather, key, resized(getattr(gather, key), a))
            end = a
        gather.leaf = gather.source = gather.F = gather.FV = None
        index = INDEX if n < 2**31 else np.int64
        indptr = np.zeros(L + 1, index)
        source, F, FV = np.empty(n, INDEX), np.empty(n, np.float32), np.empty(n)
        at = 0
        for r, (lo, hi) in enumerate(zip(bounds[:-1], bounds[1:])):
            got = pieces[r][::-1]                  # the entries' own order, within each row
            pieces[r] = None
            if not got:
                indptr[lo + 1:hi + 1] = at
                continue
            slot, src, f_in, fv_in = (np.concatenate([g[i] for g in got]) for i in range(4))
            del got
            shape = (int(hi - lo), n_elements)
            # scipy sorts into rows by counting and sums duplicates in place.  F V and F ride
            # together as one complex number (sums are per part), so the rows are sorted once
            # (sorting the columns within rows was half the time, done for each field apart)
            both = np.empty(len(fv_in), np.complex128)
            both.real, both.imag = fv_in, f_in
            del f_in, fv_in
            rows = sp.coo_matrix((both, (slot - lo, src)), shape=shape).tocsr()
            del slot, src, both
            m = rows.nnz
            source[at:at + m], FV[at:at + m], F[at:at + m] = (rows.indices, rows.data.real,
                                                              rows.data.imag)
            indptr[lo + 1:hi + 1] = at + rows.indptr[1:]
            at += m
            del rows
            # the pieces (~1 MB each) were freed into the heap, which keeps their pages
            give_back_memory()
        return cls(np.asarray(leaves), indptr, resized(source, at), resized(F, at),
                   resized(FV, at), gather.near)

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
