"""Independent form-factor references and patch-pair generators (deterministic), shared by the
form-factor, radiosity and source-split tests and by ``benchmarks/bench_formfactor.py``:

  * closed forms from Howell's catalogue (point to parallel rectangle, C-11 parallel rectangles,
    C-14 perpendicular rectangles with a common edge, coaxial parallel disks);
  * pyviewfactor (double contour integral, SA-30 kernel) on the mutually visible parts;
  * brute-force double Gauss integration of cos cos / (pi r^2) over both patches.

``pyviewfactor.compute_viewfactor(cell1, cell2)`` returns F(cell2 -> cell1), normalised by the
area of cell2 and with both cells' normals (right-handed winding) facing each other, so
F(recv -> src) = compute_viewfactor(src_cell, recv_cell).
"""
from __future__ import annotations

import numpy as np

from relight_addon.core.scene import quad_area_normal


# ------------------------------------------------------------------------------------------
# Closed forms (Howell, "A catalog of radiation heat transfer configuration factors")
# ------------------------------------------------------------------------------------------
def howell_point_to_rectangle(a, b, c):
    """Differential area to a parallel a x b rectangle at distance c, one corner above it."""
    A, B = a / c, b / c
    sa, sb = np.sqrt(1 + A * A), np.sqrt(1 + B * B)
    return (A / sa * np.arctan(B / sa) + B / sb * np.arctan(A / sb)) / (2 * np.pi)


def howell_c11(a, b, c):
    """C-11: directly opposed parallel a x b rectangles at distance c."""
    X, Y = a / c, b / c
    sx, sy = np.sqrt(1 + X * X), np.sqrt(1 + Y * Y)
    return 2 / (np.pi * X * Y) * (
        0.5 * np.log((1 + X * X) * (1 + Y * Y) / (1 + X * X + Y * Y))
        + X * sy * np.arctan(X / sy) + Y * sx * np.arctan(Y / sx)
        - X * np.arctan(X) - Y * np.arctan(Y))


def howell_c14(w, h, l):
    """C-14: F from a w x l rectangle to an h x l rectangle, perpendicular, sharing the l edge."""
    W, H = w / l, h / l
    W2, H2 = W * W, H * H
    s = np.sqrt(W2 + H2)
    log = (np.log((1 + W2) * (1 + H2) / (1 + W2 + H2))
           + W2 * np.log(W2 * (1 + W2 + H2) / ((1 + W2) * (W2 + H2)))
           + H2 * np.log(H2 * (1 + W2 + H2) / ((1 + H2) * (W2 + H2))))
    return (W * np.arctan(1 / W) + H * np.arctan(1 / H) - s * np.arctan(1 / s) + 0.25 * log) / (np.pi * W)


def coaxial_disks(r1, r2, h):
    """F from a disk of radius r1 to a coaxial parallel disk of radius r2 at distance h."""
    R1, R2 = r1 / h, r2 / h
    X = 1 + (1 + R2 * R2) / (R1 * R1)
    return 0.5 * (X - np.sqrt(X * X - 4 * (R2 / R1) ** 2))


# ------------------------------------------------------------------------------------------
# Geometry helpers
# ------------------------------------------------------------------------------------------
def rectangle(center, e1, e2, a, b):
    """Corners (4, 3) of an a x b rectangle, counter-clockwise about e1 x e2."""
    center, e1, e2 = (np.asarray(v, float) for v in (center, e1, e2))
    ha, hb = 0.5 * a * e1, 0.5 * b * e2
    return np.array([center - ha - hb, center + ha - hb, center + ha + hb, center - ha + hb])


def random_rotation(rng):
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


def newell_normal(poly):
    """Unnormalised Newell normal (length = twice the area) of a planar polygon (k, 3)."""
    nxt = np.roll(poly, -1, axis=0)
    return np.cross(poly, nxt).sum(axis=0)


def polygon_area(poly):
    return 0.5 * np.linalg.norm(newell_normal(poly))


