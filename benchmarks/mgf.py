"""Reader for MGF (Materials and Geometry Format), the scene format of RenderPark / rpkCpp.

``read_mgf(path)`` turns an MGF file (and the files it includes) into a ``SceneData``, so that
the radiosity solver can run on RenderPark's example scenes (benchmarks/bench_mgf.py; the
scene files are not shipped with the project: see there).

The semantics follow the MGF parser library that RenderPark embeds (Greg Ward's mgflib:
parse.c, context.c, xf.c):

* Vertices (``v``, ``p``, ``n``) are stored untransformed; a face is transformed by the ``xf``
  context current when the face is read.  A vertex name may be redefined: a face uses the
  definition current when it is read.  Normals are normalised on input.
* ``xf`` pushes a transform (``-t``, ``-rx/-ry/-rz``, ``-s``, ``-sx/-sy/-sz``, ``-mx/-my/-mz``,
  ``-i N`` to repeat the arguments that follow it N times), composed with the enclosing one;
  ``xf`` alone pops.  A mirroring transform reverses the vertex order, so faces keep facing the
  same side.  ``i file [xf arguments]`` reads a file (relative to the including one) in a
  transform of its own.
* The curved surfaces (``sph``, ``cyl``, ``cone``, ``ring``, ``torus``, ``prism``) are expanded
  into polygons exactly as mgflib's e_sph / e_cone / e_ring / e_torus / e_prism do, with
  ``nqcdivs`` divisions per quarter circle.  The default is RenderPark's (DEFAULT_NQCDIVS = 4,
  which RenderPark sets into mgflib's ``mg_nqcdivs``); mgflib's own default MG_NQCD is 5.
  As in MGF, negative radii of ``cone``/``cyl`` turn the normals inwards.
* Faces may be non-convex and may contain holes joined by a seam (a repeated vertex:
  ``f v0 v1 v2 v3 v4 v5 v6 v7 v8 v4``); they are cut into triangles by ear clipping in their
  plane.  Triangles and planar convex quads are kept as they are.
* Materials (``m``, ``m name``, ``m name = [template]``): ``rd`` (diffuse reflectance =
  luminance Y) and ``ed`` (diffuse emittance) with the colour current when they are set (``c``,
  ``cxy``).  ``ed`` becomes the emission (exitance) as it is: MGF gives it in lm/m^2, which
  RenderPark divides by its white efficacy (183.07 lm/W); light transport being linear, that is
  one scale for the whole scene.  ``rs``, ``ts``, ``td``, ``ir`` and ``sides`` are read and
  ignored: the solver is diffuse and one-sided, like RenderPark by default (it forces one-sided
  surfaces unless told otherwise).

Colour: MGF chromaticities are relative to an equal-energy white (cxy 1/3 1/3 is neutral, as in
RenderPark and Radiance), so XYZ is first scaled from that white to D65 (X and Z only, which
keeps Y), then converted to linear Rec. 709 RGB.  Neutral MGF colours thus become grey and the
luminance of the result is exactly rd (or ed) unless a negative component had to be clipped
to 0 (saturated colours outside the Rec. 709 gamut).  A reflectance with a component above
RHO_MAX (a bright saturated colour: the office's orange vinyl) is scaled down to it.

Entities the shipped scenes do not use (``fh``, ``ies``, ``cspec``, ``cct``, ``cmix``, arrays
``xf -a``) raise MgfError rather than being skipped silently.

    python benchmarks/mgf.py FILE [--lamps object|one] [--nqcdivs N]
"""
from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from relight_addon.core.scene import (PLANARITY_TOLERANCE, RHO_MAX, SceneData,  # noqa: E402
                                      quad_area_normal)
from relight_addon.core.texture.colour import LUMINANCE  # noqa: E402

# RenderPark's DEFAULT_NQCDIVS (mgflib's own MG_NQCD is 5).
NQCDIVS = 4
# mgflib's round0(): radii this close to zero are zero (e.g. rad * sin(pi) closing a sphere).
FTINY = 1e-6
# Corners closer than this (relative to the face size) count as the same point, and cross
# products below it (relative to size squared) as collinear.
REL_EPS = 1e-9
EQUAL_ENERGY_XY = (1.0 / 3.0, 1.0 / 3.0)


