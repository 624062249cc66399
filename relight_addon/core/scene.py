"""SceneData: the one boundary type between Blender (or a test generator) and the maths.

Every patch is a planar bilinear patch with four corners ``(a, b, c, d)`` in counter-clockwise
order seen from the front (normal side).  A triangle repeats its last corner: ``(a, b, c, c)``.
The bilinear map ``P(u, v) = (1-u)(1-v) a + u(1-v) b + u v c + (1-u) v d`` is then a valid
(Duffy) parametrisation of the triangle, so quads and triangles share one code path in the
hierarchy: a 4-way split at ``u, v = 1/2`` gives planar sub-patches whose areas add up exactly.

Units: emission is exitance (W/m^2, radiosity units).  Reflectance is linear RGB in [0, 1).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .geometry.extent import longest_side
# the patch geometry (bilinear_point, quad_area_normal) lives below the scene; it is read from
# here too (the bridge, tests)
from .geometry.patch import bilinear_point, quad_area_normal  # noqa: F401
from .lights import Lights
from .numerics import safe_div

# Relative tolerance (to the patch size) above which a quad counts as non-planar and is split.
PLANARITY_TOLERANCE = 1e-4
# Faces with an area below this fraction of the mean face area are dropped as degenerate.
DEGENERATE_AREA_FRACTION = 1e-10
# Reflectances are kept below this (user materials and estimates alike): the radiosity system
# must stay solvable, and no real diffuse surface reflects more.
RHO_MAX = 0.99


class SceneError(ValueError):
    """Input the solver cannot work with; the message is meant for the user."""


@dataclass
class ImageTexels:
    """One photograph used by the scene's materials: linear RGB texels (h, w, 3) float32, row 0
    at the bottom (Blender's order), and their mean."""
    name: str
    texels: np.ndarray
    mean: np.ndarray
    filepath: str = ""
    colorspace: str = ""


def _non_planarity(corners: np.ndarray) -> np.ndarray:
    """Distance of corner d from the plane of (a, b, c), relative to the patch diameter."""
    a, b, c, d = (corners[:, i, :] for i in range(4))
    n = np.cross(b - a, c - a)
    nn = np.linalg.norm(n, axis=-1)
    size = np.maximum(np.linalg.norm(c - a, axis=-1), np.linalg.norm(d - b, axis=-1))
    dist = safe_div(np.abs(np.einsum("ij,ij->i", d - a, n)), nn)
    return safe_div(dist, size)


@dataclass
class SceneData:
    """Patches (structure of arrays) plus optional texture data and a viewpoint.

    corners   (p, 4, 3) float64  planar bilinear patches, triangles as (a, b, c, c)
    rho       (p, 3)    float64  diffuse reflectance, linear RGB
    emission  (p, 3)    float64  exitance; non-zero only on lamp patches
    lamp      (p,)      int32    index into ``lamp_names`` for emitters, -1 otherwise
    occluder  (p,)      bool     whether the patch blocks rays (Blender area lights do not)
    group     (p,)      int32    caller's grouping (object/material), carried through untouched
    uv        (p, 4, 2) optional texture coordinates of the corners
    image     (p,)      optional index into ``images`` (-1: none)
    lamp_intensity (k,) each lamp's intensity in the scene as given (the photo), relative to its
                        emission here: a lamp that is off in the photo keeps a reference emission
                        (light transport is linear, so its basis can still be solved) with
                        intensity 0.  Default: every lamp at 1.
    lights    Lights    lamps that are not patches (point, spot, sun, area with a spread):
                        core/lights.py; each row names its lamp index.
    virtual   (p,)      bool: patches of virtual objects (not in the photo: they cast shadows on
                        and reflect light onto the photographed surfaces, which are relit)
    """

    corners: np.ndarray
    rho: np.ndarray
    emission: np.ndarray
    lamp: np.ndarray
    lamp_names: list = field(default_factory=list)
    occluder: np.ndarray | None = None
    group: np.ndarray | None = None
    uv: np.ndarray | None = None
    image: np.ndarray | None = None
    images: list = field(default_factory=list)
    viewpoint: np.ndarray | None = None
    lamp_intensity: np.ndarray | None = None
    lights: object = None
    virtual: np.ndarray | None = None
    dropped_degenerate: int = 0
    dropped_duplicate: int = 0
    duplicate_groups: list = field(default_factory=list)   # (dropped group, kept group) pairs

    def __post_init__(self):
        p = len(self.corners)
        self.corners = np.asarray(self.corners, dtype=np.float64).reshape(p, 4, 3)
        self.rho = np.broadcast_to(np.asarray(self.rho, dtype=np.float64), (p, 3)).copy()
        self.emission = np.broadcast_to(np.asarray(self.emission, dtype=np.float64), (p, 3)).copy()
        self.lamp = np.broadcast_to(np.asarray(self.lamp, dtype=np.int32), (p,)).copy()
        self.occluder = (np.ones(p, bool) if self.occluder is None
                         else np.broadcast_to(np.asarray(self.occluder, bool), (p,)).copy())
        self.group = (np.zeros(p, np.int32) if self.group is None
                      else np.broadcast_to(np.asarray(self.group, np.int32), (p,)).copy())
        self.virtual = (np.zeros(p, bool) if self.virtual is None
                        else np.broadcast_to(np.asarray(self.virtual, bool), (p,)).copy())
        if not np.all(np.isfinite(self.corners)):
            raise SceneError("Some vertices have non-finite coordinates")
        if np.any(self.rho < 0) or np.any(self.rho >= 1):
            raise SceneError("Reflectance must lie in [0, 1): a value of 1 or more never converges")
        if np.any(self.emission < 0) or not np.all(np.isfinite(self.emission)):
            raise SceneError("Emission must be finite and non-negative")
        if self.lights is None:
            self.lights = Lights.empty()
        top = max(int(self.lamp.max(initial=-1)), int(self.lights.lamp.max(initial=-1)))
        if top >= len(self.lamp_names):
            self.lamp_names = list(self.lamp_names) + [
                f"lamp {i}" for i in range(len(self.lamp_names), top + 1)]
        emitting = self.emission.max(axis=1) > 0
        if np.any(emitting & (self.lamp < 0)):
            raise SceneError("Every emitting patch needs a lamp index")
        k = len(self.lamp_names)
        self.lamp_intensity = (np.ones(k) if self.lamp_intensity is None
                               else np.asarray(self.lamp_intensity, np.float64).reshape(-1))
        if len(self.lamp_intensity) != k:
            raise SceneError(f"lamp_intensity has {len(self.lamp_intensity)} values for {k} lamps")
        if not np.all(np.isfinite(self.lamp_intensity)) or np.any(self.lamp_intensity < 0):
            raise SceneError("Lamp intensities must be finite and non-negative")
        self._split_non_planar()
        self._drop_degenerate()
        self._drop_duplicates()

    # -- construction helpers -------------------------------------------------------------
    def _per_patch_arrays(self):
        names = ["corners", "rho", "emission", "lamp", "occluder", "group", "virtual"]
        if self.uv is not None:
            names.append("uv")
        if self.image is not None:
            names.append("image")
        return names

    def _take(self, index):
        for name in self._per_patch_arrays():
            setattr(self, name, np.asarray(getattr(self, name))[index])

    def _split_non_planar(self):
        bad = _non_planarity(self.corners) > PLANARITY_TOLERANCE
        if not bad.any():
            return
        # Split each non-planar quad (a, b, c, d) into (a, b, c, c) and (a, c, d, d).
        keep = np.flatnonzero(~bad)
        split = np.flatnonzero(bad)
        order = np.concatenate([keep, split, split])
        self._take(order)
        n_keep, n_split = len(keep), len(split)
        first = slice(n_keep, n_keep + n_split)
        second = slice(n_keep + n_split, None)
        c = self.corners
        c[first, 3] = c[first, 2]
        c[second, 1], c[second, 2], c[second, 3] = c[second, 2].copy(), c[second, 3].copy(), c[second, 3].copy()
        if self.uv is not None:
            t = self.uv
            t[first, 3] = t[first, 2]
            t[second, 1], t[second, 2], t[second, 3] = t[second, 2].copy(), t[second, 3].copy(), t[second, 3].copy()

    def _drop_degenerate(self):
        area, _ = quad_area_normal(self.corners)
        if len(area) == 0:
            return
        floor = DEGENERATE_AREA_FRACTION * max(float(area.mean()), 1e-300)
        bad = ~(area > floor)
        self.dropped_degenerate += int(bad.sum())
        if bad.any():
            self._take(np.flatnonzero(~bad))

    def _drop_duplicates(self):
        """Faces with the same corners (in any order) and the same facing count once: a second
        copy would z-fight in the photo and double the light it reflects."""
        if self.n_patches < 2:
            return
        _, normal = quad_area_normal(self.corners)
        size = longest_side(self.corners)
        key = np.round(np.sort(self.corners.reshape(-1, 4, 3), axis=1) / (1e-9 * size)).reshape(-1, 12)
        key = np.concatenate([key, np.round(normal * 1e6)], axis=1)
        _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
        if len(first) < self.n_patches:
            self.dropped_duplicate += self.n_patches - len(first)
            dup = np.flatnonzero(first[inverse.reshape(-1)] != np.arange(self.n_patches))
            pairs = np.stack([self.group[dup], self.group[first[inverse.reshape(-1)][dup]]], 1)
            self.duplicate_groups = [tuple(int(x) for x in p) for p in np.unique(pairs, axis=0)]
            self._take(np.sort(first))

    def with_rho(self, rho) -> "SceneData":
        """A shallow copy with other patch reflectances (clipped to [0, RHO_MAX]; the patches
        are already cleaned, so nothing is split or dropped again)."""
        new = object.__new__(SceneData)
        new.__dict__.update(self.__dict__)
        new.rho = np.clip(np.asarray(rho, float), 0.0, RHO_MAX)
        return new

    def without_virtual(self) -> "SceneData":
        """A copy without the virtual objects' patches (the scene the photo shows); the others
        keep their order, so they come first in the full scene too (virtual patches are last:
        see ``virtual_last``)."""
        new = object.__new__(SceneData)
        new.__dict__.update(self.__dict__)
        new._take(np.flatnonzero(~self.virtual))
        return new

    def virtual_last(self) -> "SceneData":
        """A copy with the virtual objects' patches moved after all the others."""
        if not self.virtual.any():
            return self
        new = object.__new__(SceneData)
        new.__dict__.update(self.__dict__)
        new._take(np.concatenate([np.flatnonzero(~self.virtual), np.flatnonzero(self.virtual)]))
        return new

    def lamps_as_polygons(self, lamps) -> "SceneData":
        """A copy where the patches of ``lamps`` (indices) are POLYGON lights instead: the same
        light, but no patches, so no new elements or links (a virtual emissive mesh, which
        blocks nothing, can then be added to a solved room like any other light).  Each face
        emits on the side of its normal (a two-sided face is two patches)."""
        move = np.flatnonzero(np.isin(self.lamp, list(lamps)))
        if len(move) == 0:
            return self
        rows = []
        for k in np.unique(self.lamp[move]):
            faces = move[self.lamp[move] == k]
            rows.append(Lights.polygons(int(k), self.corners[faces], self.emission[faces]))
        new = object.__new__(SceneData)
        new.__dict__.update(self.__dict__)
        new._take(np.setdiff1d(np.arange(self.n_patches), move))
        new.lights = Lights.concat([self.lights] + rows)
        return new

    def without_lamps(self, drop) -> "SceneData":
        """A shallow copy without the lamps ``drop`` (indices) that are lights (core Lights,
        not patches): the other lamps keep their order, renumbered."""
        drop = set(int(k) for k in drop)
        if any(int(k) in drop for k in np.unique(self.lamp[self.lamp >= 0])):
            raise ValueError("only lamps that are lights can be left out")
        keep = [k for k in range(self.n_lamps) if k not in drop]
        renumber = np.full(self.n_lamps, -1)
        renumber[keep] = np.arange(len(keep))
        new = object.__new__(SceneData)
        new.__dict__.update(self.__dict__)
        new.lamp_names = [self.lamp_names[k] for k in keep]
        new.lamp_intensity = self.lamp_intensity[keep]
        rows = np.flatnonzero(~np.isin(self.lights.lamp, list(drop)))
        import dataclasses
        lights = self.lights
        new.lights = dataclasses.replace(
            lights, **{f.name: getattr(lights, f.name)[rows] for f in dataclasses.fields(lights)})
        new.lights.lamp = renumber[new.lights.lamp]
        new.lamp = np.where(self.lamp >= 0, renumber[np.maximum(self.lamp, 0)], -1).astype(self.lamp.dtype)
        return new

    # -- derived quantities ---------------------------------------------------------------
    @property
    def n_patches(self) -> int:
        return len(self.corners)

    @property
    def n_lamps(self) -> int:
        return len(self.lamp_names)

    def area_normal(self):
        return quad_area_normal(self.corners)

    def occluder_triangles(self, with_patches=False):
        """(t, 3, 3) triangles of every occluding patch (degenerate halves are dropped); with
        ``with_patches`` also the patch of each, (t,)."""
        ids = np.flatnonzero(self.occluder)
        c = self.corners[ids]
        tris = np.concatenate([c[:, [0, 1, 2]], c[:, [0, 2, 3]]])
        e = np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=-1)
        if with_patches:
            return tris[e > 0], np.concatenate([ids, ids])[e > 0]
        return tris[e > 0]

    def make_occluder(self):
        """A ray caster of the occluding patches (None without any) that knows the patch of
        each of its triangles (``patch_of_triangle``)."""
        from .geometry.raycast import make_occluder
        tris, patches = self.occluder_triangles(with_patches=True)
        if not len(tris):
            return None
        occluder = make_occluder(tris)
        occluder.patch_of_triangle = patches
        return occluder

    def validate_for_solve(self):
        """Raise SceneError for scenes the solver cannot light."""
        if self.n_patches == 0:
            raise SceneError("The scene has no usable faces")
        lit = np.zeros(self.n_lamps, bool)
        on = self.lamp >= 0
        np.logical_or.at(lit, self.lamp[on], self.emission[on].max(axis=1) > 0)
        np.logical_or.at(lit, self.lights.lamp, self.lights.intensity.max(axis=1) > 0)
        if not np.any(lit & (self.lamp_intensity > 0)):
            if np.any(self.lamp >= 0):
                raise SceneError("Every lamp has zero power: set the real lamps to their power "
                                 "in the photo before Precompute (then animate them)")
            raise SceneError("The scene has no lamps: add an area light or an emissive face")


