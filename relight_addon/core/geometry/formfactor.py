"""Unoccluded point-to-polygon form factors (Lambert's contour formula).

F(x -> P) = 1/(2 pi) | sum_e gamma_e  n_x . (R_e x R_e+1) / |R_e x R_e+1| |

with R_e the vectors from x to the polygon's vertices and gamma_e the angle between consecutive
ones.  The formula is exact for an unoccluded planar polygon wholly in front of x; the polygon is
first clipped against the receiver's tangent plane (Sutherland-Hodgman, vectorised), and a source
whose front side does not face x contributes nothing.
"""
from __future__ import annotations

import numpy as np

from ..numerics import safe_div
from .patch import quad_area_normal
from .sampling import quadrature

# Vertices closer than this (relative to the polygon size) to x are treated as touching x.
_TINY = 1e-12


# Polygon vertices per block (rows times k): small enough for the temporaries to stay in cache.
_BLOCK = 32768


def _contour_sum(x, y, z, xn, yn, zn, nx, ny, nz, thresh, valid=None):
    """sum_e gamma_e n.(r0 x r1)/|r0 x r1| over edges r0 = (x, y, z), r1 = (xn, yn, zn).

    Vertex-major layout: component arrays are (k, n) (edge e of polygon i at [e, i]); nx, ny,
    nz and thresh are (n,).  Edges whose |r0 x r1| is at most thresh (or that are not valid)
    contribute nothing.
    """
    cx = y * zn
    cx -= z * yn
    cy = z * xn
    cy -= x * zn
    cz = x * yn
    cz -= y * xn
    proj = cx * nx
    proj += cy * ny
    proj += cz * nz
    dot = x * xn
    dot += y * yn
    dot += z * zn
    cx *= cx
    cy *= cy
    cx += cy
    cz *= cz
    cx += cz
    cross_len = np.sqrt(cx, out=cx)
    gamma = np.arctan2(cross_len, dot, out=dot)
    gamma *= proj
    unusable = cross_len <= thresh
    if valid is not None:
        unusable |= ~valid
    cross_len[unusable] = np.inf  # -> term 0 (gamma and proj are finite)
    gamma /= cross_len
    total = gamma[0].copy()
    for e in range(1, len(gamma)):
        total += gamma[e]
    return total


def _next(c):
    """Rows rolled by one: vertex e + 1 (cyclically) for each e, layout (k, n)."""
    out = np.empty_like(c)
    out[:-1] = c[1:]
    out[-1] = c[0]
    return out


def _clipped_contour_sum(x, y, z, dist, nx, ny, nz, thresh):
    """Contour sum of polygons (components (k, n)) clipped to dist >= 0.

    Same contour as Sutherland-Hodgman, summed without compacting it: each edge (e, e+1) keeps
    its part in front (from v_e or the crossing p_e to v_e+1 or p_e), and each exit crossing
    p_e is joined, along the tangent plane, to the next entry crossing in contour order.
    """
    k, n = dist.shape
    dn = _next(dist)
    inside = dist >= 0
    inside_n = dn >= 0
    crosses = inside != inside_n
    t = np.where(crosses, dist / np.where(crosses, dist - dn, 1.0), 0.0)
    exits = inside & ~inside_n
    entries = ~inside & inside_n
    # Index of the next entry crossing after each edge (only used where the edge exits).
    next_entry = np.zeros((k, n), np.intp)
    for off in range(k - 1, 0, -1):  # the nearest one wins: assign far to near
        idx = (np.arange(k) + off) % k
        np.copyto(next_entry, idx[:, None], where=entries[idx])
    cols = np.arange(n)[None, :]
    seg, close = [], []
    for c in (x, y, z):
        cn = _next(c)
        p = c + t * (cn - c)
        seg += [np.where(inside, c, p), np.where(inside_n, cn, p)]
        close += [p, p[next_entry, cols]]
    total = _contour_sum(seg[0], seg[2], seg[4], seg[1], seg[3], seg[5], nx, ny, nz, thresh,
                         inside | inside_n)
    total += _contour_sum(close[0], close[2], close[4], close[1], close[3], close[5], nx, ny, nz,
                          thresh, exits)
    return total


