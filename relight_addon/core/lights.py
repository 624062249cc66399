"""Lamps that are not Lambertian patches: Blender point, spot and sun lights, and area lights
whose spread is below 180 degrees, with their direct irradiance as Cycles computes it.

Area lights at full spread and emissive faces are Lambertian polygons: they are lamp patches of
the scene and exchange light through links.  The lights here have no Lambertian surface, so the
radiosity solution receives their light as direct irradiance per leaf, and texel mode per texel;
both come from :func:`light_irradiance`.

Units (measured against Cycles bakes of Blender 5.0.1: ``benchmarks/results/light_units.md``,
formulas in ``scenes/light_models.py``, the independent reference of the tests).  ``intensity``
(n, 3) is per kind:

* POINT: radiant intensity I = P colour / (4 pi) W/sr.  Radius 0: E = I cos / d^2.  Radius r:
  uniform radiance L = I / (pi r^2) over the cone the light fills seen from the receiver,
  sin(beta) = r / sqrt(d^2 + r^2) with soft falloff (a disk facing the receiver), r / d without
  (a sphere; inside it E = pi L on any plane); E = L x cone_irradiance(sin beta, cos theta).
* SPOT: the POINT, times Cycles' smoothstep mask of the direction light -> receiver in the
  light's scale-corrected local frame (no extra cosine, not renormalised to the cone).
* SUN: irradiance S colour (W/m^2) on a plane facing it; the disc of angular diameter ``angle``
  only matters near the horizon and for soft shadows.
* AREA (spread below 180 degrees): exitance M (W/m^2) of a rectangle or ellipse emitting along
  its local -Z, with Cycles' power-conserving spread profile on the Lambertian radiance.
* POLYGON: exitance M (W/m^2) of one planar face (``corners``, a triangle as (a, b, c, c))
  emitting on the side of -Z (one row per side): a virtual emissive mesh's face, a lamp that was
  not in the photo, lit without new patches or links (``SceneData.lamps_as_polygons``).

Visibility: ``rays`` segments per (point group, light), from the group's points (in turn) to
points spread over the light (a disk facing the receiver, the sun's disc of directions, the area
light's surface) on an R2 sequence with a random rotation per pair; the visible fraction is
weighted by what each sample contributes (cos, spot mask, spread profile x kernel).  The first
FIRST_RAYS decide; only pairs that see part of the light and miss part of it get the rest.
"""
from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from .geometry.formfactor import point_to_polygon
from .geometry.sampling import R2
from .geometry.patch import quad_area_normal
from .numerics import nonzero, safe_div

POINT, SPOT, SUN, AREA, POLYGON = 0, 1, 2, 3, 4
KIND_NAMES = {POINT: "point", SPOT: "spot", SUN: "sun", AREA: "area", POLYGON: "polygon"}
FIRST_RAYS = 16
ELLIPSE_SEGMENTS = 32          # polygon of an ellipse (same area) for the exact form factor
_CHUNK = 1 << 18               # (point, ray) pairs per ray-casting batch


