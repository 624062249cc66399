"""Points on planar bilinear patches (quads, and triangles as (a, b, c, c)).

The Jacobian of a planar bilinear map is linear in (u, v):
J(u, v) = j0 + ju u + jv v, so area-uniform sampling has a closed form (inverse CDF of a linear
density, first in v, then in u given v), and the midpoint rule with Jacobian weights integrates
the area exactly.
"""
from __future__ import annotations

import numpy as np

from .patch import bilinear_point, quad_area_normal

# Generalised golden ratios of the R2 low-discrepancy sequence (Roberts 2018).
R2 = (0.7548776662466927, 0.5698402909980532)


def jacobian_coefficients(corners: np.ndarray):
    """(j0, ju, jv) with J(u, v) = j0 + ju u + jv v for each patch (signed along its normal)."""
    a, b, c, d = (corners[..., i, :] for i in range(4))
    _, n = quad_area_normal(corners)
    q = a - b + c - d
    j0 = np.einsum("...i,...i", np.cross(b - a, d - a), n)
    ju = np.einsum("...i,...i", np.cross(b - a, q), n)
    jv = np.einsum("...i,...i", np.cross(q, d - a), n)
    return j0, ju, jv


def midpoint_grid(m: int):
    """(m*m, 2) parameter-space midpoints of an m x m grid."""
    t = (np.arange(m) + 0.5) / m
    u, v = np.meshgrid(t, t, indexing="xy")
    return np.stack([u.ravel(), v.ravel()], axis=1)


def gauss_grid(m: int):
    """(m*m, 2) tensor Gauss-Legendre nodes on [0, 1]^2 and their (m*m,) weights (sum 1)."""
    x, w = np.polynomial.legendre.leggauss(m)
    x = 0.5 * (x + 1.0)
    w = 0.5 * w
    u, v = np.meshgrid(x, x, indexing="xy")
    wu, wv = np.meshgrid(w, w, indexing="xy")
    return np.stack([u.ravel(), v.ravel()], axis=1), (wu * wv).ravel()


def gauss_cells(m: int):
    """The cells of gauss_grid's nodes along one axis of [0, 1]: node i's cell is
    [lo[i], lo[i] + width[i]), its width its weight (the cells tile [0, 1] in order)."""
    width = 0.5 * np.polynomial.legendre.leggauss(m)[1]
    return np.concatenate([[0.0], np.cumsum(width)[:-1]]), width


def quadrature(corners: np.ndarray, m: int):
    """Gauss points (n, m*m, 3) and area weights (n, m*m) summing exactly to each patch's area.

    The Jacobian is linear in (u, v), so any rule exact for linear functions gives the exact area.
    """
    uv, base = gauss_grid(m)
    pts = bilinear_point(corners[:, None], uv[None, :, 0], uv[None, :, 1])
    j0, ju, jv = jacobian_coefficients(corners)
    w = (j0[:, None] + ju[:, None] * uv[None, :, 0] + jv[:, None] * uv[None, :, 1]) * base[None]
    return pts, np.maximum(w, 0.0)


def _invert_linear_cdf(alpha, beta, xi):
    """x in [0, 1] with density proportional to alpha + beta x (both ends >= 0) at CDF level xi."""
    target = xi * (alpha + 0.5 * beta)
    disc = np.sqrt(np.maximum(alpha * alpha + 2.0 * beta * target, 0.0))
    denom = alpha + disc
    x = np.where(denom > 0, 2.0 * target / np.where(denom > 0, denom, 1.0), xi)
    return np.clip(x, 0.0, 1.0)


def area_uniform_uv(corners, xi_u: np.ndarray, xi_v: np.ndarray, coefficients=None):
    """Map uniform numbers in [0,1)^2 to (u, v) distributed uniformly in area on each patch.

    corners (n, 4, 3) (or None when ``coefficients`` = (j0, ju, jv), each (n,), are given, e.g.
    precomputed once per element); xi_u, xi_v (n, k).  Returns u, v of shape (n, k).
    """
    j0, ju, jv = jacobian_coefficients(corners) if coefficients is None else coefficients
    j0, ju, jv = j0[:, None], ju[:, None], jv[:, None]
    # Marginal in v: integral over u of J = (j0 + ju/2) + jv v.
    v = _invert_linear_cdf(j0 + 0.5 * ju, jv + 0.0 * xi_v, xi_v)
    # Conditional in u given v: (j0 + jv v) + ju u.
    u = _invert_linear_cdf(j0 + jv * v, ju + 0.0 * xi_u, xi_u)
    return u, v


def stratified_unit_square(n: int, k: int, rng: np.random.Generator):
    """Jittered stratified samples: (n, k) u and v, with k rounded up to a square."""
    s = int(np.ceil(np.sqrt(k)))
    cells = midpoint_grid(s) - 0.5 / s
    jitter = rng.random((n, s * s, 2)) / s
    uv = cells[None] + jitter
    # Shuffle strata per row so that taking the first k keeps coverage unbiased.
    perm = np.argsort(rng.random((n, s * s)), axis=1)[:, :k]
    uv = np.take_along_axis(uv, perm[..., None], axis=1)
    return uv[..., 0], uv[..., 1]


def random_points(corners: np.ndarray, k: int, rng: np.random.Generator) -> np.ndarray:
    """(n, k, 3) stratified, area-uniform random points on each patch."""
    xu, xv = stratified_unit_square(len(corners), k, rng)
    u, v = area_uniform_uv(corners, xu, xv)
    return bilinear_point(corners[:, None], u, v)


def cosine_directions(normals: np.ndarray, x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """Cosine-distributed unit directions around ``normals`` (..., 3) from uniform numbers
    ``x1``, ``x2`` (..., 1) in [0, 1), all three broadcast together."""
    axis = np.where(np.abs(normals[..., :1]) < 0.9, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    t1 = np.cross(normals, axis)
    t1 /= np.linalg.norm(t1, axis=-1, keepdims=True)
    t2 = np.cross(normals, t1)
    r, phi = np.sqrt(x1), 2.0 * np.pi * x2
    return r * np.cos(phi) * t1 + r * np.sin(phi) * t2 + np.sqrt(np.maximum(1.0 - x1, 0.0)) * normals