def _point_to_polygon_block(points, normals, polygons, source_normals):
    n, k = polygons.shape[:2]
    rel = np.empty((3, k, n))
    np.subtract(polygons.transpose(2, 1, 0), points.T[:, None, :], out=rel)
    x, y, z = rel
    nx, ny, nz = np.ascontiguousarray(normals.T)
    size2 = (x * x + y * y + z * z).max(axis=0)
    dist = x * nx
    dist += y * ny
    dist += z * nz
    # Vertices within rounding of the tangent plane count as on it (then they clip cleanly).
    dist[dist * dist <= 1e-24 * size2] = 0.0
    behind = np.any(dist < 0, axis=0)
    ahead = np.any(dist > 0, axis=0)
    # A polygon with no vertex strictly in front (wholly behind, or lying in the tangent plane,
    # e.g. coplanar with the receiver) subtends no projected solid angle.
    front = ahead & ~behind
    clip = ahead & behind
    thresh = _TINY * size2
    total = np.zeros(n)

    # Fast path: the whole polygon is in front of (or on) the tangent plane.
    n_front = np.count_nonzero(front)
    if 2 * n_front >= n:  # mostly in front: cheaper to compute every row than to gather
        total = _contour_sum(x, y, z, _next(x), _next(y), _next(z), nx, ny, nz, thresh)
        if n_front < n:
            total[~front] = 0.0
    elif n_front:
        xf, yf, zf = x[:, front], y[:, front], z[:, front]
        total[front] = _contour_sum(xf, yf, zf, _next(xf), _next(yf), _next(zf),
                                    nx[front], ny[front], nz[front], thresh[front])
    # Straddling polygons: clip against the tangent plane first.
    if clip.any():
        total[clip] = _clipped_contour_sum(x[:, clip], y[:, clip], z[:, clip], dist[:, clip],
                                           nx[clip], ny[clip], nz[clip], thresh[clip])

    ff = np.abs(total)
    ff /= 2.0 * np.pi
    if source_normals is not None:
        # A one-sided source only shines on points in front of its plane (points within
        # rounding of the plane see it edge-on).
        sx, sy, sz = np.ascontiguousarray(source_normals.T)
        side = -(x[0] * sx + y[0] * sy + z[0] * sz)
        ff[side <= _TINY * np.sqrt(size2)] = 0.0
    return np.clip(ff, 0.0, 1.0, out=ff)


def point_to_polygon(points, normals, polygons, source_normals=None):
    """Unoccluded form factor from differential areas to planar polygons.

    points (n, 3), normals (n, 3) unit receiver normals, polygons (n, k, 3) (repeated vertices
    allowed), source_normals (n, 3) optional: one-sided sources emit only on that side.
    Returns (n,) float64 in [0, 1].  A polygon lying in the receiver's tangent plane, or (with
    source_normals) a receiver point lying in the source's plane, gives 0.
    """
    points = np.asarray(points, float)
    normals = np.asarray(normals, float)
    polygons = np.asarray(polygons, float)
    if source_normals is not None:
        source_normals = np.asarray(source_normals, float)
    n, k = polygons.shape[:2]
    rows = max(1, _BLOCK // max(k, 1))
    if n <= rows:
        return _point_to_polygon_block(points, normals, polygons, source_normals)
    out = np.empty(n)
    for s in range(0, n, rows):
        e = min(n, s + rows)
        out[s:e] = _point_to_polygon_block(points[s:e], normals[s:e], polygons[s:e],
                                           None if source_normals is None else source_normals[s:e])
    return out


def patch_to_patch(recv_corners, src_corners, m: int = 8):
    """Unoccluded form factors F_rs (receiver-area average) between pairs of patches.

    recv_corners, src_corners (n, 4, 3).  Tensor Gauss rule with m x m Jacobian-weighted points on
    each receiver; exact point-to-polygon integration over each source.
    """
    recv_corners = np.asarray(recv_corners, float)
    src_corners = np.asarray(src_corners, float)
    n = len(recv_corners)
    pts, w = quadrature(recv_corners, m)
    _, rn = quad_area_normal(recv_corners)
    _, sn = quad_area_normal(src_corners)
    k = pts.shape[1]
    ff = point_to_polygon(pts.reshape(-1, 3), np.repeat(rn, k, axis=0),
                          np.repeat(src_corners, k, axis=0), np.repeat(sn, k, axis=0))
    ff = ff.reshape(n, k)
    return safe_div((ff * w).sum(axis=1), w.sum(axis=1))


def point_kernel(n_r, n_s, d):
    """cos cos' / r^2 between points (without 1/pi), zero unless both face each other."""
    dd = d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2]
    cr = d[:, 0] * n_r[:, 0] + d[:, 1] * n_r[:, 1] + d[:, 2] * n_r[:, 2]
    cs = -(d[:, 0] * n_s[:, 0] + d[:, 1] * n_s[:, 1] + d[:, 2] * n_s[:, 2])
    return np.where((cr > 0) & (cs > 0), safe_div(cr * cs, dd * dd), 0.0)
