"""A moving object's shadow from a table of the lines that cross it (bpy-free).

Blender before 5.1 has no Raycast shader node, and the sphere set (sphere_shadow.py) costs
Cycles some 25 nodes per sphere and lamp at every point in an object's reach.  A shadow ray
from a receiving point towards a lamp lies on a line through the object's bounding sphere, and
whether the object stops it depends only on that line and on where along it the ray starts
and ends.  So the object is ray-traced once, at Update, for a set of lines in its own frame:
the directions of a grid of ``n_dir x n_dir`` *tiles* over half of the sphere of directions
(a line has two: the half with z >= 0, through the upper half of the octahedral map turned by
45 degrees so that it fills the square), and in each direction a grid of ``n_off x n_off``
parallel lines across the bounding sphere (its *texels*).  Each texel keeps whether its line
meets the object and the middle and half the length of where it does along the line (in
bounding radii from the centre's plane).  The table is an image; at render time a relit
material finds the tile of its ray's direction and the texel of its ray's offset (one image
lookup, bilinear within the tile, plus two for the tile's axes) and compares the object's
interval on the line with its ray's: some 70 nodes per lamp term whatever the object, its real
mesh's shadow (not the spheres'), soft as the rays' lamp points are drawn over the lamp's disk
(blender/ray_shadow.py's target group).

The ray's own direction stands for its tile's (at most half a tile apart, about 2.6 degrees at
24 x 24), and a line grazing the object's edge or a feature thinner than a texel (2 radii / 32)
may be missed: the table's errors against the object's ray-traced mesh are tested in
tests/test_line_shadow.py (half the spheres' on Suzanne, a torus, boxes).  This module builds
the table and is the numpy twin of the node group that reads it (blender/line_nodes.py): the
same operations in the same order.
"""
from __future__ import annotations

import numpy as np

N_DIR = 24            # directions per side of the tile grid (a half of the directions)
N_OFF = 32            # lines per side of a tile (texels)
OUTSIDE = 1.25        # rays start this many bounding radii before the centre's plane


def sign_nz(x):
    """+1 for x >= 0, -1 below (no 0: the flip to the upper half needs a side)."""
    return 1.0 - 2.0 * (np.asarray(x) < 0.0)


def tile_coords(u):
    """(flip (n,), tile coordinates (n, 2) in [-1, 1]^2) of unit directions ``u`` (n, 3).  A
    line has two directions: the one with z >= 0 (``flip`` u) is mapped to the square by the
    upper half of the octahedral map turned by 45 degrees, (x + y, x - y) / (|x| + |y| + z),
    which fills the square (no fold, linear in the flipped direction)."""
    u = np.asarray(u, float)
    flip = sign_nz(u[..., 2])
    v = u * (flip / np.maximum(np.abs(u).sum(axis=-1), 1e-30))[..., None]
    return flip, np.stack([v[..., 0] + v[..., 1], v[..., 0] - v[..., 1]], axis=-1)


def tile_direction(ab):
    """The unit direction (n, 3) at tile coordinates ``ab`` (n, 2) (tile_coords' inverse)."""
    ab = np.asarray(ab, float)
    x = 0.5 * (ab[..., 0] + ab[..., 1])
    y = 0.5 * (ab[..., 0] - ab[..., 1])
    v = np.stack([x, y, 1.0 - np.abs(x) - np.abs(y)], axis=-1)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def basis(w):
    """Two unit vectors (e1, e2), each (n, 3), completing unit ``w`` (n, 3, z >= 0) to an
    orthonormal frame (Duff et al. 2017; smooth on the upper half)."""
    w = np.asarray(w, float)
    x, y, z = w[..., 0], w[..., 1], w[..., 2]
    a = -1.0 / (1.0 + z)
    b = x * y * a
    e1 = np.stack([1.0 + x * x * a, b, -x], axis=-1)
    e2 = np.stack([b, 1.0 + y * y * a, -y], axis=-1)
    return e1, e2


def tile_centres(n_dir=N_DIR):
    """(n_dir, n_dir, 2): tile (row j, column i)'s centre in tile coordinates."""
    k = (np.arange(n_dir) + 0.5) * (2.0 / n_dir) - 1.0
    jj, ii = np.meshgrid(k, k, indexing="ij")
    return np.stack([ii, jj], axis=-1)