class MgfError(ValueError):
    """An MGF file this reader cannot read; the message names the file and line."""


# --------------------------------------------------------------------------- colour
def _xy_to_xyz(xy):
    x, y = xy
    return np.array([x / y, 1.0, (1.0 - x - y) / y])


# Linear sRGB (Rec. 709, D65) -> XYZ, IEC 61966-2-1; its Y row is the project's LUMINANCE.
_RGB_TO_XYZ = np.array([[0.4124, 0.3576, 0.1805], LUMINANCE, [0.0193, 0.1192, 0.9505]])
# XYZ relative to MGF's equal-energy white -> linear RGB: scale X and Z from that white to the
# matrix's own (RGB 1, 1, 1), keeping Y (so the luminance of the RGB result is Y), then invert.
_MGF_XYZ_TO_RGB = np.linalg.inv(_RGB_TO_XYZ) @ np.diag(
    _RGB_TO_XYZ.sum(axis=1) / _xy_to_xyz(EQUAL_ENERGY_XY))


def mgf_colour_to_rgb(xy, luminance: float) -> np.ndarray:
    """Linear RGB of an MGF colour (chromaticity xy) with luminance Y, negatives clipped."""
    if luminance == 0.0 or xy[1] <= 0.0:
        return np.zeros(3)
    return np.maximum(_MGF_XYZ_TO_RGB @ (_xy_to_xyz(xy) * luminance), 0.0)


# --------------------------------------------------------------------------- contexts
@dataclass
class _Colour:
    xy: tuple = EQUAL_ENERGY_XY


@dataclass
class _Material:
    rd: float = 0.0
    rd_xy: tuple = EQUAL_ENERGY_XY
    ed: float = 0.0
    ed_xy: tuple = EQUAL_ENERGY_XY


@dataclass
class _Vertex:
    p: np.ndarray = field(default_factory=lambda: np.zeros(3))
    n: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def copy(self):
        return _Vertex(self.p.copy(), self.n.copy())


def _xf_matrix(args) -> np.ndarray:
    """4x4 matrix of one ``xf`` argument list, for row vectors (p' = [p 1] M), as mgflib's xf():
    the operations apply in the order given; ``-i N`` repeats the ones after it (up to the next
    ``-i``) N times."""
    result = np.eye(4)
    pending = np.eye(4)
    count = 1
    i = 0
    while i < len(args):
        op = args[i]
        m = np.eye(4)
        try:
            if op == "-t":
                if len(args) < i + 4:
                    raise ValueError
                m[3, :3] = [float(a) for a in args[i + 1:i + 4]]
                i += 4
            elif op in ("-rx", "-ry", "-rz"):
                a = math.radians(float(args[i + 1]))
                c, s = math.cos(a), math.sin(a)
                j, k = {"-rx": (1, 2), "-ry": (2, 0), "-rz": (0, 1)}[op]
                m[j, j] = m[k, k] = c
                m[j, k], m[k, j] = s, -s
                i += 2
            elif op in ("-s", "-sx", "-sy", "-sz"):
                s = float(args[i + 1])
                if s == 0.0:
                    raise ValueError
                axes = {"-s": (0, 1, 2), "-sx": (0,), "-sy": (1,), "-sz": (2,)}[op]
                m[axes, axes] = s
                i += 2
            elif op in ("-mx", "-my", "-mz"):
                axis = "xyz".index(op[2])
                m[axis, axis] = -1.0
                i += 1
            elif op == "-i":
                result = result @ np.linalg.matrix_power(pending, count)
                count = int(args[i + 1])
                pending = np.eye(4)
                i += 2
                continue
            else:
                raise MgfError(f"unsupported xf argument {op!r}")
        except MgfError:
            raise
        except (ValueError, IndexError):
            raise MgfError(f"bad xf argument {op!r}") from None
        pending = pending @ m
    return result @ np.linalg.matrix_power(pending, count)


