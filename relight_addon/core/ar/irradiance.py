# SPDX-License-Identifier: GPL-3.0-or-later
"""Diffuse irradiance of an environment map, three ways (seed 002 §4.2).

Irradiance here is E(n) = integral over the hemisphere of n of L(w) max(w.n, 0) dw (W/m^2 for a
map in W/(m^2 sr)); a white Lambertian surface shows E / pi (seed 002's eq. 4.2.1.1 carries
that 1/pi), a surface of albedo rho shows rho E / pi.

1. **SH9** (default; Ramamoorthi and Hanrahan 2001): the map projected on the nine real
   spherical harmonics of bands 0-2, convolved with the clamped cosine (A0 = pi, A1 = 2 pi / 3,
   A2 = pi / 4).  :func:`irradiance_polynomial` lays the result out as nine RGB coefficients of
   the monomials ``SH_POLYNOMIAL_TERMS`` of the normal, the form a material's node maths (or a
   shader) evaluates: E(n) = sum_k c_k term_k(n).
2. **Exact cube-face weights**: the map constant over each cube face (the 1 x 1 mip level;
   or over each texel of an N x N level), E(n) = sum_F L_F W_F(n), W_F(n) the clamped-cosine
   integral over the face, exactly, by Lambert's formula on the face polygon clipped by the
   plane w.n = 0 (sum over the six faces: exactly pi).
3. **The seed's approximate face weights** (eq. 4.2.2.2): W_F ~ max(0.75 + n.F, 0)^2 / 1.75, F
   the face's axis.  They sum to 3.04-3.14 depending on n (pi = 3.1416): kept as an option.
"""
from __future__ import annotations

import numpy as np

from .envmap import (FACE_AXES, cube_mips, equirect_directions, equirect_solid_angles,
                     face_directions)

# real SH basis constants (bands 0-2)
_Y0 = 0.5 * np.sqrt(1 / np.pi)
_Y1 = np.sqrt(3 / (4 * np.pi))
_Y2 = 0.5 * np.sqrt(15 / np.pi)
_Y20 = 0.25 * np.sqrt(5 / np.pi)
_Y22 = 0.25 * np.sqrt(15 / np.pi)
# clamped-cosine convolution per band (Ramamoorthi and Hanrahan 2001)
SH_COSINE = np.array([np.pi] + [2 * np.pi / 3] * 3 + [np.pi / 4] * 5)
SH_POLYNOMIAL_TERMS = ("1", "x", "y", "z", "x*y", "y*z", "x*z", "x*x - y*y", "z*z")
SEED_OFFSET = 0.75           # eq. 4.2.2.2
SEED_SCALE = 1.75


def sh9_basis(d):
    """(..., 9) real SH basis at unit directions ``d`` (..., 3), order (0,0), (1,-1), (1,0),
    (1,1), (2,-2), (2,-1), (2,0), (2,1), (2,2)."""
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    return np.stack([np.full_like(x, _Y0), _Y1 * y, _Y1 * z, _Y1 * x, _Y2 * x * y, _Y2 * y * z,
                     _Y20 * (3 * z * z - 1), _Y2 * x * z, _Y22 * (x * x - y * y)], axis=-1)


def sh9_project(env):
    """(9, 3) SH coefficients of the radiance of the equirectangular map ``env`` (H, W, 3),
    by the exact per-pixel solid angles (midpoint rule inside each pixel)."""
    h, w = env.shape[:2]
    basis = sh9_basis(equirect_directions(h, w))                   # (h, w, 9)
    om = equirect_solid_angles(h, w)
    return np.einsum("hwk,hwc,h->kc", basis, env, om)


def sh9_radiance(sh, d):
    """Radiance (..., 3) of the band-limited map ``sh`` (9, 3) in directions ``d``."""
    return sh9_basis(np.asarray(d, float)) @ sh


def sh9_irradiance(sh, n):
    """Irradiance (..., 3) at unit normals ``n`` (..., 3) of the map with radiance SH ``sh``."""
    return sh9_basis(np.asarray(n, float)) @ (SH_COSINE[:, None] * sh)