def clip_polygon(poly, normal, origin):
    """Part of a convex polygon (k, 3) with (p - origin) . normal >= 0 (Sutherland-Hodgman)."""
    out = []
    d = (poly - origin) @ normal
    for i in range(len(poly)):
        j = (i + 1) % len(poly)
        if d[i] >= 0:
            out.append(poly[i])
        if (d[i] >= 0) != (d[j] >= 0):
            t = d[i] / (d[i] - d[j])
            out.append(poly[i] + t * (poly[j] - poly[i]))
    return np.array(out).reshape(-1, 3)


def dedupe(poly, tol=1e-12):
    """Drop consecutive repeated vertices (triangles stored as (a, b, c, c))."""
    keep = [p for i, p in enumerate(poly) if np.linalg.norm(p - poly[i - 1]) > tol]
    return np.array(keep)


def _segment_hits_rectangle(p, q, half_a, half_b):
    """Liang-Barsky: does the 2D segment p-q meet the box |x| <= half_a, |y| <= half_b?"""
    t0, t1 = 0.0, 1.0
    d = q - p
    for pi, di, lim in ((p[0], d[0], half_a), (p[1], d[1], half_b)):
        for s in (1.0, -1.0):  # s * (pi + t di) <= lim
            num, den = lim - s * pi, s * di
            if abs(den) < 1e-15:
                if num < 0:
                    return False
            elif den > 0:
                t1 = min(t1, num / den)
            else:
                t0 = max(t0, num / den)
    return t0 <= t1


def facing_pairs(n=50, seed=20240607):
    """n random rectangle pairs, each wholly in front of the other (no clipping, no contact).

    Returns recv (n, 4, 3), src (n, 4, 3).  Sizes 0.3..2, centre distances 0.6..3 times the
    larger size, sources tilted up to ~60 degrees away from facing the receiver's centre.
    """
    rng = np.random.default_rng(seed)
    recv, src = [], []
    while len(recv) < n:
        rot = random_rotation(rng)
        e1, e2, nr = rot[:, 0], rot[:, 1], rot[:, 2]
        a, b = rng.uniform(0.3, 2.0, 2)
        c0 = rng.uniform(-3, 3, 3)
        r = rectangle(c0, e1, e2, a, b)
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction)
        if direction @ nr < 0.2:
            continue
        a2, b2 = rng.uniform(0.3, 2.0, 2)
        dist = rng.uniform(0.6, 3.0) * max(a, b, a2, b2)
        c1 = c0 + dist * direction
        ns = -direction + rng.uniform(0, 1.7) * np.cross(direction, rng.normal(size=3))
        ns /= np.linalg.norm(ns)
        t = np.cross(ns, rng.normal(size=3))
        t /= np.linalg.norm(t)
        s = rectangle(c1, t, np.cross(ns, t), a2, b2)
        if np.min((s - c0) @ nr) < 1e-3 or np.min((r - c1) @ ns) < 1e-3:
            continue
        recv.append(r)
        src.append(s)
    return np.array(recv), np.array(src)


def straddling_pairs(n=20, seed=777):
    """n random non-intersecting rectangle pairs where the source crosses the receiver's plane
    (and sometimes the receiver crosses the source's plane), with a visible part both ways."""
    rng = np.random.default_rng(seed)
    recv, src = [], []
    while len(recv) < n:
        rot = random_rotation(rng)
        e1, e2, nr = rot[:, 0], rot[:, 1], rot[:, 2]
        a, b = rng.uniform(0.3, 2.0, 2)
        c0 = rng.uniform(-3, 3, 3)
        r = rectangle(c0, e1, e2, a, b)
        # Source centre close to the receiver plane, off to the side.
        lateral = rng.normal(size=2)
        lateral /= np.linalg.norm(lateral)
        a2, b2 = rng.uniform(0.3, 2.0, 2)
        off = rng.uniform(0.7, 2.5) * max(a, b, a2, b2)
        c1 = c0 + off * (lateral[0] * e1 + lateral[1] * e2) + rng.uniform(-0.3, 0.6) * a2 * nr
        ns = rng.normal(size=3)
        ns /= np.linalg.norm(ns)
        t = np.cross(ns, rng.normal(size=3))
        t /= np.linalg.norm(t)
        s = rectangle(c1, t, np.cross(ns, t), a2, b2)
        ds = (s - c0) @ nr
        if not (ds.min() < -1e-2 and ds.max() > 1e-2):
            continue
        if ((r - c1) @ ns).max() < 1e-2:
            continue
        # The source's chord in the receiver plane must miss the receiver rectangle.
        chord = [s[i] + ds[i] / (ds[i] - ds[(i + 1) % 4]) * (s[(i + 1) % 4] - s[i])
                 for i in range(4) if (ds[i] >= 0) != (ds[(i + 1) % 4] >= 0)]
        p, q = (np.array([(x - c0) @ e1, (x - c0) @ e2]) for x in chord[:2])
        if _segment_hits_rectangle(p, q, 0.5 * a + 1e-2, 0.5 * b + 1e-2):
            continue
        vr, vs = visible_parts(r, s)  # keep pairs with a sizeable mutually visible part
        if len(vr) < 3 or len(vs) < 3 or polygon_area(vr) < 0.2 * a * b or polygon_area(vs) < 0.2 * a2 * b2:
            continue
        recv.append(r)
        src.append(s)
    return np.array(recv), np.array(src)