# --------------------------------------------------------------------------- curved surfaces
def _round0(x: float) -> float:
    return 0.0 if -FTINY <= x <= FTINY else x


def _cross3(a, b):
    """Cross products of (..., 3) arrays (np.cross is slow on small arrays)."""
    return np.stack([a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
                     a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
                     a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]], axis=-1)


def _make_axes(w):
    """mgflib's make_axes: u, v perpendicular to the unit vector w, (u, v, w) right-handed."""
    i = next(i for i in range(3) if -0.6 < w[i] < 0.6)
    v = np.zeros(3)
    v[i] = 1.0
    u = _cross3(v, w)
    u /= np.linalg.norm(u)
    return u, _cross3(w, u)


def cone_polygons(p1, r1, p2, r2, nqcdivs=NQCDIVS):
    """mgflib's e_cone: 4 * nqcdivs quads (triangles if one radius is 0) between the circle of
    radius r1 around p1 and the one of radius r2 around p2, both normal to p2 - p1.  Positive
    radii face outwards, negative ones inwards."""
    r1, r2 = _round0(r1), _round0(r2)
    if r1 == 0.0 and r2 == 0.0:
        raise MgfError("cone with two zero radii")
    if r1 != 0.0 and r2 != 0.0 and (r1 < 0.0) != (r2 < 0.0):
        raise MgfError("cone radii of opposite signs")
    if r2 == 0.0:
        p1, r1, p2, r2 = p2, r2, p1, r1
    w = np.asarray(p1, float) - p2
    length = np.linalg.norm(w)
    if length == 0.0:
        raise MgfError("cone of zero length")
    u, v = _make_axes(w / length)
    theta = math.copysign(1.0, r2) * np.arange(4 * nqcdivs + 1) * (math.pi / 2) / nqcdivs
    d = np.cos(theta)[:, None] * u + np.sin(theta)[:, None] * v
    rim2 = p2 + r2 * d
    if r1 == 0.0:
        return [np.array([p1, rim2[i - 1], rim2[i]]) for i in range(1, len(d))]
    rim1 = p1 + r1 * d
    return [np.array([rim1[i - 1], rim2[i - 1], rim2[i], rim1[i]]) for i in range(1, len(d))]


def sphere_polygons(centre, radius, nqcdivs=NQCDIVS):
    """mgflib's e_sph: 2 * nqcdivs cones stacked along z (4 * nqcdivs faces each)."""
    c = np.asarray(centre, float)
    polygons = []
    top, r_top = c + [0.0, 0.0, radius], 0.0
    for i in range(1, 2 * nqcdivs + 1):
        theta = i * (math.pi / 2) / nqcdivs
        bottom, r_bottom = c + [0.0, 0.0, radius * math.cos(theta)], radius * math.sin(theta)
        polygons += cone_polygons(top, r_top, bottom, r_bottom, nqcdivs)
        top, r_top = bottom, r_bottom
    return polygons


def torus_polygons(centre, normal, minrad, maxrad, nqcdivs=NQCDIVS):
    """mgflib's e_torus: the outer half as cones of positive radii, the inner half negative."""
    minrad = _round0(minrad)
    sgn = next((math.copysign(1.0, r) for r in (minrad, maxrad) if r != 0.0), 0.0)
    if sgn == 0.0 or sgn * (maxrad - minrad) <= 0.0 or not np.any(normal):
        raise MgfError("bad torus")
    c, n = np.asarray(centre, float), np.asarray(normal, float)
    tube, mean = 0.5 * (maxrad - minrad), 0.5 * (minrad + maxrad)
    half = sgn * tube
    polygons = []
    top, r_top = c + half * n, mean
    for i in range(1, 4 * nqcdivs + 1):
        theta = i * (math.pi / 2) / nqcdivs
        if i == 2 * nqcdivs + 1:
            r_top = -mean        # inner section: same tube, radii negated (normals inwards)
        bottom = c + half * math.cos(theta) * n
        r_bottom = (mean + tube * math.sin(theta) if i <= 2 * nqcdivs
                    else -mean - tube * math.sin(theta))
        polygons += cone_polygons(top, r_top, bottom, r_bottom, nqcdivs)
        top, r_top = bottom, r_bottom
    return polygons


