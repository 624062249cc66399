# SPDX-License-Identifier: GPL-3.0-or-later
"""Environment maps: validation, equirectangular <-> cube faces, mip chains, sampling.

Conventions (Blender's World "Environment Texture", equirectangular, checked against a Cycles
render): a world direction d = (x, y, z), z up, maps to

    u = 0.5 - atan2(y, x) / (2 pi)        (+X at the image centre, +Y at u = 1/4)
    v = 0.5 + asin(z) / pi                (v = 1 at the zenith)

An equirectangular map here is an (H, W, 3) float64 array of linear radiance stored **top row
first** (row 0 at the zenith, as an EXR read by OpenCV; ``bpy`` ``Image.pixels`` come bottom row
first: flip them with ``[::-1]``, or pass ``bottom_row_first=True`` to
:func:`validate_environment`).

Cube maps are (6, S, S, 3) arrays in OpenGL's face order and orientation (+X, -X, +Y, -Y, +Z,
-Z; row t, column s as ``textureCube`` reads them), applied to Blender's world axes directly: a
GLSL ``texture(samplerCube, d)`` with d a Blender world direction reads the same texel as
:func:`sample_cube` does.  A mip chain is a list of such arrays, level 0 the finest, each level
the solid-angle-weighted 2 x 2 mean of the one above (a texel keeps the mean radiance over its
own solid angle, so the 1 x 1 level holds each face's mean, as seed 002 §4.2.1 uses it).
"""
from __future__ import annotations

import numpy as np

MIN_HEIGHT = 4              # rows: a smaller map has no usable directional content
MIN_WIDTH = 8               # columns
NEGATIVE_TOLERANCE = 5e-2   # of the map's mean: EXR half-float noise above it is clamped to 0
SUPERSAMPLE = 4             # sub-directions per texel side when resampling between layouts

# OpenGL cube-map faces: (major axis index, sign, s axis (index, sign), t axis (index, sign))
_FACES = (
    (0, +1, (2, -1), (1, -1)),     # +X: s = -z, t = -y
    (0, -1, (2, +1), (1, -1)),     # -X: s = +z, t = -y
    (1, +1, (0, +1), (2, +1)),     # +Y: s = +x, t = +z
    (1, -1, (0, +1), (2, -1)),     # -Y: s = +x, t = -z
    (2, +1, (0, +1), (1, -1)),     # +Z: s = +x, t = -y
    (2, -1, (0, -1), (1, -1)),     # -Z: s = -x, t = -y
)
FACE_AXES = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]],
                     float)


# ------------------------------------------------------------------------------------------
# validation
# ------------------------------------------------------------------------------------------

