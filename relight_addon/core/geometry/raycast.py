"""Ray casting behind one small interface: segment occlusion and first-hit distances.

Backends (all built from world-space triangles ``(t, 3, 3)``):

``EmbreeOccluder``   embreex (Embree 4), batched float32 queries, chunked, run on a thread pool
                     (embreex releases the GIL inside ``run``: 1.7-1.9x with 2 threads on an
                     idle 2-core machine).
``BVHTreeOccluder``  the fallback where no embreex wheel exists (Linux aarch64, Windows arm64):
                     ``mathutils.bvhtree`` lives in the bridge (``blender/bvhtree.py``), which
                     registers it here with :func:`register_backend`; core never imports
                     mathutils.
``NumpyOccluder``    brute-force Moller-Trumbore over rays x triangles, vectorised in chunks: for
                     tiny scenes and as an independent check in tests.  Never picked by "auto".

Conventions shared by every backend
-----------------------------------
* ``segments_occluded(origins, ends, eps)``: True when a triangle meets the open segment, trimmed
  by ``eps * length`` at both ends so that endpoints lying exactly on a surface do not hit it.
  Callers that need more margin (float32 precision on tilted surfaces far from the scene centre is
  ~1e-7 of the scene size) offset their endpoints along the surface normals themselves.
* Zero-length, NaN or infinite segments are never occluded (no error, no NaN out).
* With ``eps=0`` an endpoint exactly on a surface is backend-dependent (Embree and numpy count
  the hit at the end, BVHTree tests ``dist < tfar`` strictly); use eps > 0.
* Triangles are two-sided; hits on triangle edges/vertices count (Embree is run in robust,
  watertight mode, so a segment through the shared diagonal of a quad does not leak).
* A segment lying in the plane of a triangle (grazing) has a zero determinant and is reported
  NOT occluded by that triangle by every backend; such configurations have measure zero.
* ``first_hit_distance(origins, directions, tmax, tmin)``: Euclidean distance along the
  (normalised) direction to the first hit in ``[tmin, tmax]``, ``inf`` for a miss or a zero
  direction.
* Empty inputs give empty outputs; an empty triangle set occludes nothing.

Embree and BVHTree work in float32: to keep precision, triangles and rays are translated so that
the scene's bounding-box centre is the origin before the float32 conversion.
"""
from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np

__all__ = [
    "Occluder", "EmbreeOccluder", "NumpyOccluder", "RAY_OFFSET", "ray_offset",
    "make_occluder", "available_backends", "active_backend_name", "register_backend",
]

# Ray end points on a surface are lifted along its normal by this fraction of the scene's
# bounding-box diagonal, so that a ray does not hit the element it starts or ends on (float32
# backends resolve about 1e-7 of the scene size).
RAY_OFFSET = 1e-6


def ray_offset(scene_size: float) -> float:
    """The lift (world units) of ray end points off their surfaces in a scene of this size."""
    return RAY_OFFSET * (float(scene_size) or 1.0)

# Rays per embreex call: bounds temporary memory (~100 bytes per ray) and is the unit of work
# handed to the thread pool.
_EMBREE_CHUNK = 1 << 20
# Below this many rays, the thread pool costs more than it gains.
_THREAD_MIN_RAYS = 1 << 14
# rays x triangles per numpy brute-force block.
_NUMPY_BLOCK = 1 << 20
# Moller-Trumbore determinant floor (relative to |edge1||edge2||dir|): parallel rays miss.
_DET_REL = 1e-12


def _as_points(a, name: str) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    if a.ndim == 1 and a.shape[0] == 3:
        a = a[None]
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"{name} must have shape (n, 3), got {a.shape}")
    return a


def _as_triangles(triangles) -> np.ndarray:
    t = np.asarray(triangles, dtype=np.float64)
    if t.size == 0:
        return np.zeros((0, 3, 3))
    if t.ndim != 3 or t.shape[1:] != (3, 3):
        raise ValueError(f"triangles must have shape (t, 3, 3), got {t.shape}")
    # Drop triangles with non-finite coordinates; they cannot be traced consistently.
    return np.ascontiguousarray(t[np.isfinite(t).all(axis=(1, 2))])


def _check_eps(eps: float) -> float:
    eps = float(eps)
    if not (0.0 <= eps < 0.5):
        raise ValueError(f"eps must be in [0, 0.5), got {eps}")
    return eps