def build_table(triangles, centre, radius, occluder=None, n_dir=N_DIR, n_off=N_OFF):
    """The table (n_dir n_off, n_dir n_off, 3) float32 of the object ``triangles`` (t, 3, 3)
    inside the bounding sphere (``centre``, ``radius``), all in its own frame: per texel (row
    j n_off + t, column i n_off + s) whether its line meets the object (0 or 1), and the
    middle and half the length of where it does along the tile's direction, in radii from
    the centre's plane.  ``occluder``: a raycast.Occluder of the triangles (made when None)."""
    from ..geometry.raycast import make_occluder
    occ = occluder or make_occluder(np.asarray(triangles, float))
    c = np.asarray(centre, float)
    r = float(radius)
    w = tile_direction(tile_centres(n_dir).reshape(-1, 2))          # (tiles, 3), row-major j
    e1, e2 = basis(w)
    k = (np.arange(n_off) + 0.5) * (2.0 / n_off) - 1.0              # texel offsets, in radii
    tt, ss = np.meshgrid(k, k, indexing="ij")
    base = c + r * (ss.reshape(1, -1, 1) * e1[:, None] + tt.reshape(1, -1, 1) * e2[:, None])
    ww = np.broadcast_to(w[:, None], base.shape)
    span = 2.0 * OUTSIDE * r
    d = ww.reshape(-1, 3)
    f = occ.first_hit_distance((base - OUTSIDE * r * ww).reshape(-1, 3), d, tmax=span)
    g = occ.first_hit_distance((base + OUTSIDE * r * ww).reshape(-1, 3), -d, tmax=span)
    hit = np.isfinite(f) & np.isfinite(g)
    h_in = np.where(hit, f / r - OUTSIDE, np.nan)
    h_out = np.where(hit, OUTSIDE - g / r, np.nan)
    grid = np.stack([hit.astype(float), 0.5 * (h_in + h_out), 0.5 * (h_out - h_in)], -1)
    grid = grid.reshape(n_dir, n_dir, n_off, n_off, 3)
    _dilate(grid)
    return grid.transpose(0, 2, 1, 3, 4).reshape(n_dir * n_off, n_dir * n_off, 3) \
        .astype(np.float32)


def _dilate(grid):
    """Give every missing texel of a tile its nearest hit's interval, in place: the bilinear
    lookup then blends a hit's interval only with intervals, never with a made-up one."""
    from scipy.ndimage import distance_transform_edt
    for tile in grid.reshape(-1, *grid.shape[2:]):
        miss = tile[..., 0] < 0.5
        if not miss.any():
            continue
        if miss.all():
            tile[..., 1], tile[..., 2] = 0.0, 0.0
            continue
        idx = distance_transform_edt(miss, return_distances=False, return_indices=True)
        tile[..., 1:] = tile[idx[0], idx[1], 1:]


def bilinear(img, x, y):
    """``img`` (H, W, C) at continuous texel coordinates ``x`` (columns) and ``y`` (rows),
    texel centres at k + 0.5, as Cycles' linear image interpolation reads it."""
    h, w = img.shape[:2]
    x0 = np.floor(x - 0.5)
    y0 = np.floor(y - 0.5)
    fx, fy = (x - 0.5 - x0)[..., None], (y - 0.5 - y0)[..., None]
    x0i = np.clip(x0, 0, w - 1).astype(int)
    x1i = np.clip(x0 + 1, 0, w - 1).astype(int)
    y0i = np.clip(y0, 0, h - 1).astype(int)
    y1i = np.clip(y0 + 1, 0, h - 1).astype(int)
    return ((1 - fy) * ((1 - fx) * img[y0i, x0i] + fx * img[y0i, x1i])
            + fy * ((1 - fx) * img[y1i, x0i] + fx * img[y1i, x1i]))


def basis_image(radius, n_dir=N_DIR, n_off=N_OFF):
    """(n_dir, 2 n_dir, 3): the tile (i, j)'s e1 at column i of row j and its e2 at column
    n_dir + i, each times n_off / 2 over the radius (a dot product with an offset is then in
    texels from the tile's middle)."""
    e1, e2 = basis(tile_direction(tile_centres(n_dir)))
    return np.concatenate([e1, e2], axis=1) * (0.5 * n_off / float(radius))


def line_visibility(table, basis_img, centre, radius, points, targets, start=1e-3,
                    n_dir=N_DIR, n_off=N_OFF):
    """Visibility (n,) of ``targets`` from ``points`` (each (n, 3), the object's frame) past the
    object of ``table`` (``build_table``, ``basis_image``): 0 where the segment meets it, 1
    where not.  The segment is trimmed by ``start`` radii at both ends (the receiving surface
    and the lamp are not the object)."""
    p = np.asarray(points, float)
    q = np.asarray(targets, float)
    c = np.asarray(centre, float)
    r = float(radius)
    dv = q - p
    length = np.linalg.norm(dv, axis=-1)
    u = dv / np.maximum(length, 1e-30)[..., None]
    flip, ab = tile_coords(u)
    tile = np.clip(np.floor(ab * (0.5 * n_dir) + 0.5 * n_dir), 0.0, n_dir - 1.0)
    col = tile[..., 0].astype(int)
    row = tile[..., 1].astype(int)
    e1 = basis_img[row, col]
    e2 = basis_img[row, n_dir + col]
    w = c - p
    tc = np.sum(w * u, axis=-1)                               # the centre's foot on the ray
    o = tc[..., None] * u - w                                 # the foot, from the centre
    st = np.stack([np.sum(o * e1, -1), np.sum(o * e2, -1)], -1)     # texels from the middle
    inside = np.sum(st * st, axis=-1) < (0.5 * n_off) ** 2     # the line crosses the bound
    xy = tile * n_off + np.clip(st + 0.5 * n_off, 0.5, n_off - 0.5)
    texel = bilinear(table, xy[..., 0], xy[..., 1])
    hit, mid, half = texel[..., 0], texel[..., 1], texel[..., 2]
    x = tc / r + flip * mid                                   # the object on the ray, in radii
    ahead = (x + half) > start                                # past the point ...
    before = (x - half) < (length / r - start)                # ... and before the target
    return 1.0 - (hit > 0.5) * (ahead & before & inside)