def ring_polygons(centre, normal, minrad, maxrad, nqcdivs=NQCDIVS):
    """mgflib's e_ring: a disc (minrad 0, triangles) or annulus (quads) facing ``normal``."""
    minrad = _round0(minrad)
    if minrad < 0.0 or maxrad <= minrad or not np.any(normal):
        raise MgfError("bad ring")
    c = np.asarray(centre, float)
    u, v = _make_axes(np.asarray(normal, float))
    theta = np.arange(4 * nqcdivs + 1) * (math.pi / 2) / nqcdivs
    d = np.cos(theta)[:, None] * u + np.sin(theta)[:, None] * v
    outer = c + maxrad * d
    if minrad == 0.0:
        return [np.array([c, outer[i - 1], outer[i]]) for i in range(1, len(d))]
    inner = c + minrad * d
    return [np.array([inner[i - 1], outer[i - 1], outer[i], inner[i]]) for i in range(1, len(d))]


def prism_polygons(points, length):
    """mgflib's e_prism: the polygon ``points`` extruded by ``length`` against its normal."""
    p = np.asarray(points, float)
    normal = _cross3(p[1:-1] - p[0], p[2:] - p[0]).sum(axis=0)
    if abs(length) <= FTINY or np.linalg.norm(normal) == 0.0:
        raise MgfError("bad prism")
    moved = p - length * normal / np.linalg.norm(normal)
    sides = [np.array([moved[i], p[i], p[i - 1], moved[i - 1]]) for i in range(len(p))]
    return sides + [moved[::-1], p]


# --------------------------------------------------------------------------- triangulation
def _cross(o, a, b):
    """z of (a - o) x (b - o) for 2-D points given as tuples."""
    return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])


def _segments_cross(p, q, a, b, eps):
    """Whether the segments pq and ab cross at a point inside both (touching does not count)."""
    d1, d2 = _cross(a, b, p), _cross(a, b, q)
    d3, d4 = _cross(p, q, a), _cross(p, q, b)
    return ((d1 > eps and d2 < -eps) or (d1 < -eps and d2 > eps)) and \
           ((d3 > eps and d4 < -eps) or (d3 < -eps and d4 > eps))


def ear_clip(q) -> list:
    """Triangles (index triples, counter-clockwise) of a 2-D polygon q (n points, anticlockwise).

    The polygon may be non-convex and weakly simple: holes joined to the outline by a seam walk
    the seam twice, so corners repeat and edges overlap.  A corner is cut off when it is convex,
    the triangle holds no other corner (corners at the same place as its own do not count) and
    no edge crosses its new diagonal; a corner on a straight line or a needle (zero area) is
    dropped without a triangle.
    """
    q = [tuple(map(float, x)) for x in q]
    xs, ys = [x for x, _ in q], [y for _, y in q]
    size = max(max(xs) - min(xs), max(ys) - min(ys))
    eps_len, eps_area = REL_EPS * size, REL_EPS * size * size
    idx = list(range(len(q)))
    triangles = []
    while len(idx) > 3:
        m = len(idx)
        for k in range(m):
            a, b, c = idx[k - 1], idx[k], idx[(k + 1) % m]
            turn = _cross(q[a], q[b], q[c])
            if abs(turn) <= eps_area:
                del idx[k]
                break
            if turn > 0 and _is_ear(q, idx, a, b, c, eps_len, eps_area):
                triangles.append((a, b, c))
                del idx[k]
                break
        else:
            raise MgfError("face cannot be triangulated (self-intersecting?)")
    if len(idx) == 3 and _cross(q[idx[0]], q[idx[1]], q[idx[2]]) > eps_area:
        triangles.append(tuple(idx))
    return triangles