@dataclass
class Lights:
    """Structure of arrays, one row per light; ``lamp`` indexes the scene's lamps.

    axes (n, 3, 3): rows are the light object's unit local X, Y, Z axes in world space (a spot
    and an area light emit along -Z, a sun shines along -Z); scale (n, 3): the object's scale
    along them (it shapes a spot's cone).  size (n, 2): an area light's world widths along X and
    Y (diameters when ``round``).  corners (n, 4, 3): a POLYGON's face (zeros for the others);
    its ``radius`` bounds it around ``position``.  See the module docstring for ``intensity``.
    """
    kind: np.ndarray
    lamp: np.ndarray
    position: np.ndarray
    axes: np.ndarray
    scale: np.ndarray
    intensity: np.ndarray
    radius: np.ndarray
    soft_falloff: np.ndarray
    spot_size: np.ndarray
    spot_blend: np.ndarray
    angle: np.ndarray
    size: np.ndarray
    round: np.ndarray
    spread: np.ndarray
    corners: np.ndarray

    def __post_init__(self):
        n = len(np.atleast_1d(self.kind))
        shapes = {"position": (n, 3), "axes": (n, 3, 3), "scale": (n, 3), "intensity": (n, 3),
                  "size": (n, 2), "corners": (n, 4, 3)}
        for f in fields(self):
            a = np.asarray(getattr(self, f.name))
            dtype = {"kind": np.int8, "lamp": np.int32, "soft_falloff": bool,
                     "round": bool}.get(f.name, np.float64)
            shape = shapes.get(f.name, (n,))
            if n == 0:
                a = np.zeros(shape)
            setattr(self, f.name, np.broadcast_to(a.astype(dtype), shape).copy())

    def __len__(self):
        return len(self.kind)

    @staticmethod
    def empty() -> "Lights":
        return Lights(*(np.zeros((0,)) for _ in fields(Lights)))

    @staticmethod
    def concat(parts) -> "Lights":
        parts = [p for p in parts if len(p)]
        if not parts:
            return Lights.empty()
        return Lights(*(np.concatenate([getattr(p, f.name) for p in parts]) for f in fields(Lights)))

    @staticmethod
    def make(kind, lamp, matrix, intensity, radius=0.0, soft_falloff=True, spot_size=np.pi / 4,
             spot_blend=0.15, angle=0.0, size=(1.0, 1.0), round=False, spread=np.pi):
        """One light from its object's 4x4 world ``matrix`` (position, axes and scale)."""
        if kind == POLYGON:
            raise ValueError("a polygon light is made with Lights.polygons")
        m = np.asarray(matrix, np.float64)
        cols = m[:3, :3].T                                   # rows: world images of X, Y, Z
        scale = np.linalg.norm(cols, axis=1)
        axes = cols / nonzero(scale)[:, None]
        return Lights(kind, lamp, m[:3, 3], axes, scale, np.asarray(intensity, float), radius,
                      soft_falloff, spot_size, spot_blend, angle, np.asarray(size, float), round,
                      spread, np.zeros((4, 3)))

    @staticmethod
    def polygons(lamp, corners, exitance) -> "Lights":
        """POLYGON lights: faces ``corners`` (n, 4, 3), each emitting ``exitance`` (n, 3) on the
        side its corners wind counter-clockwise around (their area normal)."""
        c = np.asarray(corners, np.float64).reshape(-1, 4, 3)
        n = len(c)
        if n == 0:
            return Lights.empty()
        _, normal = quad_area_normal(c)
        centre = c.mean(axis=1)
        u = c[:, 1] - c[:, 0]
        u -= np.einsum("ij,ij->i", u, normal)[:, None] * normal
        u /= nonzero(np.linalg.norm(u, axis=1))[:, None]
        v = np.cross(-normal, u)
        axes = np.stack([u, v, -normal], axis=1)           # emits along local -Z = the normal
        radius = np.linalg.norm(c - centre[:, None], axis=2).max(axis=1)
        return Lights(np.full(n, POLYGON), np.broadcast_to(lamp, (n,)), centre, axes,
                      np.ones((n, 3)), np.asarray(exitance, float), radius, True, 0.0, 0.0, 0.0,
                      np.zeros((n, 2)), False, np.pi, c)

    @property
    def emit_axis(self) -> np.ndarray:
        """(n, 3) unit direction the light points along (local -Z)."""
        return -self.axes[:, 2]

    def polygon(self, i) -> np.ndarray:
        """(k, 3) outline of area light ``i`` (an equal-area polygon for an ellipse)."""
        if self.kind[i] == POLYGON:
            return self.corners[i]
        u, v = self.axes[i, 0], self.axes[i, 1]
        lu, lv = self.size[i]
        if self.round[i]:
            ph = 2 * np.pi * np.arange(ELLIPSE_SEGMENTS) / ELLIPSE_SEGMENTS
            k = np.sqrt(2 * np.pi / ELLIPSE_SEGMENTS / np.sin(2 * np.pi / ELLIPSE_SEGMENTS))
            s = 0.5 * k * np.stack([np.cos(ph), np.sin(ph)], 1)
        else:
            s = 0.5 * np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], float)
        # counter-clockwise seen from the emitting side (-Z)
        s = s[::-1]
        return self.position[i] + s[:, :1] * lu * u + s[:, 1:] * lv * v

    def fingerprint_arrays(self):
        """Everything the lights' light depends on except their powers (colour kept)."""
        peak = self.intensity.max(axis=1, keepdims=True)
        colour = np.where(peak > 0, self.intensity / np.where(peak > 0, peak, 1.0), 0.0)
        return [self.kind, self.lamp, self.position, self.axes, self.scale, colour, self.radius,
                self.soft_falloff, self.spot_size, self.spot_blend, self.angle, self.size,
                self.round, self.spread, self.corners]


# -- closed forms ------------------------------------------------------------------------------

