"""A solved result as bytes and flat arrays, and back: what a .blend keeps so that Update after
reopening starts from the solution instead of solving the room again.

The object graph (dataclasses and plain classes of ``core``, dicts, lists) is pickled with every
numpy array, sparse matrix and ray caster taken out of the stream: arrays go to a table of
their own (stored as they are, no copy, no numpy pickle), sparse matrices as their arrays, ray
casters as their triangles (built again on load with the backend at hand).  So the stream holds
no numpy or scipy internals and reads the same on other numpy, scipy and Python versions.

Loading accepts only what a result is made of: classes of ``relight_addon.core`` (whatever
package the extension is installed under) and plain builtins.  Anything else in the stream
(another module's class or function) is refused, so a crafted file cannot run code through it.
"""
from __future__ import annotations

import importlib
import io
import pickle

import numpy as np
import scipy.sparse as sp

from .geometry.raycast import Occluder, make_occluder

FORMAT = 1
# attributes set on a ray caster after it is made (the patch of each triangle)
_OCCLUDER_EXTRAS = ("patch_of_triangle",)
_BUILTINS = {"set", "frozenset", "slice", "complex", "range", "bytearray"}
_SPARSE = {"csr": sp.csr_matrix, "csc": sp.csc_matrix, "coo": sp.coo_matrix}
_CORE = __name__.rsplit(".", 1)[0]          # this package's own name for core


class PersistError(ValueError):
    """The stored data cannot be read back (another format, a class that is not allowed)."""


class _Pickler(pickle.Pickler):
    def __init__(self, file, arrays):
        super().__init__(file, protocol=5)
        self.arrays, self._index = arrays, {}

    def _array(self, a):
        # views of one memory (a sparse matrix built on a gather's own arrays) are kept once
        key = (a.__array_interface__["data"][0], a.shape, a.strides, a.dtype.str) \
            if a.size else id(a)
        if key not in self._index:
            self._index[key] = len(self.arrays)
            self.arrays.append(a)
        return self._index[key]

    def persistent_id(self, obj):
        if isinstance(obj, np.ndarray):
            if obj.dtype.hasobject:
                raise PersistError("object arrays are not kept")
            return ("nd", self._array(obj))
        if isinstance(obj, np.generic):
            return ("np", obj.dtype.str, obj.item())
        if isinstance(obj, np.dtype):
            return ("dt", obj.str)
        if sp.issparse(obj):
            fmt = obj.format
            if fmt == "coo":
                parts = (obj.data, obj.row, obj.col)
            elif fmt in ("csr", "csc"):
                parts = (obj.data, obj.indices, obj.indptr)
            else:
                obj, fmt = obj.tocsr(), "csr"
                parts = (obj.data, obj.indices, obj.indptr)
            return ("sp", fmt, tuple(self._array(np.asarray(p)) for p in parts),
                    tuple(int(s) for s in obj.shape))
        if isinstance(obj, Occluder):
            extras = {k: self._array(np.asarray(getattr(obj, k))) for k in _OCCLUDER_EXTRAS
                      if getattr(obj, k, None) is not None}
            return ("occ", self._array(np.asarray(obj.triangles)), extras)
        return None


class _Unpickler(pickle.Unpickler):
    def __init__(self, file, arrays):
        super().__init__(file)
        self.arrays = arrays
        self._occluders = {}

    def persistent_load(self, pid):
        kind = pid[0]
        if kind == "nd":
            return self.arrays[pid[1]]
        if kind == "np":
            return np.dtype(pid[1]).type(pid[2])
        if kind == "dt":
            return np.dtype(pid[1])
        if kind == "sp":
            _, fmt, parts, shape = pid
            a, b, c = (self.arrays[i] for i in parts)
            if fmt == "coo":
                return sp.coo_matrix((a, (b, c)), shape=shape)
            return _SPARSE[fmt]((a, b, c), shape=shape, copy=False)
        if kind == "occ":
            _, tri, extras = pid
            key = (tri, tuple(sorted(extras.items())))
            if key not in self._occluders:
                occ = make_occluder(self.arrays[tri])
                for name, i in extras.items():
                    setattr(occ, name, self.arrays[i])
                self._occluders[key] = occ
            return self._occluders[key]
        raise PersistError(f"unknown stored object {kind!r}")

    def find_class(self, module, name):
        if module == "builtins" and name in _BUILTINS:
            return super().find_class(module, name)
        if module == "copyreg" and name == "_reconstructor":
            return super().find_class(module, name)
        if module == "collections" and name in ("OrderedDict", "defaultdict"):
            return super().find_class(module, name)
        marker = "relight_addon.core"
        if module == marker or module.startswith(marker + ".") or f".{marker}." in module \
                or module.endswith("." + marker):
            tail = module.split(marker, 1)[1]
            target = importlib.import_module(_CORE + tail)
            value = getattr(target, name, None)
            if isinstance(value, type):
                return value
        raise PersistError(f"a kept solution may not hold {module}.{name}")


def dumps(obj):
    """``obj`` as (stream bytes, list of arrays): the arrays are ``obj``'s own (not copied)."""
    arrays = []
    buf = io.BytesIO()
    _Pickler(buf, arrays).dump((FORMAT, obj))
    return buf.getvalue(), arrays


def loads(stream: bytes, arrays):
    """The object that :func:`dumps` gave (stream, arrays); raises PersistError on data it did
    not write."""
    try:
        fmt, obj = _Unpickler(io.BytesIO(stream), list(arrays)).load()
    except PersistError:
        raise
    except Exception as ex:
        raise PersistError(f"the kept solution cannot be read ({type(ex).__name__}: {ex})")
    if fmt != FORMAT:
        raise PersistError(f"the kept solution has format {fmt}, not {FORMAT}")
    return obj


# -- one blob ---------------------------------------------------------------------------------

_ALIGN = 16


def pack(obj):
    """``obj`` as (header: dict of plain values with the stream, blob: one contiguous uint8
    array holding every array, aligned), for storage as two ID properties."""
    stream, arrays = dumps(obj)
    table, offset = [], 0
    for a in arrays:
        a = np.ascontiguousarray(a)
        offset = -(-offset // _ALIGN) * _ALIGN
        table.append((a.dtype.str, list(a.shape), offset))
        offset += a.nbytes
    blob = np.zeros(-(-offset // 4) * 4, np.uint8)          # a whole number of int32
    for a, (_, _, start) in zip(arrays, table):
        a = np.ascontiguousarray(a)
        blob[start:start + a.nbytes] = a.reshape(-1).view(np.uint8)
    return {"format": FORMAT, "stream": stream, "table": table}, blob


def unpack(header, blob):
    """The object :func:`pack` gave; ``blob`` any buffer of its bytes (read-only is fine: the
    arrays are copied out of it, so the result owns its memory)."""
    if int(header.get("format", -1)) != FORMAT:
        raise PersistError("the kept solution has another format")
    raw = np.frombuffer(blob, np.uint8)
    arrays = []
    for dtype, shape, start in header["table"]:
        dt = np.dtype(dtype)
        n = int(np.prod(shape, dtype=np.int64)) * dt.itemsize
        if start < 0 or start + n > len(raw):
            raise PersistError("the kept solution is truncated")
        arrays.append(raw[start:start + n].view(dt).reshape(shape).copy())
    return loads(header["stream"], arrays)