def irradiance_polynomial(sh):
    """(9, 3) RGB coefficients c_k with E(n) = sum_k c_k term_k(n), terms SH_POLYNOMIAL_TERMS
    = 1, x, y, z, xy, yz, xz, x^2 - y^2, z^2 of the unit normal (x, y, z) in world space: the
    same values as :func:`sh9_irradiance`, for node maths (a material computes them with Vector
    Math dot products of the normal) or a shader.  Divide by pi for the outgoing radiance of a
    white Lambertian surface."""
    c = SH_COSINE[:, None] * np.asarray(sh, float)
    out = np.empty((9, 3))
    out[0] = _Y0 * c[0] - _Y20 * c[6]
    out[1] = _Y1 * c[3]
    out[2] = _Y1 * c[1]
    out[3] = _Y1 * c[2]
    out[4] = _Y2 * c[4]
    out[5] = _Y2 * c[5]
    out[6] = _Y2 * c[7]
    out[7] = _Y22 * c[8]
    out[8] = 3 * _Y20 * c[6]
    return out


def evaluate_polynomial(coeffs, n):
    """E(n) (..., 3) from :func:`irradiance_polynomial`'s coefficients (the node maths' twin)."""
    n = np.asarray(n, float)
    x, y, z = n[..., 0], n[..., 1], n[..., 2]
    terms = np.stack([np.ones_like(x), x, y, z, x * y, y * z, x * z, x * x - y * y, z * z], -1)
    return terms @ np.asarray(coeffs, float)


# ------------------------------------------------------------------------------------------
# cube-face weights
# ------------------------------------------------------------------------------------------

def _lambert(poly, n):
    """Clamped-cosine integral of the polygons ``poly`` (..., k, 3) (vertices on the unit cube,
    closed implicitly; repeated vertices allowed) about normals ``n`` (..., 3), all above the
    plane n.x = 0: Lambert's formula 1/2 |sum_i gamma_i n.(v_i x v_i+1)/|v_i x v_i+1||."""
    v = poly / np.linalg.norm(poly, axis=-1, keepdims=True)
    w = np.roll(v, -1, axis=-2)
    c = np.cross(v, w)
    s = np.linalg.norm(c, axis=-1)
    gamma = np.arctan2(s, np.einsum("...i,...i", v, w))
    g = np.where(s > 1e-15, gamma / np.maximum(s, 1e-300), 1.0)   # gamma / |c| -> 1 as c -> 0
    return 0.5 * np.abs(np.einsum("...ki,...i->...", c * g[..., None], n))


def _clip_squares(corners, n):
    """The squares ``corners`` (q, 4, 3) clipped by n.x >= 0 for every normal ``n`` (m, 3):
    (m, q, 8, 3) polygons (Sutherland-Hodgman, the valid vertices first, the rest repeating the
    first valid one, so closing edges have zero length) and (m, q) 'anything left'."""
    s = np.einsum("qki,mi->mqk", corners, n)                        # (m, q, 4)
    nxt = np.roll(np.arange(4), -1)
    a = np.broadcast_to(corners, s.shape + (3,))
    b = a[:, :, nxt]
    sa, sb = s, s[:, :, nxt]
    inside = sa >= 0
    cross_ = (sa >= 0) != (sb >= 0)
    t = np.where(cross_, sa / np.where(cross_, sa - sb, 1.0), 0.0)
    hit = a + t[..., None] * (b - a)
    cand = np.stack([a, hit], axis=3).reshape(s.shape[:2] + (8, 3))
    valid = np.stack([inside, cross_], axis=3).reshape(s.shape[:2] + (8,))
    order = np.argsort(~valid, axis=-1, kind="stable")
    cand = np.take_along_axis(cand, order[..., None], axis=-2)
    valid = np.take_along_axis(valid, order, axis=-1)
    first = cand[..., :1, :]
    cand = np.where(valid[..., None], cand, first)
    return cand, valid.any(axis=-1)


def face_texel_corners(level_size):
    """(6 * N * N, 4, 3) corners on the unit cube of the texels of an N x N per face level, in
    the order of a (6, N, N) array (face, row t, column s)."""
    e = np.linspace(-1.0, 1.0, level_size + 1)
    out = []
    for f in range(6):
        for r in range(level_size):
            for q in range(level_size):
                s0, s1, t0, t1 = e[q], e[q + 1], e[r], e[r + 1]
                out.append(face_directions(f, np.array([s0, s1, s1, s0]),
                                           np.array([t0, t0, t1, t1])))
    return np.array(out)