def cone_irradiance(sin_beta, cos_theta):
    """Irradiance from a circular cone of half-angle beta and UNIT radiance on a plane whose
    normal makes angle theta with the cone axis (pi times the sphere-to-tilted-element view
    factor): pi sin^2(beta) cos(theta) while the cone is wholly above the horizon, 0 once wholly
    below, the partial-visibility closed form in between."""
    sb = np.clip(np.asarray(sin_beta, np.float64), 1e-12, 1.0)
    ct = np.clip(np.asarray(cos_theta, np.float64), -1.0, 1.0)
    sb, ct = np.broadcast_arrays(sb, ct)
    st = np.sqrt(np.maximum(1.0 - ct * ct, 0.0))
    full = ct >= sb
    none = ct <= -sb
    out = np.where(full, np.pi * sb * sb * ct, 0.0)
    part = ~(full | none)
    if np.any(part):
        s, c, t = sb[part], ct[part], st[part]
        h2 = 1.0 / (s * s)
        root = np.sqrt(np.maximum(h2 - 1.0, 0.0))
        a1 = np.arcsin(np.clip(safe_div(root / np.sqrt(h2), t), -1.0, 1.0))
        a2 = np.arccos(np.clip(safe_div(-root * c, t), -1.0, 1.0))
        a3 = np.sqrt(np.maximum(1.0 - h2 * c * c, 0.0))
        f = 0.5 - a1 / np.pi + (c * a2 - root * a3) / (np.pi * h2)
        out[part] = np.pi * np.maximum(f, 0.0)
    return out