def validate_environment(pixels, bottom_row_first: bool = False) -> np.ndarray:
    """The environment ``pixels`` as a clean (H, W, 3) float64 equirectangular map, top row
    first, or a ValueError whose message is one sentence naming the problem.

    Accepts (H, W) grey, (H, W, 3) RGB or (H, W, 4) RGBA (alpha dropped) arrays, or a flat
    RGBA buffer with ``shape`` given by the caller beforehand.  Rejected: fewer than
    MIN_HEIGHT x MIN_WIDTH pixels (a 1 x 1 map), NaN or infinite values, values more negative
    than NEGATIVE_TOLERANCE x the map's mean (smaller negatives, the half-float noise of the
    bundled EXRs, are clamped to 0).  The input is never modified."""
    try:
        a = np.asarray(pixels, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError("The environment map is not an array of numbers.") from None
    if a.ndim == 2:
        a = np.repeat(a[..., None], 3, axis=2)
    if a.ndim != 3 or a.shape[2] not in (1, 3, 4):
        raise ValueError(f"The environment map has shape {a.shape}, expected (height, width, "
                         f"3 or 4 channels).")
    if a.shape[2] == 1:
        a = np.repeat(a, 3, axis=2)
    a = a[..., :3]
    h, w = a.shape[:2]
    if h < MIN_HEIGHT or w < MIN_WIDTH:
        raise ValueError(f"The environment map is {w} x {h} pixels, too small to light with: it "
                         f"needs at least {MIN_WIDTH} x {MIN_HEIGHT}.")
    bad = ~np.isfinite(a)
    if bad.any():
        raise ValueError(f"The environment map has {int(bad.any(axis=2).sum())} pixels that are "
                         f"NaN or infinite.")
    mean = float(np.abs(a).mean())
    lowest = float(a.min())
    if lowest < -NEGATIVE_TOLERANCE * max(mean, 1e-30):
        raise ValueError(f"The environment map has negative radiance (down to {lowest:.3g}), "
                         f"which no light can have.")
    a = np.maximum(a, 0.0)
    return np.ascontiguousarray(a[::-1] if bottom_row_first else a)


# ------------------------------------------------------------------------------------------
# equirectangular
# ------------------------------------------------------------------------------------------

def direction_to_equirect(d):
    """(u, v) in [0, 1] of unit directions ``d`` (..., 3) (v = 1 at the zenith)."""
    d = np.asarray(d, float)
    u = 0.5 - np.arctan2(d[..., 1], d[..., 0]) / (2 * np.pi)
    v = 0.5 + np.arcsin(np.clip(d[..., 2], -1.0, 1.0)) / np.pi
    return np.mod(u, 1.0), v


def equirect_to_direction(u, v):
    """Unit directions (..., 3) at equirectangular coordinates (u, v)."""
    phi = (0.5 - np.asarray(u, float)) * 2 * np.pi
    lat = (np.asarray(v, float) - 0.5) * np.pi
    c = np.cos(lat)
    return np.stack([c * np.cos(phi), c * np.sin(phi), np.sin(lat)], axis=-1)


def equirect_directions(h, w):
    """(h, w, 3) unit directions of the pixel centres of an (h, w) map, top row first."""
    u = (np.arange(w) + 0.5) / w
    v = 1.0 - (np.arange(h) + 0.5) / h
    U, V = np.meshgrid(u, v)
    return equirect_to_direction(U, V)


def equirect_solid_angles(h, w):
    """(h,) exact solid angle of one pixel of each row (top row first): (2 pi / w) times the
    difference of sin(latitude) across the row; they sum to 4 pi over the map."""
    lat = np.pi / 2 - np.pi * np.arange(h + 1) / h
    return (2 * np.pi / w) * (np.sin(lat[:-1]) - np.sin(lat[1:]))


def sample_equirect(env, d):
    """Bilinear radiance (..., 3) of the equirectangular map ``env`` in directions ``d``
    (..., 3): wraps in longitude, clamps at the poles."""
    h, w = env.shape[:2]
    u, v = direction_to_equirect(d)
    return _bilinear(env, u * w - 0.5, (1.0 - v) * h - 0.5, h - 1)


def _bilinear(table, x, y, last_row):
    """Bilinear lookup of ``table`` (h, w, C) at column x (wrapping) and row y (clamped to
    0 .. last_row; the upper neighbour of row last_row is itself or the next row)."""
    h, w = table.shape[:2]
    x0 = np.floor(x)
    y0 = np.clip(np.floor(y), 0, last_row)
    fx = (x - x0)[..., None]
    fy = np.clip(y - y0, 0.0, 1.0)[..., None]
    x0 = x0.astype(np.int64) % w
    x1 = (x0 + 1) % w
    y0 = y0.astype(np.int64)
    y1 = np.minimum(y0 + 1, h - 1)
    top = table[y0, x0] * (1 - fx) + table[y0, x1] * fx
    bot = table[y1, x0] * (1 - fx) + table[y1, x1] * fx
    return top * (1 - fy) + bot * fy


def resize_equirect(env, h, w):
    """The map resampled to (h, w): exact area (solid-angle) means when both sides divide,
    else supersampled bilinear lookups."""
    H, W = env.shape[:2]
    if H % h == 0 and W % w == 0:
        fy, fx = H // h, W // w
        om = equirect_solid_angles(H, W)
        weighted = (env * om[:, None, None]).reshape(h, fy, w, fx, 3).sum(axis=(1, 3))
        return weighted / om.reshape(h, fy).sum(1)[:, None, None] / fx
    k = SUPERSAMPLE
    sub = equirect_directions(h * k, w * k)
    om = equirect_solid_angles(h * k, w * k)
    val = sample_equirect(env, sub) * om[:, None, None]
    return val.reshape(h, k, w, k, 3).sum(axis=(1, 3)) / om.reshape(h, k).sum(1)[:, None, None] / k


# ------------------------------------------------------------------------------------------
# cube faces
# ------------------------------------------------------------------------------------------

def face_directions(face, s, t):
    """Unnormalised directions (..., 3) on the unit cube of ``face`` at face coordinates
    s, t in [-1, 1] (OpenGL orientation)."""
    major, sign, (sa, ss), (ta, ts) = _FACES[face]
    s = np.asarray(s, float)
    t = np.asarray(t, float)
    out = np.zeros(np.broadcast(s, t).shape + (3,))
    out[..., major] = sign
    out[..., sa] += ss * s
    out[..., ta] += ts * t
    return out


def cube_texel_coords(size):
    """Face coordinates (size,) of the texel centres along one side, in (-1, 1)."""
    return (np.arange(size) + 0.5) / size * 2.0 - 1.0


def cube_directions(size):
    """(6, size, size, 3) unit directions of every texel centre (row t, column s)."""
    c = cube_texel_coords(size)
    S, T = np.meshgrid(c, c)
    d = np.stack([face_directions(f, S, T) for f in range(6)])
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def _corner_area(x, y):
    return np.arctan2(x * y, np.sqrt(x * x + y * y + 1.0))


def cube_solid_angles(size):
    """(size, size) exact solid angle of each texel of a face (same for all six faces); they
    sum to 4 pi / 6 per face."""
    e = np.linspace(-1.0, 1.0, size + 1)
    X, Y = np.meshgrid(e, e)
    A = _corner_area(X, Y)
    return A[1:, 1:] - A[1:, :-1] - A[:-1, 1:] + A[:-1, :-1]


def direction_to_cube(d):
    """(face (...,) int, s, t in [-1, 1]) of directions ``d`` (..., 3)."""
    d = np.asarray(d, float)
    ad = np.abs(d)
    major = np.argmax(ad, axis=-1)
    m = np.take_along_axis(d, major[..., None], axis=-1)[..., 0]
    face = 2 * major + (m < 0)
    s = np.empty(d.shape[:-1])
    t = np.empty(d.shape[:-1])
    am = np.maximum(np.abs(m), 1e-300)
    for f, (_, _, (sa, ss), (ta, ts)) in enumerate(_FACES):
        sel = face == f
        s[sel] = ss * d[..., sa][sel] / am[sel]
        t[sel] = ts * d[..., ta][sel] / am[sel]
    return face, np.clip(s, -1.0, 1.0), np.clip(t, -1.0, 1.0)


def _padded(cube):
    """(6, S+2, S+2, 3): each face with a one-texel border read from its neighbours (nearest
    texel in the direction of the border texel's centre), so bilinear lookups are seamless."""
    size = cube.shape[1]
    c = (np.arange(-1, size + 1) + 0.5) / size * 2.0 - 1.0
    S, T = np.meshgrid(c, c)
    out = np.empty((6, size + 2, size + 2) + cube.shape[3:])
    for f in range(6):
        face, s, t = direction_to_cube(face_directions(f, S, T))
        col = np.clip(((s + 1) * 0.5 * size).astype(np.int64), 0, size - 1)
        row = np.clip(((t + 1) * 0.5 * size).astype(np.int64), 0, size - 1)
        out[f] = cube[face, row, col]
    return out


def sample_cube(cube, d, padded=None):
    """Seamless bilinear radiance (..., 3) of the cube faces ``cube`` (6, S, S, 3) in
    directions ``d`` (..., 3) (GL_TEXTURE_CUBE_MAP_SEAMLESS-like).  ``padded``: the faces
    with their border (``_padded(cube)``), when sampling the same faces many times."""
    size = cube.shape[1]
    pad = _padded(cube) if padded is None else padded
    face, s, t = direction_to_cube(d)
    x = (s + 1) * 0.5 * size - 0.5 + 1.0          # +1: the border column
    y = (t + 1) * 0.5 * size - 0.5 + 1.0
    x0 = np.clip(np.floor(x), 0, size).astype(np.int64)
    y0 = np.clip(np.floor(y), 0, size).astype(np.int64)
    fx = np.clip(x - x0, 0.0, 1.0)[..., None]
    fy = np.clip(y - y0, 0.0, 1.0)[..., None]
    a = pad[face, y0, x0] * (1 - fx) + pad[face, y0, x0 + 1] * fx
    b = pad[face, y0 + 1, x0] * (1 - fx) + pad[face, y0 + 1, x0 + 1] * fx
    return a * (1 - fy) + b * fy


def equirect_to_cube(env, size=None):
    """(6, size, size, 3) cube faces of the equirectangular map: each texel the solid-angle
    mean of k^2 bilinear lookups over it (k = the source pixels per texel side,
    2..SUPERSAMPLE).  ``size`` defaults to the power of two
    nearest W / 4 (the same pixel density at the equator)."""
    if size is None:
        size = 1 << max(0, int(round(np.log2(max(env.shape[1] / 4.0, 1.0)))))
    # enough sub-directions to visit every source pixel a texel covers
    k = int(np.clip(np.ceil(env.shape[1] / (4.0 * size)), 2, SUPERSAMPLE))
    sub = cube_directions(size * k)
    om = cube_solid_angles(size * k)
    val = sample_equirect(env, sub) * om[None, :, :, None]
    num = val.reshape(6, size, k, size, k, 3).sum(axis=(2, 4))
    den = om.reshape(size, k, size, k).sum(axis=(1, 3))
    return num / den[None, :, :, None]


def cube_to_equirect(cube, h, w):
    """(h, w, 3) equirectangular map of the cube faces: each pixel the solid-angle mean of
    SUPERSAMPLE^2 seamless bilinear lookups over it."""
    k = SUPERSAMPLE
    pad = _padded(cube)
    sub = equirect_directions(h * k, w * k)
    om = equirect_solid_angles(h * k, w * k)
    val = sample_cube(cube, sub, pad) * om[:, None, None]
    return val.reshape(h, k, w, k, 3).sum(axis=(1, 3)) / om.reshape(h, k).sum(1)[:, None, None] / k


# ------------------------------------------------------------------------------------------
# mip chains
# ------------------------------------------------------------------------------------------

def cube_mips(cube):
    """[level 0 = ``cube``, level 1, ..., the 1 x 1 level]: each level the solid-angle-weighted
    2 x 2 mean of the level above.  The face size must be a power of two."""
    size = cube.shape[1]
    if size & (size - 1):
        raise ValueError(f"The cube faces are {size} texels wide; mip levels need a power of two.")
    levels = [np.asarray(cube, float)]
    om = cube_solid_angles(size)
    while levels[-1].shape[1] > 1:
        c = levels[-1]
        s = c.shape[1] // 2
        w = om.reshape(s, 2, s, 2)
        num = (c * om[None, :, :, None]).reshape(6, s, 2, s, 2, 3).sum(axis=(2, 4))
        om = w.sum(axis=(1, 3))
        levels.append(num / om[None, :, :, None])
    return levels


def sample_cube_mips(mips, d, level, padded=None):
    """Trilinear radiance (..., 3) of the mip chain in directions ``d`` at fractional mip
    ``level`` (scalar or (...,), 0 = finest, clamped to the chain).  ``padded``: the list of
    ``_padded`` levels when sampling the same chain many times."""
    d = np.asarray(d, float)
    n = len(mips) - 1
    level = np.clip(np.broadcast_to(np.asarray(level, float), d.shape[:-1]), 0.0, n)
    pads = padded if padded is not None else [None] * len(mips)
    lo = np.floor(level).astype(np.int64)
    out = np.zeros(d.shape[:-1] + (3,))
    for k in np.unique(lo):
        sel = lo == k
        f = (level[sel] - k)[..., None]
        a = sample_cube(mips[k], d[sel], pads[k])
        if k < n:
            b = sample_cube(mips[k + 1], d[sel], pads[k + 1])
            a = a * (1 - f) + b * f
        out[sel] = a
    return out


def padded_mips(mips):
    """The ``_padded`` faces of every level, for repeated :func:`sample_cube_mips` calls."""
    return [_padded(m) for m in mips]


# ------------------------------------------------------------------------------------------
# latitude-node tables (the small maps of E(n) and cap means)
# ------------------------------------------------------------------------------------------
#
# A table of a smooth function of direction is sampled at normals and cap axes, and those are
# very often exactly vertical (floors, table tops, a sphere overhead), where an equirectangular
# map's longitude is undefined and its top row lies half a pixel below the pole.  So the
# tables keep their rows on latitude *nodes*: row 0 at the zenith, row h - 1 at the nadir (each
# pole row holds one value repeated), columns cell-centred as usual.  A GL texture reads them
# with t = (0.5 + v (h - 1)) / h (the shader's relight_node_uv).

def node_directions(h, w):
    """(h, w, 3) unit directions of a latitude-node table, row 0 at the zenith."""
    u = (np.arange(w) + 0.5) / w
    v = 1.0 - np.arange(h) / (h - 1.0)
    U, V = np.meshgrid(u, v)
    return equirect_to_direction(U, V)


def sample_nodes(table, d):
    """Bilinear values (..., C) of the latitude-node table (h, w, C) in directions ``d``."""
    h, w = table.shape[:2]
    u, v = direction_to_equirect(d)
    return _bilinear(table, u * w - 0.5, (1.0 - v) * (h - 1.0), h - 2)