def exact_face_weights(n, level_size=1, chunk=256):
    """(m, 6 * N * N) exact clamped-cosine weights W(n) = integral over each texel of an N x N
    per face cube level of max(w.n, 0) dw, for unit normals ``n`` (m, 3) (Lambert's formula on
    the texel clipped by the horizon).  They sum to pi for every normal."""
    n = np.atleast_2d(np.asarray(n, float))
    corners = face_texel_corners(level_size)
    out = np.empty((len(n), len(corners)))
    for a in range(0, len(n), chunk):
        nn = n[a:a + chunk]
        poly, some = _clip_squares(corners, nn)
        val = _lambert(poly, nn[:, None, :])
        out[a:a + chunk] = np.where(some, val, 0.0)
    return out


def seed_face_weights(n):
    """(m, 6) seed 002's approximate face weights max(0.75 + n.F, 0)^2 / 1.75 (eq. 4.2.2.2)."""
    cos = np.atleast_2d(np.asarray(n, float)) @ FACE_AXES.T
    return np.maximum(SEED_OFFSET + cos, 0.0) ** 2 / SEED_SCALE


def face_irradiance(cube_or_mips, n, level_size=1, weights="exact"):
    """Irradiance (m, 3) at normals ``n`` of the map taken constant over each texel of its
    N x N mip level (N = ``level_size``; 1: one value per face, the seed's model).
    ``cube_or_mips``: (6, S, S, 3) faces or their :func:`envmap.cube_mips` chain.  ``weights``:
    "exact" (Lambert) or "seed" (eq. 4.2.2.2, only with level_size 1)."""
    mips = cube_or_mips if isinstance(cube_or_mips, list) else cube_mips(cube_or_mips)
    level = next((m for m in mips if m.shape[1] == level_size), None)
    if level is None:
        raise ValueError(f"The cube map has no {level_size} x {level_size} mip level.")
    values = level.reshape(-1, 3)
    if weights == "seed":
        if level_size != 1:
            raise ValueError("The seed's face weights are defined for whole faces only.")
        return seed_face_weights(n) @ values
    return exact_face_weights(n, level_size) @ values


# ------------------------------------------------------------------------------------------
# irradiance map
# ------------------------------------------------------------------------------------------

IRRADIANCE_MAP_SIZE = (33, 64)      # (H, W) latitude nodes every 5.6 deg: E(n) is smooth
IRRADIANCE_SOURCE = (64, 128)       # the map is averaged down to this before the sum (2.8 deg)


def irradiance_map(env, size=IRRADIANCE_MAP_SIZE, source=IRRADIANCE_SOURCE, chunk=512,
                   sparse=None, layout="nodes"):
    """(h, w, 3) latitude-node table of the irradiance E(n) (envmap.node_directions: row 0 at
    the zenith, row h - 1 at the nadir), by summing every pixel of ``env`` averaged down to
    ``source`` (exact solid angles).  Sampled with the normal as direction
    (:func:`envmap.sample_nodes`; a GL texture with t = (0.5 + v (h - 1)) / h) it gives E(n)
    within the interpolation's error: the accurate alternative to SH9 where a map's
    irradiance has more than bands 0-2.  With ``sparse``, a full-resolution map whose few
    non-zero pixels are summed exactly (the lights of main_light.extract_lights: map -
    residual), ``env`` is the rest (the residual): a sun is not smeared by the averaging
    down.  ``layout="equirect"``
    gives an ordinary equirectangular image instead (cell-centred rows, top row first), for
    Blender's Environment Texture node fed the normal: take size (128, 256) or more there, its
    top row lies half a row below the zenith that floors' normals read."""
    from .envmap import resize_equirect
    h, w = env.shape[:2]
    sh, sw = source
    if h > sh and w > sw:
        env = resize_equirect(env, sh, sw)
        h, w = sh, sw
    d = equirect_directions(h, w).reshape(-1, 3).astype(np.float32)
    lw = (env * equirect_solid_angles(h, w)[:, None, None]).reshape(-1, 3)
    from .envmap import node_directions
    grid = node_directions if layout == "nodes" else equirect_directions
    n = grid(*size).reshape(-1, 3).astype(np.float32)
    out = np.empty((len(n), 3))
    for a in range(0, len(n), chunk):
        out[a:a + chunk] = np.maximum(n[a:a + chunk] @ d.T, 0.0).astype(np.float64) @ lw
    if sparse is not None:
        sh, sw = sparse.shape[:2]
        rows, cols = np.nonzero(np.any(sparse != 0, axis=2))
        if len(rows):
            ds = equirect_directions(sh, sw)[rows, cols]
            ls = sparse[rows, cols] * equirect_solid_angles(sh, sw)[rows, None]
            out += np.maximum(n.astype(np.float64) @ ds.T, 0.0) @ ls
    return out.reshape(size + (3,))