def _is_ear(q, idx, a, b, c, eps_len, eps_area):
    """Whether the convex corner b (between a and c) of the polygon idx can be cut off."""
    corners = (q[a], q[b], q[c])
    for i in idx:
        p = q[i]
        if any(abs(p[0] - x[0]) <= eps_len and abs(p[1] - x[1]) <= eps_len for x in corners):
            continue
        ab, bc, ca = _cross(q[a], q[b], p), _cross(q[b], q[c], p), _cross(q[c], q[a], p)
        if min(ab, bc, ca) > eps_area:
            return False                       # strictly inside
        if abs(ca) <= eps_area and min(ab, bc) > eps_area:
            return False                       # on the new diagonal c -> a
    m = len(idx)
    return not any(_segments_cross(q[idx[j]], q[idx[(j + 1) % m]], q[c], q[a], eps_area)
                   for j in range(m))


def face_patches(points: np.ndarray) -> list:
    """Planar patches (4, 3) of one face: itself if a triangle or a planar convex quad, else the
    triangles (a, b, c, c) of an ear clipping in its plane.  A zero-area face gives none."""
    p = np.asarray(points, float)
    d = p - p.mean(axis=0)
    area_vector = 0.5 * _cross3(d, np.concatenate((d[1:], d[:1]))).sum(axis=0)
    area = math.sqrt(area_vector @ area_vector)
    size = float((p.max(axis=0) - p.min(axis=0)).max())
    if area <= REL_EPS * size * size:
        return []
    normal = area_vector / area
    if len(p) == 3:
        return [p[[0, 1, 2, 2]]]
    q = (d @ np.stack(_make_axes(normal), axis=1)).tolist()
    if len(p) == 4:
        turns = [_cross(q[i - 1], q[i], q[(i + 1) % 4]) for i in range(4)]
        planar = np.abs(d @ normal).max() <= PLANARITY_TOLERANCE * size
        if planar and min(turns) > REL_EPS * size * size:
            return [p]
    return [p[[a, b, c, c]] for a, b, c in ear_clip(q)]


# --------------------------------------------------------------------------- parser
@dataclass
class MgfModel:
    """What an MGF file describes: patches with their material and object, and counts."""
    corners: np.ndarray          # (p, 4, 3)
    rho: np.ndarray              # (p, 3)
    emission: np.ndarray         # (p, 3)
    obj: np.ndarray              # (p,) index into object_names
    object_names: list
    faces: int                   # input polygons: f entities and those of the curved surfaces
    surface_faces: int           # of which from sph, cyl, cone, ring, torus, prism
    empty_faces: int             # faces of zero area (no patch)

    def scene(self, lamps: str = "object") -> SceneData:
        """SceneData of the model.  lamps="object": each MGF object with emitting faces is one
        lamp (named after the object); lamps="one": all emitting faces form one lamp."""
        emitting = self.emission.max(axis=1) > 0
        lamp = np.full(len(self.corners), -1, np.int32)
        if lamps == "object":
            order = {o: k for k, o in enumerate(dict.fromkeys(self.obj[emitting].tolist()))}
            lamp[emitting] = [order[o] for o in self.obj[emitting].tolist()]
            names = [self.object_names[o] for o in order]
        elif lamps == "one":
            lamp[emitting] = 0
            names = ["emitters"] if emitting.any() else []
        else:
            raise ValueError(f"lamps must be 'object' or 'one', not {lamps!r}")
        return SceneData(self.corners, self.rho, self.emission, lamp, names, group=self.obj)