def visible_parts(recv, src):
    """Receiver part in front of the source plane, source part in front of the receiver plane."""
    _, nr = quad_area_normal(recv)
    _, ns = quad_area_normal(src)
    return clip_polygon(dedupe(recv), ns, src[0]), clip_polygon(dedupe(src), nr, recv[0])


def _triangle_rule(tri, m):
    """Collapsed (Duffy) Gauss rule on a triangle: points (m*m, 3), weights summing to its area."""
    x, w = np.polynomial.legendre.leggauss(m)
    x, w = 0.5 * (x + 1), 0.5 * w
    s, t = np.meshgrid(x, x, indexing="ij")
    ws = np.outer(w, w) * (1 - s)  # d(u, v) = (1 - s) ds dt with u = s, v = (1 - s) t
    u, v = s, (1 - s) * t
    a, b, c = tri
    pts = a + u.reshape(-1, 1) * (b - a) + v.reshape(-1, 1) * (c - a)
    return pts, ws.ravel() * np.linalg.norm(np.cross(b - a, c - a))


def polygon_rule(poly, m):
    pts, ws = zip(*(_triangle_rule(np.array([poly[0], poly[i], poly[i + 1]]), m)
                    for i in range(1, len(poly) - 1)))
    return np.concatenate(pts), np.concatenate(ws)


def brute_force_ff(recv, src, m=24):
    """F(recv -> src) by direct double Gauss integration of cos cos / (pi r^2) over the mutually
    visible parts (smooth integrand: no contact, both cosines >= 0 there)."""
    area_r, nr = quad_area_normal(recv)
    _, ns = quad_area_normal(src)
    vr, vs = visible_parts(recv, src)
    if len(vr) < 3 or len(vs) < 3:
        return 0.0
    pr, wr = polygon_rule(vr, m)
    ps, ws = polygon_rule(vs, m)
    d = ps[None, :, :] - pr[:, None, :]
    r2 = np.einsum("ijk,ijk->ij", d, d)
    cos_r = np.clip(d @ nr, 0, None)
    cos_s = np.clip(-(d @ ns), 0, None)
    kern = cos_r * cos_s / (np.pi * r2 * r2)
    return float(wr @ kern @ ws) / area_r


def pvf_ff(recv, src):
    """F(recv -> src) from pyviewfactor on the mutually visible parts (pyviewfactor integrates
    the double contour formula, which is only valid for fully mutually visible polygons)."""
    import pyvista as pv
    import pyviewfactor as pvf

    def cell(poly):
        poly = np.ascontiguousarray(poly, dtype=np.float64)
        return pv.PolyData(poly, faces=np.r_[len(poly), np.arange(len(poly))])

    area_r, _ = quad_area_normal(recv)
    vr, vs = visible_parts(recv, src)
    if len(vr) < 3 or len(vs) < 3:
        return 0.0
    # compute_viewfactor(cell1, cell2) = F(cell2 -> cell1); A_r F_rs = A_vs F(vs -> vr).
    return polygon_area(vs) * pvf.compute_viewfactor(cell(vr), cell(vs)) / area_r


def relative_errors(ours, ref):
    return np.abs(ours - ref) / ref