class Occluder:
    """Base class: subclasses implement ``_occluded`` and ``_first_hit`` on valid rays only."""

    name = "base"

    def __init__(self, triangles):
        self.triangles = _as_triangles(triangles)

    @property
    def n_triangles(self) -> int:
        return len(self.triangles)

    def segments_occluded(self, origins, ends, eps: float = 1e-6) -> np.ndarray:
        """(n,) bool: does any triangle meet the segment [origin, end] trimmed by eps*length?"""
        o = _as_points(origins, "origins")
        e = _as_points(ends, "ends")
        if o.shape != e.shape:
            raise ValueError(f"origins {o.shape} and ends {e.shape} differ in shape")
        eps = _check_eps(eps)
        out = np.zeros(len(o), bool)
        if len(o) == 0 or self.n_triangles == 0:
            return out
        with np.errstate(invalid="ignore", over="ignore"):
            d = e - o
            length2 = np.einsum("ij,ij->i", d, d)
            # a finite length needs finite ends (inf - inf is nan, inf - x is inf)
            valid = np.isfinite(length2) & (length2 > 0)
        if valid.all():                 # the usual case: no copies of 48 B a segment
            return self._occluded(o, d, eps)
        idx = np.flatnonzero(valid)
        if len(idx):
            out[idx] = self._occluded(o[idx], d[idx], eps)
        return out

    def first_hit_distance(self, origins, directions, tmax=np.inf, tmin: float = 0.0) -> np.ndarray:
        """(n,) float64 distance to the first hit along normalised directions, inf for misses.

        ``tmax`` is a scalar or (n,) array of maximum distances; hits closer than ``tmin`` (a
        scalar >= 0, e.g. to leave the surface a ray starts on) are ignored.
        """
        o = _as_points(origins, "origins")
        d = _as_points(directions, "directions")
        if o.shape != d.shape:
            raise ValueError(f"origins {o.shape} and directions {d.shape} differ in shape")
        n = len(o)
        tmax = np.broadcast_to(np.asarray(tmax, np.float64), (n,))
        tmin = float(tmin)
        if not tmin >= 0.0:
            raise ValueError(f"tmin must be >= 0, got {tmin}")
        out = np.full(n, np.inf)
        if n == 0 or self.n_triangles == 0:
            return out
        with np.errstate(invalid="ignore", over="ignore"):
            norm = np.sqrt(np.einsum("ij,ij->i", d, d))
            valid = (np.isfinite(o).all(1) & np.isfinite(norm) & (norm > 0)
                     & ~np.isnan(tmax) & (tmax >= tmin))
        idx = np.flatnonzero(valid)
        if len(idx):
            u = d[idx] / norm[idx, None]
            start = o[idx] + tmin * u
            t = self._first_hit(start, u, tmax[idx] - tmin)
            out[idx] = np.where(np.isfinite(t), t + tmin, np.inf)
        return out

    def first_hit(self, origins, directions, tmax=np.inf) -> tuple:
        """(distance (n,), triangle index (n,), -1 and inf for misses) of the first hit along
        normalised directions from the origins."""
        o = _as_points(origins, "origins")
        d = _as_points(directions, "directions")
        n = len(o)
        tmax = np.broadcast_to(np.asarray(tmax, np.float64), (n,))
        t, prim = np.full(n, np.inf), np.full(n, -1, np.int64)
        if n == 0 or self.n_triangles == 0:
            return t, prim
        with np.errstate(invalid="ignore", over="ignore"):
            norm = np.sqrt(np.einsum("ij,ij->i", d, d))
            valid = np.isfinite(o).all(1) & np.isfinite(norm) & (norm > 0) & (tmax >= 0)
        if valid.all():                    # the usual case: no gathered copies of 4M rays
            return self._first_hit_prim(o, d / norm[:, None], tmax)
        idx = np.flatnonzero(valid)
        if len(idx):
            t[idx], prim[idx] = self._first_hit_prim(o[idx], d[idx] / norm[idx, None], tmax[idx])
        return t, prim

    # --- to implement: inputs are finite, directions non-zero -------------------------------
    def _occluded(self, o: np.ndarray, d: np.ndarray, eps: float) -> np.ndarray:
        """Segments o + s d, s in [eps, 1 - eps] -> (n,) bool."""
        raise NotImplementedError

    def _first_hit(self, o: np.ndarray, u: np.ndarray, tmax: np.ndarray) -> np.ndarray:
        """Unit directions u, distances in [0, tmax] -> (n,) float, inf for misses."""
        raise NotImplementedError

    def _first_hit_prim(self, o: np.ndarray, u: np.ndarray, tmax: np.ndarray) -> tuple:
        """As ``_first_hit``, with the triangle hit (-1 for misses)."""
        raise NotImplementedError