class _Reader:
    def __init__(self, nqcdivs: int):
        self.nqcdivs = nqcdivs
        self.vertices: dict = {}
        self.vertex = _Vertex()
        self.colours: dict = {}
        self.colour = _Colour()
        self.materials: dict = {}
        self.material = _Material()
        self.objects: list = []
        self.xf: list = [(np.eye(4), False)]     # (matrix, whether it mirrors)
        self.object_ids: dict = {}
        self.rgb_cache: dict = {}
        self.patches, self.rho, self.emission, self.obj = [], [], [], []
        self.faces = self.surface_faces = self.empty_faces = 0
        self.handlers = {
            "v": self.e_vertex, "p": self.e_point, "n": self.e_normal, "f": self.e_face,
            "c": self.e_colour, "cxy": self.e_cxy, "m": self.e_material, "rd": self.e_rd,
            "ed": self.e_ed, "rs": self.e_ignore(3), "ts": self.e_ignore(3),
            "td": self.e_ignore(2), "ir": self.e_ignore(3), "sides": self.e_ignore(2),
            "o": self.e_object, "xf": self.e_xf, "i": self.e_include,
            "sph": self.e_sph, "cyl": self.e_cyl, "cone": self.e_cone, "ring": self.e_ring,
            "torus": self.e_torus, "prism": self.e_prism,
        }

    # -- files ------------------------------------------------------------------------------
    def read(self, path: Path):
        lines = path.read_text().splitlines()
        pending = ""
        for number, line in enumerate(lines, 1):
            if line.endswith("\\"):            # continued on the next line
                pending += line[:-1] + " "
                continue
            words = (pending + line).split()
            pending = ""
            if not words or words[0].startswith("#"):
                continue
            handler = self.handlers.get(words[0])
            try:
                if handler is None:
                    raise MgfError(f"unsupported entity {words[0]!r}")
                handler(words, path)
            except MgfError as exc:
                raise MgfError(f"{path}:{number}: {exc}") from None

    def e_include(self, w, path):
        if len(w) < 2:
            raise MgfError("i needs a file name")
        depth = len(self.xf)
        if len(w) > 2:
            self.e_xf(["xf"] + w[2:], path)
        self.read(path.parent / w[1])
        del self.xf[depth:]             # an included file's transforms end with it

    # -- vertices ---------------------------------------------------------------------------
    def e_vertex(self, w, path):
        if len(w) == 1:
            self.vertex = _Vertex()
        elif len(w) == 2:
            self.vertex = self._vertex(w[1])
        elif w[2] == "=" and len(w) <= 4:
            self.vertex = self._vertex(w[3]).copy() if len(w) == 4 else _Vertex()
            self.vertices[w[1]] = self.vertex
        else:
            raise MgfError("v takes: name [= [template]]")

    def _vertex(self, name) -> _Vertex:
        if name not in self.vertices:
            raise MgfError(f"undefined vertex {name!r}")
        return self.vertices[name]

    def e_point(self, w, path):
        self.vertex.p = self._floats(w, 3)

    def e_normal(self, w, path):
        n = self._floats(w, 3)
        length = np.linalg.norm(n)
        self.vertex.n = n / length if length > 0 else n

    @staticmethod
    def _floats(w, count):
        if len(w) != count + 1:
            raise MgfError(f"{w[0]} takes {count} numbers")
        try:
            return np.array([float(x) for x in w[1:]])
        except ValueError:
            raise MgfError(f"{w[0]}: not a number in {w[1:]}") from None

    # -- colours and materials --------------------------------------------------------------
    def e_colour(self, w, path):
        self.colour = self._context(w, self.colours, _Colour, "colour")

    def e_cxy(self, w, path):
        x, y = self._floats(w, 2)
        if x < 0 or y <= 0 or x + y > 1:
            raise MgfError(f"bad chromaticity {x} {y}")
        self.colour.xy = (x, y)

    def e_material(self, w, path):
        self.material = self._context(w, self.materials, _Material, "material")

    @staticmethod
    def _context(w, table, default, kind):
        """``c``/``m``: alone, a fresh unnamed context; ``name``, an existing one; ``name =
        [template]``, (re)define ``name`` as the default or as a copy of the template."""
        if len(w) == 1:
            return default()
        if len(w) == 2:
            if w[1] not in table:
                raise MgfError(f"undefined {kind} {w[1]!r}")
            return table[w[1]]
        if w[2] != "=" or len(w) > 4:
            raise MgfError(f"{w[0]} takes: name [= [template]]")
        if len(w) == 4 and w[3] not in table:
            raise MgfError(f"undefined {kind} {w[3]!r}")
        table[w[1]] = replace(table[w[3]]) if len(w) == 4 else default()
        return table[w[1]]

    def e_rd(self, w, path):
        rd = float(self._floats(w, 1)[0])
        if not 0.0 <= rd <= 1.0:
            raise MgfError(f"rd {rd} outside [0, 1]")
        self.material.rd, self.material.rd_xy = rd, self.colour.xy

    def e_ed(self, w, path):
        ed = float(self._floats(w, 1)[0])
        if ed < 0.0:
            raise MgfError(f"negative ed {ed}")
        self.material.ed, self.material.ed_xy = ed, self.colour.xy

    @staticmethod
    def e_ignore(words):
        def check(w, path):
            if len(w) != words:
                raise MgfError(f"{w[0]} takes {words - 1} values")
        return check

    # -- objects and transforms -------------------------------------------------------------
    def e_object(self, w, path):
        if len(w) == 1:
            if not self.objects:
                raise MgfError("o closes no object")
            self.objects.pop()
        else:
            self.objects.append(w[1])

    def e_xf(self, w, path):
        if len(w) == 1:
            if len(self.xf) == 1:
                raise MgfError("xf pops no transform")
            self.xf.pop()
        elif "-a" in w:
            raise MgfError("xf arrays (-a) are not supported")
        else:
            m = _xf_matrix(w[1:]) @ self.xf[-1][0]
            self.xf.append((m, np.linalg.det(m[:3, :3]) < 0))

    # -- geometry ---------------------------------------------------------------------------
    def e_face(self, w, path):
        if len(w) < 4:
            raise MgfError("a face needs 3 vertices or more")
        self._add_face(np.array([self._vertex(name).p for name in w[1:]]))

    def _add_face(self, local):
        """One polygon in the coordinates of the current xf context."""
        self.faces += 1
        m, mirror = self.xf[-1]
        points = local @ m[:3, :3] + m[3, :3]
        if mirror:
            points = points[::-1]                # else the mirror would turn the face around
        patches = face_patches(points)
        if not patches:
            self.empty_faces += 1
            return
        rho, emission = self._rgb()
        obj = self._object_id()
        self.patches += patches
        self.rho += [rho] * len(patches)
        self.emission += [emission] * len(patches)
        self.obj += [obj] * len(patches)

    def _rgb(self):
        mat = self.material
        key = (mat.rd, mat.rd_xy, mat.ed, mat.ed_xy)
        if key not in self.rgb_cache:
            rho = mgf_colour_to_rgb(mat.rd_xy, mat.rd)
            if rho.max() > RHO_MAX:      # as RenderPark: scale down, keeping the colour
                rho *= RHO_MAX / rho.max()
            self.rgb_cache[key] = rho, mgf_colour_to_rgb(mat.ed_xy, mat.ed)
        return self.rgb_cache[key]

    def _object_id(self):
        name = "/".join(self.objects) or "(no object)"
        return self.object_ids.setdefault(name, len(self.object_ids))

    def _surface(self, polygons):
        self.surface_faces += len(polygons)
        for polygon in polygons:
            self._add_face(polygon)

    def _radius(self, word):
        try:
            return float(word)
        except ValueError:
            raise MgfError(f"not a radius: {word!r}") from None

    def e_sph(self, w, path):
        if len(w) != 3:
            raise MgfError("sph takes: centre radius")
        self._surface(sphere_polygons(self._vertex(w[1]).p, self._radius(w[2]), self.nqcdivs))

    def e_cyl(self, w, path):
        if len(w) != 4:
            raise MgfError("cyl takes: v1 radius v2")
        r = self._radius(w[2])
        self._surface(cone_polygons(self._vertex(w[1]).p, r, self._vertex(w[3]).p, r,
                                    self.nqcdivs))

    def e_cone(self, w, path):
        if len(w) != 5:
            raise MgfError("cone takes: v1 radius1 v2 radius2")
        self._surface(cone_polygons(self._vertex(w[1]).p, self._radius(w[2]),
                                    self._vertex(w[3]).p, self._radius(w[4]), self.nqcdivs))

    def _about_axis(self, w, polygons):
        """ring and torus: a centre vertex (its normal the axis) and two radii."""
        if len(w) != 4:
            raise MgfError(f"{w[0]} takes: centre minradius maxradius")
        v = self._vertex(w[1])
        self._surface(polygons(v.p, v.n, self._radius(w[2]), self._radius(w[3]), self.nqcdivs))

    def e_ring(self, w, path):
        self._about_axis(w, ring_polygons)

    def e_torus(self, w, path):
        self._about_axis(w, torus_polygons)

    def e_prism(self, w, path):
        if len(w) < 5:
            raise MgfError("prism takes: v1 v2 v3 ... length")
        self._surface(prism_polygons([self._vertex(n).p for n in w[1:-1]], self._radius(w[-1])))


