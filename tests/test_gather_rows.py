"""The leaf gather by rows (radiosity/gather_rows.py) against a dense sum of its entries."""
import numpy as np

from relight_addon.core.radiosity.gather_rows import GatherRows
from relight_addon.core.radiosity.links import LeafGather


def _entries(rng, n_entries=400, n_elements=30):
    leaves = np.sort(rng.choice(n_elements, 12, replace=False))
    leaf = rng.choice(leaves, n_entries)
    leaf[:5] = leaves[3]                                   # a row with repeated entries
    source = rng.integers(0, n_elements, n_entries)
    source[:5] = 7                                         # ... to the same source
    F = rng.random(n_entries)
    FV = F * rng.random(n_entries)
    return leaves, LeafGather.of(leaf, source, F, FV), n_elements


def _dense(leaves, leaf, source, values, n_elements):
    out = np.zeros((len(leaves), n_elements))
    np.add.at(out, (np.searchsorted(leaves, leaf), source), values)
    return out


def test_rows_sum_the_entries_and_share_the_solvers_array():
    rng = np.random.default_rng(0)
    leaves, g, n = _entries(rng)
    leaf, source, F, FV = g.leaf.copy(), g.source.copy(), g.F.copy(), g.FV.copy()
    rows = GatherRows.from_entries(leaves, g, n)
    assert g.leaf is None and g.FV is None                 # the entries are released
    assert rows.n_entries < len(leaf)                      # duplicates merged
    assert np.allclose(rows.matrix(rows.FV, n).toarray(), _dense(leaves, leaf, source, FV, n))
    assert np.allclose(rows.matrix(rows.F, n).toarray(), _dense(leaves, leaf, source, F, n),
                       rtol=1e-6)                          # F in float32
    # the entries' leaves read back
    assert np.array_equal(rows.matrix(np.ones(rows.n_entries), n).toarray() > 0,
                          _dense(leaves, leaf, source, np.ones(len(leaf)), n) > 0)
    assert np.array_equal(np.bincount(np.searchsorted(leaves, rows.leaf), minlength=len(leaves)),
                          np.diff(rows.indptr))
    # the matrix holds the rows' own array: a row scaled in place scales the operator
    M = rows.matrix(rows.FV, n)
    x = rng.random(n)
    before = M @ x
    rows.FV[rows.indptr[2]:rows.indptr[3]] *= 0.5
    after = M @ x
    assert np.isclose(after[2], 0.5 * before[2]) and np.allclose(np.delete(after, 2),
                                                                 np.delete(before, 2))


def test_restrict_keeps_the_chosen_entries_in_their_rows():
    rng = np.random.default_rng(1)
    leaves, g, n = _entries(rng)
    rows = GatherRows.from_entries(leaves, g, n)
    keep = rows.source % 3 == 0
    sub = rows.restrict(keep)
    dense = rows.matrix(rows.FV, n).toarray()
    dense[:, np.arange(n) % 3 != 0] = 0
    assert np.allclose(sub.matrix(sub.FV, n).toarray(), dense)
    assert sub.n_entries == keep.sum()


def test_rows_sorted_range_by_range_are_the_rows_sorted_at_once():
    """from_entries moves the entries block by block into ranges of rows (so that the entries
    and the rows are never both whole): any blocks and ranges give the same arrays, bit for
    bit, as one block and one range; an empty range of rows is kept."""
    rng = np.random.default_rng(2)
    leaves, g, n = _entries(rng, n_entries=5000, n_elements=300)
    leaves = np.union1d(leaves, np.setdiff1d(np.arange(0, n, 7), leaves))   # rows with none
    fields = (g.leaf.copy(), g.source.copy(), g.F.copy(), g.FV.copy())
    whole = GatherRows.from_entries(leaves, g, n, ranges=1, block=1 << 20)
    for ranges, block in ((3, 7), (16, 1000), (40, 64)):
        g = LeafGather.of(*(f.copy() for f in fields))
        rows = GatherRows.from_entries(leaves, g, n, ranges=ranges, block=block)
        assert g.leaf is None and g.FV is None
        for key in ("indptr", "source", "F", "FV"):
            assert np.array_equal(getattr(rows, key), getattr(whole, key)), (ranges, block, key)
    assert np.allclose(whole.matrix(whole.FV, n).toarray(),
                       _dense(leaves, fields[0], fields[1], fields[3], n))


def test_resized_keeps_the_items_and_leaves_views_alone():
    """memory.resized grows and shrinks an array that owns its buffer in place (realloc), and
    copies one that does not (a view: its base must stay whole)."""
    from relight_addon.core.radiosity.memory import resized
    a = np.arange(10.0)
    b = resized(a, 15)
    assert len(b) == 15 and np.array_equal(b[:10], np.arange(10.0))
    c = resized(b, 4)
    assert np.array_equal(c, np.arange(4.0))
    base = np.arange(20)
    view = base[5:15]
    grown = resized(view, 12)
    assert len(grown) == 12 and np.array_equal(grown[:10], np.arange(5, 15))
    assert len(base) == 20 and np.array_equal(base, np.arange(20))
