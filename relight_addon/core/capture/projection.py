# SPDX-License-Identifier: GPL-3.0-or-later
"""Posed photos projected onto the UV atlases of meshes: the photo-textured model.

Per target mesh (world triangles with UVs and a texture size):

1. Texels: ``texture.mapping.rasterize_patches`` gives each texel centre its triangle; the
   triangle's affine map UV -> world places the texel (and its sub-samples) on the surface.
2. Per view and texel, a quality ``q = cos(theta) * p / (1 + p) * border * edge`` where theta is
   the angle between the surface normal and the direction to the camera, p the photo pixels the
   texel covers (resolution and distance), ``border`` a ramp over the photo's outer
   BORDER_FEATHER, ``edge`` a ramp over EDGE_FEATHER texels from where the view stops seeing the
   surface (occlusion edges and silhouettes, a distance transform in texture space); zero when
   the surface faces away (cos < MIN_COS), lies outside the photo, or is hidden.
   Visibility is ray cast through ``core.geometry.raycast``'s occluder (Embree, or the
   bridge's BVHTree): a segment from each texel to each camera (``exact_visibility``), and the
   first hit (triangle, distance) of every photo pixel's ray, kept in a per-view map.  Near
   silhouettes and creases a photo pixel mixes the surface with what is beside it, so a
   sample is dropped where the pixels it reads (its 3 x 3 neighbourhood) see another object,
   a face of the object turned another way, or a surface nearer than the texel: a texel takes
   colours of its own surface only, and its weight is the share of its samples kept.
   Saturated photo pixels weigh SATURATED_WEIGHT.
3. Exposure: a gain per view and channel (the first view fixed at 1) so that views agree where
   they overlap: least squares on the median log ratios of every pair of views over the texels
   both see well.
4. Blend: ``sum_v w_v g_v c_v / sum_v w_v`` with ``w_v = q_v ** SHARPNESS``: the best view
   dominates, a view about as good blends in, and the ramps above remove seams where a view
   starts or stops.  Colours are sampled bilinearly at s x s points of the texel, s growing
   (to MAX_SUPERSAMPLE) with the photo pixels a texel covers: the photo's noise averages out.
5. Holes (texels no view sees): reported, and filled from the nearest seen texels of the same
   mesh in 3D (inverse square distance, surfaces facing another way weighed down), so a texel
   hidden from every camera never takes an occluder's colour; then seam padding
   (``dilate_seams``) outside the charts.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import CaptureError
from ..geometry.extent import longest_side
from ..geometry.raycast import make_occluder
from ..texture.mapping import dilate_seams, rasterize_patches

MIN_COS = 0.1                 # views more grazing than ~84 degrees are not used
BORDER_FEATHER = 0.05         # of the photo's smaller side: weight ramp at the photo's edges
EDGE_FEATHER = 4.0            # texels: weight ramp away from where a view stops seeing
SHARPNESS = 4.0               # blend exponent on the quality
SATURATED = 0.99              # linear value (any channel) above which a photo pixel is clipped
SATURATED_WEIGHT = 1e-3
RAY_LIFT = 1e-5               # of the scene's size: ray origins off their surface
# a pixel of the footprint sees a nearer surface when its distance is below the texel's by
# this fraction, plus the depth change of a plane seen at the texel's angle over the footprint
NEARER = 0.01
SAME_FACING = 0.8             # cos between normals under which a pixel shows another surface
MAX_SUPERSAMPLE = 4
GAIN_TEXELS = 200_000         # texels of each mesh used to match the exposures
FOOTPRINT_TEXELS = 20_000     # texels of each mesh whose footprint sets the supersampling
GAIN_MIN_TEXELS = 50          # texels two views must share to compare their exposures
GAIN_DARK = 0.003             # linear values below this are too noisy to compare
HOLE_NEIGHBOURS = 8
HOLE_RING = 3                 # texels around the holes whose seen texels are searched
HOLE_SPARE = 100_000          # and this many others, at random
HOLE_FACING = 0.5             # cos between normals under which a neighbour weighs 1e-3
PAD_TEXELS = 4


@dataclass
class View:
    """A posed photo: K, world -> OpenCV camera (R, t), linear RGB (H, W, 3) top row first."""

    name: str
    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    image: np.ndarray

    @property
    def centre(self) -> np.ndarray:
        return -np.asarray(self.R).T @ np.asarray(self.t)


@dataclass
class Target:
    """A mesh to texture: world triangles (t, 3, 3), their UVs (t, 3, 2), texture (h, w)."""

    name: str
    triangles: np.ndarray
    uvs: np.ndarray
    size: tuple


@dataclass
class Projected:
    """One mesh's result: texture (h, w, 3) linear float32 (row 0 at v = 0: Blender's order,
    unlike the photos),
    covered (h, w) texels of some triangle, seen (h, w) texels some view saw, views used."""

    name: str
    texture: np.ndarray
    covered: np.ndarray
    seen: np.ndarray
    views: list = field(default_factory=list)

    @property
    def holes(self) -> int:
        return int(np.count_nonzero(self.covered & ~self.seen))


@dataclass
class ProjectionResult:
    meshes: list
    gains: dict                  # view name -> (3,) RGB gain
    unused_views: list           # views that saw none of the meshes
    supersample: dict            # mesh name -> samples a side

    def summary(self) -> str:
        cov = sum(int(m.covered.sum()) for m in self.meshes)
        holes = sum(m.holes for m in self.meshes)
        used = len(self.gains) - len(self.unused_views)
        g = np.array([v for k, v in self.gains.items() if k not in self.unused_views]).ravel()
        gains = f", exposure gains {g.min():.2f}-{g.max():.2f}" if len(g) else ""
        unused = (f" ({len(self.unused_views)} seeing none of them: "
                  f"{', '.join(self.unused_views[:3])})" if self.unused_views else "")
        return (f"Projected {used} photos{unused} onto {len(self.meshes)} meshes: "
                f"{100 * (1 - holes / max(cov, 1)):.1f} % of {cov:,} texels seen, {holes:,} holes "
                f"filled from their neighbours{gains}")


class _Texels:
    """The covered texels of a target: world positions, normals, size and UV-to-world maps."""

    def __init__(self, target: Target):
        tri = np.asarray(target.triangles, np.float64)
        uv = np.asarray(target.uvs, np.float64)
        h, w = int(target.size[0]), int(target.size[1])
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        area = 0.5 * np.linalg.norm(n, axis=1)
        normal = n / np.maximum(2 * area, 1e-300)[:, None]
        e1, e2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
        uv_area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
        good = (area > 0) & (uv_area > 1e-14)
        quad = np.concatenate([uv, uv[:, 2:3]], axis=1)           # (a, b, c, c)
        tm = rasterize_patches(quad, np.where(good, 0, -1), [(h, w)])[0]
        self.shape = (h, w)
        self.index = np.asarray(tm.texel_index, np.int64)
        self.tri = np.asarray(tm.patch, np.int64)
        self.covered = tm.coverage
        # affine map per triangle: world = P0 + [e1 e2]^-1 (uv - uv0) applied to edges
        det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
        det = np.where(np.abs(det) > 1e-300, det, 1.0)
        inv = np.stack([np.stack([e2[:, 1], -e2[:, 0]], -1), np.stack([-e1[:, 1], e1[:, 0]], -1)],
                       1) / det[:, None, None]                    # (t, 2, 2): uv -> (s, r)
        c = np.ascontiguousarray
        self._u0, self._v0 = c(uv[:, 0, 0]), c(uv[:, 0, 1])
        self._i00, self._i01, self._i10, self._i11 = (c(inv[:, 0, 0]), c(inv[:, 0, 1]),
                                                      c(inv[:, 1, 0]), c(inv[:, 1, 1]))
        self._p0 = [c(tri[:, 0, k]) for k in range(3)]
        self._d1 = [c(tri[:, 1, k] - tri[:, 0, k]) for k in range(3)]
        self._d2 = [c(tri[:, 2, k] - tri[:, 0, k]) for k in range(3)]
        self.normal = normal[self.tri]
        # world size of a texel on its triangle
        self.size = np.sqrt(area / np.maximum(uv_area * w * h, 1e-300))[self.tri]
        y, x = np.divmod(self.index, w)
        self.uv = np.stack([(x + 0.5) / w, (y + 0.5) / h], axis=1)
        self.centre = self._points((0.0, 0.0), slice(None))
        self.normal32 = self.normal.astype(np.float32)
        self.size32 = self.size.astype(np.float32)

    def __len__(self):
        return len(self.index)

    def world(self, offset=(0.0, 0.0), rows=None) -> np.ndarray:
        """World points of the texels (``rows``: some of them) at ``offset`` (in texels) from
        their centres."""
        rows = slice(None) if rows is None else rows
        if offset[0] == 0 and offset[1] == 0 and hasattr(self, "centre"):
            return self.centre[rows]
        return self._points(offset, rows)

    def _points(self, offset, rows):
        h, w = self.shape
        t = self.tri[rows]
        # component by component: gathers from 1D arrays, not (t, 2, 2) blocks
        du = self.uv[rows, 0] + offset[0] / w - self._u0[t]
        dv = self.uv[rows, 1] + offset[1] / h - self._v0[t]
        a = self._i00[t] * du + self._i01[t] * dv
        b = self._i10[t] * du + self._i11[t] * dv
        out = np.empty((len(t), 3))
        for k in range(3):
            out[:, k] = self._p0[k][t] + a * self._d1[k][t] + b * self._d2[k][t]
        return out


def _project(view: View, pts):
    """Pixel coordinates (n, 2) and depth (n,) of world points in a view (float32 after the
    camera's position is taken off in float64: sub-micrometre on a room)."""
    rel = (pts - view.centre[None]).astype(np.float32)
    c = rel @ np.asarray(view.R, np.float32).T
    z = c[:, 2]
    K = np.asarray(view.K, np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        iz = np.float32(1.0) / z
        u = np.float32(K[0, 0]) * c[:, 0] * iz + np.float32(K[0, 1]) * c[:, 1] * iz + np.float32(K[0, 2])
        v = np.float32(K[1, 1]) * c[:, 1] * iz + np.float32(K[1, 2])
    return np.stack([u, v], 1), z, rel


def _sample(image, uv) -> np.ndarray:
    """Bilinear samples (n, 3) of an image at pixel coordinates (OpenCV convention)."""
    import cv2  # noqa: PLC0415
    n = len(uv)
    if n == 0:
        return np.zeros((0, 3), np.float32)
    side = int(np.ceil(np.sqrt(n)))
    pad = side * side - n
    mx = np.concatenate([uv[:, 0], np.full(pad, -10.0)]).astype(np.float32).reshape(side, side)
    my = np.concatenate([uv[:, 1], np.full(pad, -10.0)]).astype(np.float32).reshape(side, side)
    out = cv2.remap(image, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return out.reshape(-1, 3)[:n]


def _footprint(view: View, tx: _Texels, rows) -> np.ndarray:
    """Photo pixels each texel of ``rows`` covers in a view where it faces the camera inside
    the frame (0 elsewhere); no visibility."""
    pts = tx.world(rows=rows)
    h, w = view.image.shape[:2]
    uv, z, _ = _project(view, pts)
    to_cam = view.centre[None] - pts
    cos = np.einsum("ij,ij->i", tx.normal[rows], to_cam) / np.maximum(
        np.linalg.norm(to_cam, axis=1), 1e-300)
    f = 0.5 * (view.K[0, 0] + view.K[1, 1])
    ppt = (f * tx.size[rows] / np.where(z > 1e-9, z, np.inf)) ** 2 * np.clip(cos, 0, 1)
    inside = (z > 0) & (cos > MIN_COS) & (uv[:, 0] > -0.5) & (uv[:, 0] < w - 0.5) \
        & (uv[:, 1] > -0.5) & (uv[:, 1] < h - 0.5)
    return np.where(inside, ppt, 0.0)


class _ViewMaps:
    """What every pixel of a photo sees, from the first hit of its ray, kept in 11 bytes a
    pixel: ``owner`` the object's index where the pixel's 3 x 3 neighbourhood sees that one
    object on faces turned alike (cos between its normals > SAME_FACING), else -2 (an edge,
    a crease, or nothing hit); ``depth`` the smallest distance over the neighbourhood;
    ``normal`` the pixel's surface normal (int8, / 127)."""

    def __init__(self, view: View, occluder, surfaces):
        import cv2  # noqa: PLC0415
        h, w = view.image.shape[:2]
        yy, xx = np.mgrid[0:h, 0:w]
        pix = np.stack([xx.ravel(), yy.ravel(), np.ones(h * w)], axis=1).astype(np.float64)
        rays = pix @ (np.linalg.inv(np.asarray(view.K, np.float64)).T @ np.asarray(view.R))
        rays /= np.linalg.norm(rays, axis=1, keepdims=True)
        t, prim = occluder.first_hit(np.broadcast_to(view.centre, rays.shape), rays)
        del rays, pix
        owner = surfaces.owner[prim].reshape(h, w).astype(np.float32)     # exact below 2^24
        normal = surfaces.normal[prim].reshape(h, w, 3).astype(np.float32)
        depth = np.where(np.isfinite(t), t, 3e38).reshape(h, w).astype(np.float32)
        del t, prim
        k = np.ones((3, 3), np.uint8)
        border = cv2.BORDER_REPLICATE
        same = cv2.erode(owner, k, borderType=border) == cv2.dilate(owner, k, borderType=border)
        # per channel planes: three multiply-adds a neighbour (an einsum over the channel axis
        # was a third of the maps' time)
        planes = [np.ascontiguousarray(normal[..., c]) for c in range(3)]
        pads = [np.pad(pl, 1, mode="edge") for pl in planes]
        for dy in (0, 1, 2):
            for dx in (0, 1, 2):
                if dy != 1 or dx != 1:
                    dot = pads[0][dy:dy + h, dx:dx + w] * planes[0]
                    dot += pads[1][dy:dy + h, dx:dx + w] * planes[1]
                    dot += pads[2][dy:dy + h, dx:dx + w] * planes[2]
                    same &= dot > SAME_FACING
        self.owner = np.where(same & (owner >= 0), owner, -2.0).astype(np.float32)
        self.depth = cv2.erode(depth, k, borderType=border)
        self.normal = np.rint(normal * 127).astype(np.int8)


class _Surfaces:
    """Per scene triangle: its object's index and its unit normal (for the clean test)."""

    def __init__(self, owner, triangles):
        n = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
        norm = np.linalg.norm(n, axis=1, keepdims=True)
        self.owner = np.append(np.asarray(owner, np.int64), -1)        # index -1: nothing hit
        self.normal = np.vstack([n / np.maximum(norm, 1e-300), np.zeros((1, 3))])


def _clean(maps, own, uv, dist, cos, normal, f):
    """Whether the pixels a bilinear sample at ``uv`` reads (its 3 x 3 neighbourhood) see the
    object ``own`` on a surface facing as the texel's (a crease of the object is an edge too)
    and nothing nearer than ``dist`` (less NEARER and the depth change of a plane at this
    angle over the window)."""
    h, w = maps.owner.shape
    x = np.clip(np.rint(uv[:, 0]).astype(np.int64), 0, w - 1)
    y = np.clip(np.rint(uv[:, 1]).astype(np.int64), 0, h - 1)
    tan = np.sqrt(np.maximum(1.0 - cos ** 2, 0.0)) / np.maximum(cos, MIN_COS)
    floor = dist * (1.0 - (NEARER + 3.0 * tan / f))
    facing = np.einsum("ij,ij->i", maps.normal[y, x].astype(np.float32),
                       np.asarray(normal, np.float32)) / np.float32(127.0)
    return (maps.owner[y, x] == own) & (maps.depth[y, x] >= floor) & (facing > SAME_FACING)


def _quality(view: View, tx: _Texels, occluder, lift, own, maps, rows=None, clean_centre=True,
             segments=False):
    """(q (n,), pixel coordinates (n, 2), pixels a texel covers (n,), distance (n,), cos (n,))
    of texels in a view, q = 0 where the view does not see them (edge feathering not
    included; with ``clean_centre``, also where the texel centre's sample is not clean)."""
    idx = slice(None) if rows is None else rows           # all texels: views, no copies
    pts = tx.world(rows=idx)
    nrm = tx.normal32[idx]
    h, w = view.image.shape[:2]
    uv, z, rel = _project(view, pts)
    dist = np.sqrt(np.einsum("ij,ij->i", rel, rel))
    with np.errstate(divide="ignore", invalid="ignore"):
        cos = -np.einsum("ij,ij->i", nrm, rel) / np.maximum(dist, np.float32(1e-30))
    f = 0.5 * (view.K[0, 0] + view.K[1, 1])
    ppt = (np.float32(f) * tx.size32[idx] / np.where(z > 1e-9, z, np.inf)) ** 2 \
        * np.clip(cos, 0, 1)
    margin = BORDER_FEATHER * min(h, w)
    edge = np.minimum(np.minimum(uv[:, 0] + 0.5, w - 0.5 - uv[:, 0]),
                      np.minimum(uv[:, 1] + 0.5, h - 0.5 - uv[:, 1]))
    ok = (z > 0) & (cos > MIN_COS) & (edge > 0) & np.isfinite(uv).all(axis=1)
    q = np.zeros(len(pts), np.float32)
    sel = np.flatnonzero(ok)
    if len(sel) and clean_centre:
        sel = sel[_clean(maps, own, uv[sel], dist[sel], cos[sel], nrm[sel], f)]
    if len(sel) and segments:
        start = pts[sel] + lift * tx.normal[idx][sel]
        hidden = occluder.segments_occluded(start, np.broadcast_to(view.centre, start.shape),
                                            eps=1e-7)
        sel = sel[~hidden]
    if len(sel):
        q[sel] = (cos[sel] * ppt[sel] / (1.0 + ppt[sel])
                  * np.clip(edge[sel] / max(margin, 1e-9), 0.0, 1.0))
    return q, uv, ppt, dist, cos


def _edge_ramp(tx: _Texels, seen_rows) -> np.ndarray:
    """Per texel, a ramp 0 -> 1 over EDGE_FEATHER texels away from the covered texels this view
    does not see (uncovered texels count as seen: chart borders are no edge)."""
    import cv2  # noqa: PLC0415
    h, w = tx.shape
    free = np.ones(h * w, np.uint8)
    unseen = np.ones(len(tx), bool)
    unseen[seen_rows] = False
    free[tx.index[unseen]] = 0
    dist = cv2.distanceTransform(free.reshape(h, w), cv2.DIST_L2, 3).reshape(-1)
    return np.clip(dist[tx.index] / EDGE_FEATHER, 0.0, 1.0)


def _gains(views, texel_sets, occluder, lift, owners, maps, rng):
    """Per view (3,) gains making overlapping views agree; the first view's is 1."""
    nv = len(views)
    logs = [[] for _ in range(nv)]          # per view: (texel key, log colour (3,))
    rows_of = []
    for tx in texel_sets:
        rows = np.arange(len(tx))
        if len(rows) > GAIN_TEXELS:
            rows = np.sort(rng.choice(len(rows), GAIN_TEXELS, replace=False))
        rows_of.append(rows)
    for v, view in enumerate(views):
        vm = maps(v)
        for m, tx in enumerate(texel_sets):
            rows = rows_of[m]
            q, uv, *_ = _quality(view, tx, occluder, lift, owners[m], vm, rows=rows)
            good = q > 0.05
            if not good.any():
                continue
            c = _sample(view.image, uv[good]).astype(np.float64)
            ok = (c.min(axis=1) > GAIN_DARK) & (c.max(axis=1) < SATURATED)
            keys = rows[good][ok] + (m << 40)
            logs[v].append((keys, np.log(c[ok])))
    per = [(np.concatenate([k for k, _ in L]), np.concatenate([c for _, c in L])) if L else
           (np.zeros(0, np.int64), np.zeros((0, 3))) for L in logs]
    eqs, rhs, wts = [], [], []
    for i in range(nv):
        for j in range(i + 1, nv):
            common, ia, ja = np.intersect1d(per[i][0], per[j][0], assume_unique=True,
                                            return_indices=True)
            if len(common) < GAIN_MIN_TEXELS:
                continue
            d = np.median(per[i][1][ia] - per[j][1][ja], axis=0)    # log c_i - log c_j
            row = np.zeros(nv)
            row[i], row[j] = 1.0, -1.0                               # log g_i - log g_j = -d
            eqs.append(row)
            rhs.append(-d)
            wts.append(np.sqrt(len(common)))
    gains = np.ones((nv, 3))
    if eqs:
        A = np.array(eqs) * np.array(wts)[:, None]
        b = np.array(rhs) * np.array(wts)[:, None]
        # the first view is the reference: its log gain is 0
        A = np.vstack([A, np.eye(nv)[:1] * 1e3])
        b = np.vstack([b, np.zeros((1, 3))])
        x, *_ = np.linalg.lstsq(A, b, rcond=None)
        connected = np.zeros(nv, bool)
        connected[0] = True
        for _ in range(nv):                       # views linked to the reference by pairs
            for row in eqs:
                i, j = np.flatnonzero(row)
                if connected[i] or connected[j]:
                    connected[i] = connected[j] = True
        gains = np.where(connected[:, None], np.exp(np.clip(x, -10, 10)), 1.0)
    return gains


def _fill_holes(tx: _Texels, colour, seen, rng):
    """Colours of unseen texels from the nearest seen texels of the mesh in 3D.  The seen
    texels searched: those within HOLE_RING texels of a hole in the texture (where a hole's
    nearest ones almost always are) and a random HOLE_SPARE of the others (holes that fill a
    whole chart)."""
    import cv2  # noqa: PLC0415
    from scipy.spatial import cKDTree  # noqa: PLC0415
    holes = np.flatnonzero(~seen)
    if len(holes) == 0 or not seen.any():
        return colour
    h, w = tx.shape
    mask = np.zeros(h * w, np.uint8)
    mask[tx.index[holes]] = 1
    k = np.ones((2 * HOLE_RING + 1, 2 * HOLE_RING + 1), np.uint8)
    ring = cv2.dilate(mask.reshape(h, w), k).reshape(-1).astype(bool)[tx.index] & seen
    src = np.flatnonzero(ring)
    rest = np.flatnonzero(seen & ~ring)
    if len(rest) > HOLE_SPARE:
        rest = rng.choice(rest, HOLE_SPARE, replace=False)
    src = np.concatenate([src, rest])
    pts = tx.world()
    tree = cKDTree(pts[src])
    kk = min(HOLE_NEIGHBOURS, len(src))
    d, j = tree.query(pts[holes], k=kk)
    d, j = d.reshape(len(holes), kk), j.reshape(len(holes), kk)
    facing = np.einsum("hd,hkd->hk", tx.normal[holes], tx.normal[src][j])
    wgt = np.where(facing > HOLE_FACING, 1.0, 1e-3) / np.maximum(d, 1e-9) ** 2
    out = colour.copy()
    out[holes] = np.einsum("hk,hkc->hc", wgt, colour[src][j]) / wgt.sum(axis=1, keepdims=True)
    return out


def suggest_texture_size(triangles, uvs, views, lo=64, hi=4096, samples=20_000, seed=0) -> int:
    """A texture side (a multiple of 64 in [lo, hi]) whose texels are about the size of a
    photo pixel on the surface where the photos see it best: the median, over points of the
    mesh, of the smallest footprint (distance / focal length / sqrt(cos)) among the views
    facing it inside their frame."""
    tri = np.asarray(triangles, np.float64)
    uv = np.asarray(uvs, np.float64)
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    e1, e2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    uv_area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    if area.sum() <= 0 or uv_area.sum() <= 0:
        return lo
    rng = np.random.default_rng(seed)
    pick = rng.choice(len(tri), min(samples, len(tri)), p=area / area.sum())
    pts = tri[pick].mean(axis=1)
    nrm = np.cross(tri[pick, 1] - tri[pick, 0], tri[pick, 2] - tri[pick, 0])
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-300)
    best = np.full(len(pts), np.inf)
    for view in views:
        h, w = np.asarray(view.image).shape[:2]
        uvp, z, _ = _project(view, pts)
        to_cam = view.centre[None] - pts
        d = np.linalg.norm(to_cam, axis=1)
        cos = np.einsum("ij,ij->i", nrm, to_cam) / np.maximum(d, 1e-300)
        ok = (z > 0) & (cos > MIN_COS) & (uvp[:, 0] > 0) & (uvp[:, 0] < w - 1) \
            & (uvp[:, 1] > 0) & (uvp[:, 1] < h - 1)
        f = 0.5 * (view.K[0, 0] + view.K[1, 1])
        foot = np.where(ok, d / f / np.sqrt(np.maximum(cos, MIN_COS)), np.inf)
        best = np.minimum(best, foot)
    seen = best[np.isfinite(best)]
    if not len(seen):
        return lo
    # texel side = sqrt(world area / (uv area N^2)) = footprint
    n = np.sqrt(area.sum() / uv_area.sum()) / float(np.median(seen))
    return int(np.clip(64 * np.ceil(n / 64), lo, hi))


def project(targets, views, scene_triangles, owners=None, supersample=None,
            match_exposure=True, fill_holes=True, progress=None, seed=0,
            exact_visibility=True) -> ProjectionResult:
    """Textures of ``targets`` from ``views``.  ``scene_triangles`` (t, 3, 3) occlude, and
    ``owners`` (t,) names the object of each (a target's own triangles must be among them,
    owned by its name; None: every triangle its own object, no target among them).
    ``supersample``: samples a side per texel (None: from the pixels a texel covers, 1 to
    MAX_SUPERSAMPLE).  ``exact_visibility``: cast a segment from every texel to every camera
    besides the per-pixel first hits (those alone, with their tolerance, let a few texels
    hidden by a nearby surface through: 28 of 17,250 on the office)."""
    if not targets:
        raise CaptureError("No mesh to texture")
    if not views:
        raise CaptureError("No photo to project")
    for v in views:
        img = np.asarray(v.image)
        if img.ndim != 3 or img.shape[2] < 3 or not np.isfinite(img).all():
            raise CaptureError(f"The photo of '{v.name}' is not a finite RGB image")
        v.image = np.ascontiguousarray(img[..., :3], np.float32)
    tris = np.asarray(scene_triangles, np.float64).reshape(-1, 3, 3)
    names = [] if owners is None else list(owners)
    finite = np.isfinite(tris).all(axis=(1, 2))
    tris = tris[finite]
    objects = sorted(set(names)) if names else []
    index = {n: i for i, n in enumerate(objects)}
    owner = (np.array([index[n] for n, keep in zip(names, finite) if keep], np.int64)
             if names else np.arange(len(tris), dtype=np.int64) + len(targets) + 1)
    own = [index.get(t.name, -2) for t in targets]
    occluder = make_occluder(tris)
    lift = RAY_LIFT * (longest_side(tris.reshape(-1, 3)) if len(tris) else 1.0)
    texel_sets = [_Texels(t) for t in targets]
    rng = np.random.default_rng(seed)
    steps = len(views) * len(targets) + len(views)
    done = 0

    def tick():
        nonlocal done
        done += 1
        if progress is not None:
            progress(min(1.0, done / steps))

    surfaces = _Surfaces(owner, tris)
    cache = {}

    def maps(v):
        if v not in cache:
            cache[v] = _ViewMaps(views[v], occluder, surfaces)
            tick()
        return cache[v]

    # samples a side per texel: from the pixels a texel covers in the view that sees it best
    # (the geometry alone: facing and in the frame)
    samples_of = []
    for tx in texel_sets:
        s = supersample
        if s is None:              # on a sample of the texels: a median needs no more
            rows = np.arange(len(tx))
            if len(rows) > FOOTPRINT_TEXELS:
                rows = np.sort(rng.choice(len(rows), FOOTPRINT_TEXELS, replace=False))
            best = np.zeros(len(rows))
            for view in views:
                best = np.maximum(best, _footprint(view, tx, rows))
            seen_ppt = best[best > 0]
            s = int(np.clip(np.floor(np.sqrt(np.median(seen_ppt))) if len(seen_ppt) else 1,
                            1, MAX_SUPERSAMPLE))
        samples_of.append(int(s))
    gains = (_gains(views, texel_sets, occluder, lift, own, maps, rng) if match_exposure
             else np.ones((len(views), 3)))
    used = np.zeros(len(views), bool)
    acc = [(np.zeros((len(tx), 3)), np.zeros(len(tx)), []) for tx in texel_sets]
    for v, view in enumerate(views):
        vm = maps(v)
        for m, tx in enumerate(texel_sets):
            num, den, names_used = acc[m]
            s = samples_of[m]
            offsets = [((i + 0.5) / s - 0.5, (j + 0.5) / s - 0.5)
                       for i in range(s) for j in range(s)]
            q, uv_all, _, dist, cos = _quality(view, tx, occluder, lift, own[m], vm,
                                               clean_centre=False, segments=exact_visibility)
            rows = np.flatnonzero(q > 0)
            tick()
            if len(rows) == 0:
                continue
            # the sub-texel samples whose pixels see this object and nothing nearer
            f = 0.5 * (view.K[0, 0] + view.K[1, 1])
            if s == 1:                    # the texel centre, projected already
                uv = uv_all[rows]
                ok = _clean(vm, own[m], uv, dist[rows], cos[rows], tx.normal32[rows], f)
                rows = rows[ok]
                colour = _sample(view.image, uv[ok])
                sat = colour.max(axis=1) >= SATURATED
                share = np.ones(len(rows), np.float32)
            else:
                colour = np.zeros((len(rows), 3), np.float32)
                count = np.zeros(len(rows), np.float32)
                sat = np.zeros(len(rows), bool)
                for off in offsets:       # s * s sub-texel points (at most 16)
                    uv = _project(view, tx.world(off, rows))[0]
                    ok = _clean(vm, own[m], uv, dist[rows], cos[rows], tx.normal32[rows], f)
                    c = _sample(view.image, uv)
                    sat |= ok & (c.max(axis=1) >= SATURATED)
                    colour += np.where(ok[:, None], c, 0.0)
                    count += ok
                keep = count > 0
                rows, colour, sat = rows[keep], colour[keep], sat[keep]
                colour /= count[keep][:, None]
                share = count[keep] / len(offsets)
            if len(rows) == 0:
                continue
            qq = q[rows] * share * _edge_ramp(tx, rows)[rows]
            good = qq > 0
            rows, colour, qq, sat = rows[good], colour[good], qq[good], sat[good]
            if len(rows) == 0:
                continue
            used[v] = True
            names_used.append(view.name)
            wgt = qq ** SHARPNESS * np.where(sat, SATURATED_WEIGHT, 1.0)
            num[rows] += wgt[:, None] * colour * gains[v]
            den[rows] += wgt
    meshes, samples_used = [], {}
    for m, (target, tx) in enumerate(zip(targets, texel_sets)):
        num, den, names_used = acc[m]
        seen = den > 0
        colour = num / np.maximum(den, 1e-300)[:, None]
        if fill_holes:
            colour = _fill_holes(tx, colour, seen, rng)
        h, w = tx.shape
        tex = np.zeros((h * w, 3), np.float32)
        tex[tx.index] = colour
        seen_img = np.zeros(h * w, bool)
        seen_img[tx.index] = seen
        tex = tex.reshape(h, w, 3)
        cover = tx.covered.copy() if fill_holes else seen_img.reshape(h, w)
        tex, _ = dilate_seams(tex, cover, pixels=PAD_TEXELS)
        meshes.append(Projected(target.name, np.nan_to_num(tex).astype(np.float32),
                                tx.covered, seen_img.reshape(h, w), names_used))
        samples_used[target.name] = samples_of[m]
    unused = [v.name for v, u in zip(views, used) if not u]
    return ProjectionResult(meshes, {v.name: g for v, g in zip(views, gains)}, unused,
                            samples_used)