# ------------------------------------------------------------------------------------------
# Embree
# ------------------------------------------------------------------------------------------

def _import_embree():
    from embreex import mesh_construction, rtcore_scene  # noqa: F401  (compiled modules)
    return rtcore_scene, mesh_construction


class EmbreeOccluder(Occluder):
    """embreex (Embree 4) scene; queries are float32, chunked and threaded.

    Notes on embreex 4.4 ``EmbreeScene.run(origins, dirs, dists, query, output)``: tnear is
    always 0 (we move origins instead), ``dists`` is the per-ray tfar in units of |dir| and is
    overwritten in place for DISTANCE/INTERSECT, OCCLUDED returns geomID (-1 = free), arrays must
    be float32 (no conversion), and the scene commits lazily on the first ``run`` (not
    thread-safe), so we commit in the constructor with a dummy ray.
    """

    name = "embree"

    def __init__(self, triangles, threads: int | None = None, chunk: int = _EMBREE_CHUNK):
        super().__init__(triangles)
        rtcs, mc = _import_embree()
        self.threads = max(1, int(threads if threads is not None else (os.cpu_count() or 1)))
        self.chunk = max(1, int(chunk))
        self._scene = None
        if self.n_triangles == 0:
            self._centre = np.zeros(3)
            return
        lo = self.triangles.min(axis=(0, 1))
        hi = self.triangles.max(axis=(0, 1))
        self._centre = 0.5 * (lo + hi)
        tri32 = np.ascontiguousarray(self.triangles - self._centre, dtype=np.float32)
        self._scene = rtcs.EmbreeScene(robust=True)
        self._mesh = mc.TriangleMesh(self._scene, tri32)  # keep a reference
        z = np.zeros((1, 3), np.float32)
        self._scene.run(z, np.ones((1, 3), np.float32), dists=np.zeros(1, np.float32),
                        query="OCCLUDED")  # commit now, single-threaded

    def _pieces(self, n: int):
        size = self.chunk
        if self.threads > 1 and n >= _THREAD_MIN_RAYS:
            size = min(size, -(-n // self.threads))
        return [(a, min(a + size, n)) for a in range(0, n, size)]

    def _map(self, fn, n: int):
        pieces = self._pieces(n)
        if self.threads == 1 or len(pieces) == 1:
            for a, b in pieces:
                fn(a, b)
            return
        with ThreadPoolExecutor(max_workers=min(self.threads, len(pieces))) as ex:
            for f in [ex.submit(fn, a, b) for a, b in pieces]:
                f.result()

    def _occluded(self, o, d, eps):
        out = np.empty(len(o), bool)
        c = self._centre
        tfar = np.float32(1.0 - 2.0 * eps)

        def work(a, b):
            dr = d[a:b].astype(np.float32)
            org = (o[a:b] - c).astype(np.float32)   # centre in float64, then round
            if eps:
                org += np.float32(eps) * dr
            tf = np.full(b - a, tfar, np.float32)
            out[a:b] = self._scene.run(org, dr, dists=tf, query="OCCLUDED") >= 0

        self._map(work, len(o))
        return out

    def _first_hit(self, o, u, tmax):
        return self._first_hit_prim(o, u, tmax)[0]

    def _first_hit_prim(self, o, u, tmax):
        t, prim = np.empty(len(o)), np.empty(len(o), np.int64)
        c = self._centre

        def work(a, b):
            org = (o[a:b] - c).astype(np.float32)
            dr = u[a:b].astype(np.float32)
            tf = np.minimum(tmax[a:b], np.finfo(np.float32).max).astype(np.float32)
            res = self._scene.run(org, dr, dists=tf, query="INTERSECT", output=True)
            hit = res["geomID"] >= 0
            t[a:b] = np.where(hit, res["tfar"].astype(np.float64), np.inf)
            prim[a:b] = np.where(hit, res["primID"], -1)

        self._map(work, len(o))
        return t, prim


# ------------------------------------------------------------------------------------------
# numpy brute force
# ------------------------------------------------------------------------------------------

class NumpyOccluder(Occluder):
    """Moller-Trumbore over every ray x triangle pair, in blocks of ~1 M pairs (float64)."""

    name = "numpy"

    def __init__(self, triangles, block: int = _NUMPY_BLOCK):
        super().__init__(triangles)
        t = self.triangles
        self._v0 = t[:, 0]
        self._e1 = t[:, 1] - t[:, 0]
        self._e2 = t[:, 2] - t[:, 0]
        self._scale = (np.linalg.norm(self._e1, axis=1) * np.linalg.norm(self._e2, axis=1))
        self._rows = max(1, int(block) // max(1, self.n_triangles))

    def _mt(self, o, d):
        """Parameters (s, hit) for rays o + s d against all triangles: (m, t) arrays."""
        e1, e2, v0 = self._e1[None], self._e2[None], self._v0[None]
        dd = d[:, None, :]
        p = np.cross(dd, e2)
        det = np.einsum("mtk,mtk->mt", np.broadcast_to(e1, p.shape), p)
        dn = np.linalg.norm(d, axis=1)[:, None]
        ok = np.abs(det) > _DET_REL * self._scale[None] * dn
        inv = 1.0 / np.where(ok, det, 1.0)
        tv = o[:, None, :] - v0
        u = np.einsum("mtk,mtk->mt", tv, p) * inv
        q = np.cross(tv, e1)
        v = np.einsum("mtk,mtk->mt", dd, q) * inv
        s = np.einsum("mtk,mtk->mt", np.broadcast_to(e2, q.shape), q) * inv
        ok &= (u >= 0) & (v >= 0) & (u + v <= 1)
        return s, ok

    def _occluded(self, o, d, eps):
        out = np.empty(len(o), bool)
        for a in range(0, len(o), self._rows):
            s, ok = self._mt(o[a:a + self._rows], d[a:a + self._rows])
            out[a:a + self._rows] = (ok & (s >= eps) & (s <= 1.0 - eps)).any(axis=1)
        return out

    def _first_hit(self, o, u, tmax):
        return self._first_hit_prim(o, u, tmax)[0]

    def _first_hit_prim(self, o, u, tmax):
        t, prim = np.empty(len(o)), np.empty(len(o), np.int64)
        for a in range(0, len(o), self._rows):
            s, ok = self._mt(o[a:a + self._rows], u[a:a + self._rows])
            ok &= (s >= 0) & (s <= tmax[a:a + self._rows, None])
            s = np.where(ok, s, np.inf)
            j = s.argmin(axis=1)
            best = s[np.arange(len(s)), j]
            t[a:a + self._rows] = best
            prim[a:a + self._rows] = np.where(np.isfinite(best), j, -1)
        return t, prim


# ------------------------------------------------------------------------------------------
# selection
# ------------------------------------------------------------------------------------------

_BACKENDS = {"embree": EmbreeOccluder, "numpy": NumpyOccluder}
_IMPORT_CHECKS = {"embree": _import_embree, "numpy": lambda: None}
_AUTO_ORDER = ["embree"]


def register_backend(name: str, factory, import_check, auto: bool = True):
    """Add a backend (e.g. the bridge's mathutils BVHTree): ``factory(triangles, **kwargs)``
    builds an Occluder, ``import_check()`` raises when it cannot work here; with ``auto`` it
    is tried after the ones registered before it."""
    _BACKENDS[name] = factory
    _IMPORT_CHECKS[name] = import_check
    if auto and name not in _AUTO_ORDER:
        _AUTO_ORDER.append(name)


def _importable(name: str) -> bool:
    try:
        _IMPORT_CHECKS[name]()
        return True
    except Exception:  # ImportError, or a wheel whose shared library fails to load
        return False


def available_backends() -> list[str]:
    """Importable backends in order of preference ("numpy" is always last and always there)."""
    return [n for n in _AUTO_ORDER if _importable(n)] + ["numpy"]


def active_backend_name(backend: str = "auto") -> str | None:
    """Name of the backend ``make_occluder(backend=...)`` would use now, None if it would fail."""
    if backend != "auto":
        return backend if backend in _BACKENDS and _importable(backend) else None
    for n in _AUTO_ORDER:
        if _importable(n):
            return n
    return None


def make_occluder(triangles, backend: str = "auto", **kwargs) -> Occluder:
    """Build an occluder over world-space triangles (t, 3, 3).

    ``backend``: "auto" (Embree if embreex imports, else a registered fallback such as the
    bridge's mathutils BVHTree), or a backend's name ("embree", "numpy", "bvhtree" once the
    bridge is imported).  Extra keyword arguments go to the backend's constructor.
    """
    if backend == "auto":
        name = active_backend_name("auto")
        if name is None:
            raise RuntimeError(
                "Relight needs a ray caster: neither Embree (the 'embreex' wheel) nor Blender's "
                "'mathutils.bvhtree' could be imported.")
    elif backend in _BACKENDS:
        name = backend
    else:
        raise ValueError(f"unknown ray-casting backend {backend!r}; "
                         f"expected 'auto' or one of {sorted(_BACKENDS)}")
    return _BACKENDS[name](triangles, **kwargs)