def spot_mask(lights, i, rays):
    """Cycles' spot mask for rays (m, 3) travelling from spot ``i`` (need not be unit)."""
    ax, sc = lights.axes[i], lights.scale[i]
    loc = np.stack([rays @ ax[0] / sc[0], rays @ ax[1] / sc[1], -(rays @ ax[2]) / sc[2]], -1)
    z = safe_div(loc[..., 2], np.linalg.norm(loc, axis=-1))
    ch = np.cos(0.5 * lights.spot_size[i])
    if lights.spot_blend[i] <= 0:
        return (z > ch).astype(np.float64)
    x = np.clip((z - ch) / ((1.0 - ch) * lights.spot_blend[i]), 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def spread_profile(angle, spread):
    """Cycles' factor on a Lambertian area light's radiance at emission ``angle`` from its
    normal: (tan h - tan angle) / (tan h - h) below h = spread / 2, else 0; power-conserving."""
    h = 0.5 * float(spread)
    a = np.asarray(angle, np.float64)
    if h >= 0.5 * np.pi - 1e-7:
        return np.ones_like(a)
    norm = 1.0 / (np.tan(h) - h) if h > 0.05 else 3.0 / h ** 3
    return np.where(a < h, np.maximum(np.tan(h) - np.tan(np.minimum(a, h)), 0.0) * norm, 0.0)


def _closed_form(lights, i, p, n):
    """Unoccluded irradiance without spot mask or spread profile, per point (m,): POINT / SPOT
    with their radius, SUN with its disc, AREA as a Lambertian polygon (times exitance 1)."""
    kind = lights.kind[i]
    if kind == SUN:
        ct = n @ (-lights.emit_axis[i])
        sb = np.sin(0.5 * lights.angle[i])
        if sb < 1e-6:
            return np.maximum(ct, 0.0)
        return cone_irradiance(sb, ct) / (np.pi * sb * sb)
    if kind in (AREA, POLYGON):
        poly = lights.polygon(i)
        return point_to_polygon(p, n, np.broadcast_to(poly, (len(p),) + poly.shape),
                                np.broadcast_to(lights.emit_axis[i], p.shape))
    w = lights.position[i] - p
    d = np.linalg.norm(w, axis=1)
    ct = safe_div(np.einsum("ij,ij->i", w, n), d)
    r = lights.radius[i]
    if r <= 0:
        return safe_div(np.maximum(ct, 0.0), d * d)
    L = 1.0 / (np.pi * r * r)
    if lights.soft_falloff[i]:
        return L * cone_irradiance(r / np.sqrt(d * d + r * r), ct)
    e = L * cone_irradiance(np.minimum(safe_div(r, d), 1.0), ct)
    return np.where(d <= r, np.pi * L, e)


# -- samples over each light -------------------------------------------------------------------

def _frame(w):
    """Two unit vectors perpendicular to each row of w (m, 3)."""
    a = np.where(np.abs(w[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t1 = np.cross(a, w)
    t1 /= nonzero(np.linalg.norm(t1, axis=1, keepdims=True))
    return t1, np.cross(w, t1)


def _samples(lights, i, p, j, shift, far):
    """End points (m, 3) of ray j (m,) from points p (m, 3) towards light i: an R2 sequence,
    shifted per point group (``shift`` (m, 2)), over the light's disk, disc of directions or
    surface."""
    xu = np.mod(0.5 + j * R2[0] + shift[:, 0], 1.0)
    xv = np.mod(0.5 + j * R2[1] + shift[:, 1], 1.0)
    kind = lights.kind[i]
    if kind == SUN:
        sb = np.sin(0.5 * lights.angle[i])
        axis = -lights.emit_axis[i]
        if sb < 1e-6:
            return p + far * axis
        cb = np.sqrt(1.0 - sb * sb)
        cz = 1.0 - xu * (1.0 - cb)
        sz = np.sqrt(np.maximum(1.0 - cz * cz, 0.0))
        t1, t2 = _frame(np.broadcast_to(axis, p.shape))
        ph = 2 * np.pi * xv
        d = cz[:, None] * axis + (sz * np.cos(ph))[:, None] * t1 + (sz * np.sin(ph))[:, None] * t2
        return p + far * d
    if kind == POLYGON:
        # uniform over the face: the triangles (a, b, c) and (a, c, d) by their areas
        a, b, c, d = lights.corners[i]
        a1 = np.linalg.norm(np.cross(b - a, c - a))
        a2 = np.linalg.norm(np.cross(c - a, d - a))
        split = safe_div(a1, a1 + a2)
        first = xu < split
        x = np.where(first, safe_div(xu, split), safe_div(xu - split, 1.0 - split))
        r = np.sqrt(np.clip(x, 0.0, 1.0))
        p1, p2 = np.where(first[:, None], b, c), np.where(first[:, None], c, d)
        return a + (r * (1 - xv))[:, None] * (p1 - a) + (r * xv)[:, None] * (p2 - a)
    if kind == AREA:
        u, v = lights.axes[i, 0], lights.axes[i, 1]
        lu, lv = lights.size[i]
        if lights.round[i]:
            rad, ph = 0.5 * np.sqrt(xu), 2 * np.pi * xv
            su, sv = rad * np.cos(ph), rad * np.sin(ph)
        else:
            su, sv = xu - 0.5, xv - 0.5
        return lights.position[i] + (su * lu)[:, None] * u + (sv * lv)[:, None] * v
    # POINT / SPOT: a disk of the light's radius facing each point
    w = lights.position[i] - p
    r = lights.radius[i]
    if r <= 0:
        return np.broadcast_to(lights.position[i], p.shape).copy()
    t1, t2 = _frame(safe_div(w, np.linalg.norm(w, axis=1, keepdims=True)))
    rad, ph = r * np.sqrt(xu), 2 * np.pi * xv
    return lights.position[i] + (rad * np.cos(ph))[:, None] * t1 + \
        (rad * np.sin(ph))[:, None] * t2


def _sample_weight(lights, i, p, n, q):
    """(weight, reference) of each light sample q (m, 3) seen from p (m, 3) with normal n: the
    visible fraction is sum(weight x visible) / sum(reference), the unoccluded factor on the
    closed form sum(weight) / sum(reference).  POINT and SUN: cos at the receiver for both
    (the closed form has the cosine already); SPOT: x the spot mask; AREA: the kernel cos cos' /
    r^2, x the spread profile."""
    d = q - p
    dist = np.linalg.norm(d, axis=1)
    cos_r = np.maximum(safe_div(np.einsum("ij,ij->i", d, n), dist), 0.0)
    kind = lights.kind[i]
    if kind == SPOT:
        return cos_r * spot_mask(lights, i, -d), cos_r
    if kind in (AREA, POLYGON):
        cos_l = np.maximum(safe_div(-(d @ lights.emit_axis[i]), dist), 0.0)
        k = safe_div(cos_r * cos_l, dist * dist)
        return k * spread_profile(np.arccos(np.clip(cos_l, -1.0, 1.0)), lights.spread[i]), k
    return cos_r, cos_r


# -- the irradiance ----------------------------------------------------------------------------

def light_irradiance(lights: Lights, points, normals, occluder=None, rays=16, seed=0,
                     scene_size=1.0, offset=0.0, weights=None):
    """Direct irradiance (n, m, 3) from each of the m lights at unit factor: (unoccluded, with
    visibility).  ``points`` (n, 3), or (n, S, 3) for groups of S points whose mean is wanted
    (a texel's footprint, a leaf's quadrature points), with ``normals`` (n, 3); ``weights``
    (n, S) the points' shares of their group's mean (area weights; None: equal).  Ray end
    points are lifted by ``offset`` along the receiver's normal; sun rays are 4 x
    ``scene_size`` long."""
    points = np.asarray(points, float)
    points = points.reshape(len(points), -1, 3) if points.ndim == 3 else points.reshape(-1, 1, 3)
    normals = np.asarray(normals, float).reshape(-1, 3)
    n_pts, S = points.shape[:2]
    if weights is not None:
        weights = np.asarray(weights, float).reshape(n_pts, S)
        total = weights.sum(axis=1, keepdims=True)
        weights = np.where(total > 0, weights / np.where(total > 0, total, 1.0), 1.0 / S)
    m = len(lights)
    unocc = np.zeros((n_pts, m, 3))
    occ = np.zeros((n_pts, m, 3))
    if n_pts == 0 or m == 0:
        return unocc, occ
    rng = np.random.default_rng(seed)
    far = 4.0 * max(float(scene_size), 1e-9)
    flat_n = np.repeat(normals, S, axis=0)
    for i in range(m):
        base = _closed_form(lights, i, points.reshape(-1, 3), flat_n).reshape(n_pts, S)
        base = base.mean(axis=1) if weights is None else np.einsum("ns,ns->n", base, weights)
        live = np.flatnonzero(base > 0)
        unocc_f = np.zeros(n_pts)
        occ_f = np.zeros(n_pts)
        if len(live):
            u_fac, o_fac = _visible_factor(lights, i, points[live], normals[live], occluder,
                                           rays, rng, far, offset,
                                           None if weights is None else S * weights[live])
            unocc_f[live] = base[live] * u_fac
            occ_f[live] = base[live] * o_fac
        unocc[:, i] = unocc_f[:, None] * lights.intensity[i]
        occ[:, i] = occ_f[:, None] * lights.intensity[i]
    return unocc, occ


def _visible_factor(lights, i, pts, nrm, occluder, rays, rng, far, offset, point_weight=None):
    """(unoccluded factor, occluded factor) per point group on the closed form: the spot mask or
    spread profile averaged over the light's samples (1 for a point or sun), and that times the
    visible fraction; each point's rays count ``point_weight`` (g, S) times (None: once)."""
    g, S = pts.shape[:2]
    kind = lights.kind[i]
    single = (kind in (POINT, SPOT) and lights.radius[i] <= 0) or \
        (kind == SUN and np.sin(0.5 * lights.angle[i]) < 1e-6)
    needs_profile = kind in (SPOT, AREA)
    if occluder is None and not needs_profile:
        return np.ones(g), np.ones(g)
    # a light of one point: one ray from every point of the group (one ray in all let the
    # group's first point decide a leaf's or a texel footprint's shadow alone)
    total = S if single else max(int(rays), FIRST_RAYS if occluder is None else 1)
    shift = rng.random((g, 2))
    sums = np.zeros((3, g))                       # weight, weight x visible, reference
    n_free = np.zeros(g)
    n_blocked = np.zeros(g)

    def cast(sel, j0, count):
        step = max(1, _CHUNK // max(count, 1))
        for c0 in range(0, len(sel), step):
            idx = sel[c0:c0 + step]
            j = np.tile(np.arange(j0, j0 + count), len(idx))
            row = np.repeat(idx, count)
            p, nn = pts[row, j % S], nrm[row]
            q = _samples(lights, i, p, j.astype(float), shift[row], far)
            wt, ref = _sample_weight(lights, i, p, nn, q)
            if point_weight is not None:
                pw = point_weight[row, j % S]
                wt, ref = wt * pw, ref * pw
            blocked = (occluder.segments_occluded(p + offset * nn, q) if occluder is not None
                       else np.zeros(len(p), bool))
            for k, x in enumerate((wt, wt * ~blocked, ref)):
                sums[k] += np.bincount(row, x, g)
            n_free[:] += np.bincount(row, (ref > 0) & ~blocked, g)
            n_blocked[:] += np.bincount(row, (ref > 0) & blocked, g)

    first = total if single else min(total, FIRST_RAYS)
    cast(np.arange(g), 0, first)
    more = np.arange(g) if occluder is None else np.flatnonzero((n_free > 0) & (n_blocked > 0))
    if total > first and len(more):
        cast(more, first, total - first)
    ok = sums[2] > 0
    u_fac = np.where(ok, sums[0] / np.where(ok, sums[2], 1.0), 0.0)
    o_fac = np.where(ok, sums[1] / np.where(ok, sums[2], 1.0), 0.0)
    # a sphere light wholly around the point: lit from everywhere, no mask, no shadow
    if kind in (POINT, SPOT) and lights.radius[i] > 0 and not lights.soft_falloff[i]:
        inside = np.linalg.norm(lights.position[i] - pts.mean(axis=1), axis=1) <= lights.radius[i]
        u_fac[inside] = o_fac[inside] = 1.0
    return u_fac, o_fac
