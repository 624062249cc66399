"""core/persist.py: a solved result to bytes and arrays and back, and nothing else back.

Truth: the object itself (every array bit for bit, shared arrays shared again, ray casters
rebuilt and casting the same rays), and pickle's own way of calling a function (refused)."""
import pickle

import numpy as np
import pytest
import scipy.sparse as sp

from relight_addon.core import persist
from relight_addon.core.geometry.raycast import make_occluder
from relight_addon.core.radiosity.hierarchy import Hierarchy  # noqa: F401  (a core class)
from relight_addon.core.relight.shadowfree import ShadowFreeOptions


def _graph():
    rng = np.random.default_rng(0)
    shared = rng.random(1000)
    M = sp.random(50, 40, density=0.1, format="csr", random_state=1)
    tri = rng.random((20, 3, 3))
    occ = make_occluder(tri)
    occ.patch_of_triangle = np.arange(20, dtype=np.int32)
    return {"a": shared, "view": shared[10:20], "again": shared, "M": M, "occ": occ,
            "opts": ShadowFreeOptions(mode="texel", preset="draft"), "f32": np.float32(2.5),
            "dtype": np.dtype(np.int16), "nested": [{"x": (1, 2.0, "s", None)}],
            "empty": np.zeros((0, 3)), "int": np.arange(7, dtype=np.int64)}


def test_round_trip_keeps_every_array_and_the_sharing():
    g = _graph()
    header, blob = persist.pack(g)
    assert blob.dtype == np.uint8 and blob.nbytes % 4 == 0
    back = persist.unpack(header, memoryview(blob.view(np.int32)))
    np.testing.assert_array_equal(back["a"], g["a"])
    assert back["again"] is back["a"]                      # one array, shared again
    np.testing.assert_array_equal(back["view"], g["view"])
    assert (back["M"] != g["M"]).nnz == 0 and back["M"].shape == g["M"].shape
    assert back["opts"] == g["opts"]
    assert back["f32"] == np.float32(2.5) and back["f32"].dtype == np.float32
    assert back["dtype"] == np.dtype(np.int16) and back["nested"] == g["nested"]
    assert back["empty"].shape == (0, 3) and back["int"].dtype == np.int64
    # the ray caster is built again from its triangles and casts the same rays
    rng = np.random.default_rng(3)
    o, e = rng.random((500, 3)) * 2 - 0.5, rng.random((500, 3)) * 2 - 0.5
    np.testing.assert_array_equal(back["occ"].segments_occluded(o, e),
                                  g["occ"].segments_occluded(o, e))
    np.testing.assert_array_equal(back["occ"].patch_of_triangle, g["occ"].patch_of_triangle)
    # the result owns its memory (the blob may go away)
    blob[:] = 0
    assert back["a"].any()


class Evil:
    def __reduce__(self):
        return (print, ("pwned",))


def test_refuses_what_a_result_is_not_made_of():
    stream = pickle.dumps((persist.FORMAT, Evil()), protocol=5)
    with pytest.raises(persist.PersistError, match="may not hold builtins.print"):
        persist.loads(stream, [])
    with pytest.raises(persist.PersistError):
        persist.loads(pickle.dumps((persist.FORMAT + 1, 1)), [])
    header, blob = persist.pack({"a": np.arange(10.0)})
    with pytest.raises(persist.PersistError, match="truncated"):
        persist.unpack(header, blob[:8])
    with pytest.raises(persist.PersistError):
        persist.pack({"o": np.array([object()], dtype=object)})


def test_classes_are_found_under_any_package_name():
    """A file saved with the extension installed as bl_ext.<repo>.relight opens where it is
    installed under another name (or imported as relight_addon by a script)."""
    import sys
    opts = ShadowFreeOptions(preset="high")
    klass = type(opts)
    real = klass.__module__
    elsewhere = "bl_ext.user_default.relight.relight_addon.core.relight.shadowfree"
    sys.modules[elsewhere] = sys.modules[real]
    try:
        klass.__module__ = elsewhere
        stream, arrays = persist.dumps(opts)
    finally:
        klass.__module__ = real
        del sys.modules[elsewhere]
    assert elsewhere.encode() in stream
    assert persist.loads(stream, arrays) == opts