def parse_mgf(path, nqcdivs: int = NQCDIVS) -> MgfModel:
    """Read an MGF file (and its includes) into patches; see the module docstring."""
    reader = _Reader(nqcdivs)
    reader.read(Path(path))
    if not reader.patches:
        raise MgfError(f"{path}: no faces")
    return MgfModel(np.array(reader.patches), np.array(reader.rho), np.array(reader.emission),
                    np.array(reader.obj, np.int32), list(reader.object_ids),
                    reader.faces, reader.surface_faces, reader.empty_faces)


def read_mgf(path, lamps: str = "object", nqcdivs: int = NQCDIVS) -> SceneData:
    """SceneData of an MGF file: group = MGF object (innermost ``o``, by name), lamps per
    ``lamps`` ("object": one lamp per emitting object; "one": a single lamp)."""
    return parse_mgf(path, nqcdivs).scene(lamps)


# --------------------------------------------------------------------------- command line
def summary(path, lamps: str = "object", nqcdivs: int = NQCDIVS) -> dict:
    """The counts and sizes the command line prints."""
    model = parse_mgf(path, nqcdivs)
    scene = model.scene(lamps)
    area, _ = quad_area_normal(scene.corners)
    emitting = scene.lamp >= 0
    corners = scene.corners.reshape(-1, 3)
    return {
        "faces": model.faces, "surface_faces": model.surface_faces,
        "empty_faces": model.empty_faces, "patches_read": len(model.corners),
        "patches": scene.n_patches, "triangles": int(np.sum(np.all(
            scene.corners[:, 2] == scene.corners[:, 3], axis=1))),
        "dropped_degenerate": scene.dropped_degenerate,
        "dropped_duplicate": scene.dropped_duplicate,
        "lamps": len(scene.lamp_names), "lamp_names": scene.lamp_names,
        "emitting_patches": int(emitting.sum()),
        "area": float(area.sum()), "emitting_area": float(area[emitting].sum()),
        "bbox": (corners.min(axis=0), corners.max(axis=0)),
    }


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("file")
    parser.add_argument("--lamps", choices=("object", "one"), default="object")
    parser.add_argument("--nqcdivs", type=int, default=NQCDIVS,
                        help=f"divisions per quarter circle (default {NQCDIVS}, RenderPark's)")
    args = parser.parse_args(argv)
    s = summary(args.file, args.lamps, args.nqcdivs)
    lo, hi = s["bbox"]
    print(f"{args.file}")
    print(f"faces (input polygons): {s['faces']}  ({s['surface_faces']} from curved surfaces, "
          f"{s['empty_faces']} of zero area)")
    print(f"patches: {s['patches']}  ({s['triangles']} triangles; read {s['patches_read']}, "
          f"SceneData dropped {s['dropped_degenerate']} degenerate, "
          f"{s['dropped_duplicate']} duplicate)")
    print(f"lamps ({args.lamps}): {s['lamps']}  ({s['emitting_patches']} emitting patches)")
    if len(s["lamp_names"]) <= 30:
        print("  " + ", ".join(s["lamp_names"]))
    print(f"total area: {s['area']:.6g}")
    print(f"emitting area: {s['emitting_area']:.6g}")
    print(f"bounding box: {np.array2string(lo, precision=4)} .. {np.array2string(hi, precision=4)}")


if __name__ == "__main__":
    main()