def quads_from_boxes(center, size) -> np.ndarray:
    """The six outward-facing faces (6, 4, 3) of an axis-aligned box."""
    cx, cy, cz = np.asarray(center, float)
    hx, hy, hz = np.asarray(size, float) / 2
    x0, x1, y0, y1, z0, z1 = cx - hx, cx + hx, cy - hy, cy + hy, cz - hz, cz + hz
    return np.array([
        [[x0, y0, z0], [x0, y1, z0], [x1, y1, z0], [x1, y0, z0]],  # bottom (-z)
        [[x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]],  # top (+z)
        [[x0, y0, z0], [x1, y0, z0], [x1, y0, z1], [x0, y0, z1]],  # front (-y)
        [[x0, y1, z0], [x0, y1, z1], [x1, y1, z1], [x1, y1, z0]],  # back (+y)
        [[x0, y0, z0], [x0, y0, z1], [x0, y1, z1], [x0, y1, z0]],  # left (-x)
        [[x1, y0, z0], [x1, y1, z0], [x1, y1, z1], [x1, y0, z1]],  # right (+x)
    ])


def scene_fingerprint(data: SceneData, textures: bool = True) -> str:
    """A hash of everything a precompute depends on: geometry, UVs, reflectances, textures,
    which patches emit, block rays and belong together, and each lamp's colour, but not the
    lamps' powers (the relit materials follow those through their drivers).  Without
    ``textures``: only what the radiosity mesh and links depend on (no images, reflectances
    or UVs)."""
    import hashlib
    h = hashlib.sha256()
    emission = np.asarray(data.emission, np.float64)
    colour = np.zeros_like(emission)
    for k in range(data.n_lamps):
        sel = data.lamp == k
        peak = emission[sel].max() if sel.any() else 0.0
        if peak > 0:
            colour[sel] = emission[sel] / peak
    # groups as a partition (numbered by first patch): objects read in between renumber them
    _, first, inverse = np.unique(data.group, return_index=True, return_inverse=True)
    group = np.argsort(np.argsort(first))[inverse.ravel()]
    arrays = [data.corners, colour, data.lamp, data.occluder, group, data.virtual,
              *data.lights.fingerprint_arrays()]
    if textures:
        arrays += [data.rho] + [a for a in (data.uv, data.image) if a is not None]
    for a in arrays:
        a = np.ascontiguousarray(a)
        h.update(str((a.dtype, a.shape)).encode())
        h.update(a.tobytes())
    h.update(repr(list(data.lamp_names)).encode())
    for im in (data.images if textures else ()):
        tex = np.ascontiguousarray(getattr(im, "texels", im))
        h.update(str(tex.shape).encode())
        h.update(tex.tobytes())
    return h.hexdigest()
