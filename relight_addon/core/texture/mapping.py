"""Texel <-> patch / element mapping (seed 000 §4.2-4.3).

Conventions
-----------
* UV space is Blender's: ``(0, 0)`` is the lower-left corner of the image, ``(1, 1)`` the upper
  right.  Image arrays are indexed ``image[y, x]`` with row ``y = 0`` at ``v = 0`` (this is the
  order of ``bpy.types.Image.pixels``; flip rows when loading a top-row-first file with OpenCV).
* Texel ``(x, y)`` of a ``(H, W)`` image has its centre at ``((x + 0.5) / W, (y + 0.5) / H)``
  and flat index ``y * W + x``.
* A patch covers, in UV space, the bilinear quad of its four uv corners, or for a triangle
  ``(a, b, c, c)`` the uv triangle.  Its parameters ``(u, v)`` at a texel are those of the
  bilinear map ``P(u, v) = (1-u)(1-v) a + u(1-v) b + u v c + (1-u) v d`` (the same map as
  :func:`relight_addon.core.scene.bilinear_point`), so they are directly usable with
  :meth:`Hierarchy.locate`.

Everything is vectorised: rasterisation expands (patch, texel) candidate pairs of all patches
of an image at once (chunked), never looping over patches or texels in Python.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..geometry.extent import longest_side
from ..numerics import safe_div

# Tolerance (in patch parameter units) for a texel centre lying exactly on a patch edge.
INSIDE_TOLERANCE = 1e-9
# Candidate (patch, texel) pairs processed at once (peak ~40 MB of temporaries); besides the
# outputs, rasterisation keeps ~14 bytes per texel of state.
CHUNK_PAIRS = 1 << 17
# An image of more texels than this (a photo-resolution texture, above 1024^2) keeps its texel
# parameters in float32
PHOTO_TEXELS = 1 << 20

# Parameter quantisation used to identify shared element corners (params are dyadic).
_PARAM_QUANTUM = float(1 << 30)


# ------------------------------------------------------------------------------------------
# Texel map
# ------------------------------------------------------------------------------------------
@dataclass
class CoveredTexels:
    """The covered texels of one image.

    shape        (H, W)
    texel_index  (t,) int32    flat texel index ``y * W + x``, increasing (int64 past 2**31)
    patch        (t,) int32    owning patch (the concatenated views of TexelMap are int64)
    u, v         (t,) float64  the patch's bilinear parameters at the texel centre (float32
                               in an image of more than PHOTO_TEXELS texels)
    coverage     (H, W) bool   texels owned by some patch
    n_overlap    int           texels claimed by more than one patch (overlapping UVs)
    """

    shape: tuple
    texel_index: np.ndarray
    patch: np.ndarray
    u: np.ndarray
    v: np.ndarray
    coverage: np.ndarray
    n_overlap: int = 0

    def __len__(self):
        return len(self.texel_index)

    @property
    def xy(self):
        """Integer texel coordinates (x, y) of the covered texels."""
        y, x = np.divmod(self.texel_index, self.shape[1])
        return x, y

    @property
    def uv(self):
        """Texture coordinates (t, 2) of the covered texel centres."""
        x, y = self.xy
        return np.stack([(x + 0.5) / self.shape[1], (y + 0.5) / self.shape[0]], axis=-1)


@dataclass
class TexelMap:
    """Covered texels of every image.  ``images[k]`` describes image ``k``.

    The concatenated views (``patch``, ``u``, ``v``, ``texel_index``, ``image``) list the
    texels of image 0, then image 1, ...: that is the order of the ``(T, ...)`` arrays taken
    and returned by :func:`texel_elements`, :func:`element_means`, :meth:`gather` and
    :meth:`scatter`.
    """

    images: list = field(default_factory=list)

    def __len__(self):
        return len(self.images)

    def __getitem__(self, k) -> CoveredTexels:
        return self.images[k]

    @property
    def n_texels(self) -> int:
        return int(sum(len(im) for im in self.images))

    @property
    def offsets(self) -> np.ndarray:
        """Start of each image's texels in the concatenated arrays (len(images) + 1)."""
        return np.concatenate([[0], np.cumsum([len(im) for im in self.images])]).astype(np.int64)

    def _cat(self, name, dtype):
        parts = [getattr(im, name) for im in self.images]
        return np.concatenate(parts).astype(dtype, copy=False) if parts else np.zeros(0, dtype)

    @property
    def patch(self):
        return self._cat("patch", np.int64)

    @property
    def u(self):
        return self._cat("u", np.float64)

    @property
    def v(self):
        return self._cat("v", np.float64)

    @property
    def texel_index(self):
        return self._cat("texel_index", np.int64)

    @property
    def image(self):
        """Image index of every texel of the concatenated arrays."""
        return np.repeat(np.arange(len(self.images)), [len(im) for im in self.images])

    def rows(self, start: int, stop: int) -> "TexelMap":
        """The texels start .. stop - 1 of the concatenated order, as a TexelMap of the same
        images (views, no copies): a block of a texture too large to work on whole."""
        images, off = [], self.offsets
        for i, im in enumerate(self.images):
            a, b = max(start - off[i], 0), min(stop - off[i], len(im))
            sl = slice(a, max(a, b))
            images.append(CoveredTexels(im.shape, im.texel_index[sl], im.patch[sl], im.u[sl],
                                        im.v[sl], im.coverage))
        return TexelMap(images)

    def gather(self, images) -> np.ndarray:
        """Values (T, C) of the covered texels, read from ``images`` (list of (H, W, C))."""
        parts = []
        for im, arr in zip(self.images, images):
            arr = np.asarray(arr)
            parts.append(arr.reshape(im.shape[0] * im.shape[1], -1)[im.texel_index])
        if not parts:
            return np.zeros((0, 3))
        return np.concatenate(parts, axis=0)

    def scatter(self, values, fill=0.0, images=None) -> list:
        """Write per-texel ``values`` (T, C) into images; uncovered texels get ``fill``
        (or keep the content of ``images`` when given, which is copied)."""
        values = np.asarray(values)
        values2 = values.reshape(len(values), -1)
        out = []
        off = self.offsets
        for k, im in enumerate(self.images):
            h, w = im.shape
            if images is not None:
                base = np.array(images[k], dtype=values.dtype, copy=True).reshape(h * w, -1)
            else:
                base = np.full((h * w, values2.shape[1]), fill, dtype=values.dtype)
            base[im.texel_index] = values2[off[k]:off[k + 1]]
            out.append(base.reshape((h, w) + values.shape[1:]))
        return out


def texel_subset(texel_map, mask):
    """The texels of ``texel_map`` where ``mask`` (T,) holds, in the same order."""
    images, start = [], 0
    for im in texel_map.images:
        m = mask[start:start + len(im)]
        start += len(im)
        images.append(CoveredTexels(im.shape, im.texel_index[m], im.patch[m], im.u[m], im.v[m],
                                    im.coverage))
    return TexelMap(images)


# ------------------------------------------------------------------------------------------
# Inverse maps
# ------------------------------------------------------------------------------------------
def _cross(x, y):
    return x[..., 0] * y[..., 1] - x[..., 1] * y[..., 0]


def inverse_bilinear(corners: np.ndarray, p: np.ndarray):
    """Parameters (u, v) with ``bilinear_point(corners, u, v) == p`` for 2D quads.

    corners (n, 4, 2), p (n, 2).  Closed form (quadratic in v with numerically stable roots;
    the root nearest the unit square is kept, so both orientations -- mirrored UV islands --
    work; u by least squares over both coordinates, so rotations are safe), polished by one
    Newton step to machine precision.  Returns u, v and ``valid`` (a real root exists).
    Points outside the quad get parameters outside [0, 1].
    """
    corners = np.asarray(corners, np.float64)
    p = np.asarray(p, np.float64)
    coef = _patch_coefficients(corners, np.zeros(len(corners), bool))
    u, v, margin = _invert_quads(coef, np.arange(len(corners)), p[:, 0].copy(), p[:, 1].copy())
    return u, v, np.isfinite(margin)


def inverse_triangle(corners: np.ndarray, p: np.ndarray):
    """(u, v) of the Duffy map of triangles (a, b, c, c) from barycentric coordinates.

    ``P(u, v) = (1-u)(1-v) a + u (1-v) b + v c`` so ``v = lambda_c`` and
    ``u = lambda_b / (1 - v)`` (``u = 1/2`` at the apex).  Also returns the smallest barycentric
    coordinate (>= 0 inside, -inf for degenerate triangles).
    """
    corners = np.asarray(corners, np.float64)
    p = np.asarray(p, np.float64)
    coef = _patch_coefficients(corners, np.ones(len(corners), bool))
    return _invert_triangles(coef, np.arange(len(corners)), p[:, 0].copy(), p[:, 1].copy())


def uv_patch_is_triangle(uv: np.ndarray) -> np.ndarray:
    return np.all(uv[:, 2] == uv[:, 3], axis=-1)


# ------------------------------------------------------------------------------------------
# Rasterisation
# ------------------------------------------------------------------------------------------
def rasterize_patches(uv, image_index, shapes, chunk_pairs: int = CHUNK_PAIRS) -> TexelMap:
    """Which patch covers every texel centre of every image, and where.

    uv (p, 4, 2) texture coordinates of the patch corners; image_index (p,) image of each
    patch (-1: none); shapes [(H, W), ...] (extra trailing dims are ignored).

    All patches of an image are rasterised in one vectorised pass: texel bounding boxes,
    candidate (patch, texel) pairs by ``np.repeat`` (chunks of ``chunk_pairs``), inverse map,
    inside test.  Where patches overlap in UV space, the texel goes to the patch where it is
    deepest inside (largest parameter margin), so a texel centre on a shared edge has exactly
    one owner; ``n_overlap`` counts texels strictly inside several patches.
    """
    uv = np.asarray(uv, np.float64).reshape(-1, 4, 2)
    image_index = np.asarray(image_index, np.int64).reshape(-1)
    images = []
    for k, shape in enumerate(shapes):
        h, w = int(shape[0]), int(shape[1])
        ids = np.flatnonzero(image_index == k)
        images.append(_rasterize_image(uv[ids], ids, h, w, chunk_pairs))
    return TexelMap(images)


def _rasterize_image(uv, ids, h, w, chunk_pairs) -> CoveredTexels:
    n = h * w
    # Per-texel running state kept small (~14 bytes a texel): the owner (local patch index) and
    # its margin; (u, v) are recomputed for the final owners only.
    owner = np.full(n, -1, np.int32 if len(ids) < 2**31 else np.int64)
    best = np.full(n, -np.inf, np.float32)
    n_hits = np.zeros(n, np.uint8)            # saturates at 255: only "> 1" is used
    stamp = np.empty(n, np.int32 if chunk_pairs < 2**31 else np.int64)   # scratch, see below
    dup = np.zeros(n, bool)
    coef = None
    if len(ids):
        # Texel-space coordinates: the centre of texel x sits at X = x.
        pts = uv * np.array([w, h], np.float64) - 0.5
        lo = pts.min(axis=1)
        hi = pts.max(axis=1)
        eps = 1e-7
        x0 = np.clip(np.ceil(lo[:, 0] - eps), 0, w).astype(np.int64)
        x1 = np.clip(np.floor(hi[:, 0] + eps), -1, w - 1).astype(np.int64)
        y0 = np.clip(np.ceil(lo[:, 1] - eps), 0, h).astype(np.int64)
        y1 = np.clip(np.floor(hi[:, 1] + eps), -1, h - 1).astype(np.int64)
        nx = np.maximum(x1 - x0 + 1, 0)
        ny = np.maximum(y1 - y0 + 1, 0)
        coef = _patch_coefficients(pts, uv_patch_is_triangle(uv))
        live = np.flatnonzero(nx * ny > 0)
        # Boxes: split the texel box of big patches into bands of rows so that no box holds
        # more than chunk_pairs texels (a patch spanning a whole 8k texture stays bounded).
        rows = np.maximum(chunk_pairs // np.maximum(nx[live], 1), 1)
        nsub = -(-ny[live] // rows)
        bp = np.repeat(live, nsub)                                   # box -> patch
        k = np.arange(len(bp)) - np.repeat(np.cumsum(nsub) - nsub, nsub)
        brows = np.repeat(rows, nsub)
        by0 = y0[bp] + k * brows
        bny = np.minimum(brows, y1[bp] - by0 + 1)
        bnx = nx[bp]
        count = bnx * bny
        # Chunks of consecutive boxes with <= chunk_pairs candidate pairs each.
        csum = np.cumsum(count)
        starts = [0]
        while starts[-1] < len(bp):
            base = csum[starts[-1] - 1] if starts[-1] else 0
            end = int(np.searchsorted(csum, base + chunk_pairs, side="right"))
            starts.append(max(end, starts[-1] + 1))
        for s0, s1 in zip(starts[:-1], starts[1:]):
            cnt = count[s0:s1]
            box = np.repeat(np.arange(s0, s1), cnt)
            first = np.cumsum(cnt) - cnt
            off = np.arange(int(cnt.sum()), dtype=np.int64) - np.repeat(first, cnt)
            oy, ox = np.divmod(off, bnx[box])
            pid = bp[box]
            x = x0[pid] + ox
            y = by0[box] + oy
            del box, off, ox, oy
            u, v, margin = _invert(coef, pid, x.astype(np.float64), y.astype(np.float64))
            inside = margin >= -INSIDE_TOLERANCE
            if not inside.any():
                continue
            texel = (y * w + x)[inside]
            pid, margin = pid[inside], margin[inside]
            # Texels with a single candidate in this chunk (almost all of them) are merged
            # directly; a scatter/gather stamp finds the others without sorting everything.
            idx = np.arange(len(texel), dtype=stamp.dtype)
            stamp[texel] = idx
            clash = stamp[texel] != idx
            if clash.any():
                dup[texel[clash]] = True
                multi = dup[texel]
                dup[texel[clash]] = False
                single = np.flatnonzero(~multi)
                multi = np.flatnonzero(multi)
            else:
                single, multi = slice(None), None
            ts, ms, ps = texel[single], margin[single], pid[single]
            n_hits[ts] += ms > INSIDE_TOLERANCE
            better = ms > best[ts]
            best[ts[better]] = ms[better]
            owner[ts[better]] = ps[better]
            if multi is None:
                continue
            texel, margin, pid = texel[multi], margin[multi], pid[multi]
            # Several candidates: best per texel (sorted by texel, then margin) ...
            order = np.lexsort((margin, texel))
            ts = texel[order]
            last = np.ones(len(ts), bool)
            last[:-1] = ts[1:] != ts[:-1]
            # ... texels strictly inside several patches (overlapping UV islands) ...
            strict = (margin[order] > INSIDE_TOLERANCE).astype(np.int64)
            group_end = np.flatnonzero(last)
            group_start = np.concatenate([[0], group_end[:-1] + 1])
            hits = np.add.reduceat(strict, group_start)
            ut = ts[group_end]
            n_hits[ut] = np.minimum(n_hits[ut].astype(np.int64) + hits, 255).astype(np.uint8)
            # ... merged with the running best over previous chunks.
            pick = order[group_end]
            better = margin[pick] > best[ut]
            t = ut[better]
            pick = pick[better]
            best[t] = margin[pick]
            owner[t] = pid[pick]
    texel_index = np.flatnonzero(owner >= 0)
    local = owner[texel_index].astype(np.int64)
    u = np.empty(len(texel_index))
    v = np.empty(len(texel_index))
    for c0 in range(0, len(texel_index), chunk_pairs):
        sl = slice(c0, c0 + chunk_pairs)
        y, x = np.divmod(texel_index[sl], w)
        uu, vv, _ = _invert(coef, local[sl], x.astype(np.float64), y.astype(np.float64))
        u[sl] = np.clip(uu, 0.0, 1.0)
        v[sl] = np.clip(vv, 0.0, 1.0)
    # 32-bit indices: a photo-resolution map holds tens of millions of texels; and the
    # parameters of a photo-resolution image's texels are float32 (1e-4 of a texel's width on
    # a patch spanning a 2048^2 image), those of smaller images float64
    small = np.int32 if max(n, int(ids.max(initial=0)) + 1) < 2**31 else np.int64
    if n > PHOTO_TEXELS:
        u, v = u.astype(np.float32), v.astype(np.float32)
    return CoveredTexels(
        shape=(h, w), texel_index=texel_index.astype(small),
        patch=np.asarray(ids, np.int64)[local].astype(small),
        u=u, v=v, coverage=(owner >= 0).reshape(h, w), n_overlap=int(np.count_nonzero(n_hits > 1)))


def _patch_coefficients(pts, tri):
    """Per-patch constants of the inverse maps (texel-space corners pts (m, 4, 2)).

    Stored as separate contiguous 1D arrays: gathering rows of an (m, 2) array per candidate
    is an order of magnitude slower than gathering from 1D arrays.
    """
    a, b, c, d = (pts[:, i, :] for i in range(4))
    e = b - a
    f = d - a
    g = a - b + c - d
    ca = c - a
    col = lambda x: np.ascontiguousarray(x)  # noqa: E731
    return dict(ax=col(a[:, 0]), ay=col(a[:, 1]), ex=col(e[:, 0]), ey=col(e[:, 1]),
                fx=col(f[:, 0]), fy=col(f[:, 1]), gx=col(g[:, 0]), gy=col(g[:, 1]),
                k2=_cross(g, f), kef=_cross(e, f), cx=col(ca[:, 0]), cy=col(ca[:, 1]),
                area2=_cross(e, ca), tri=np.asarray(tri, bool))


def _invert(coef, pid, x, y):
    """Inverse map of candidates (patch pid, texel-space point (x, y)); margin >= 0 inside."""
    tri = coef["tri"][pid]
    n_tri = int(np.count_nonzero(tri))
    if n_tri == 0:
        return _invert_quads(coef, pid, x, y)
    if n_tri == len(pid):
        return _invert_triangles(coef, pid, x, y)
    u = np.empty(len(pid))
    v = np.empty(len(pid))
    margin = np.empty(len(pid))
    for sel, fn in ((np.flatnonzero(~tri), _invert_quads), (np.flatnonzero(tri), _invert_triangles)):
        u[sel], v[sel], margin[sel] = fn(coef, pid[sel], x[sel], y[sel])
    return u, v, margin


def _invert_quads(coef, pid, x, y):
    """Closed-form inverse bilinear map (stable quadratic roots, root nearest the unit square,
    least-squares u), polished by one Newton step.  Margin: distance to the unit square's
    boundary in parameter space (>= 0 inside), -inf where no real root exists."""
    g = lambda name: coef[name][pid]  # noqa: E731
    ex, ey, fx, fy, gx, gy = g("ex"), g("ey"), g("fx"), g("fy"), g("gx"), g("gy")
    hx = x - g("ax")
    hy = y - g("ay")
    k2 = g("k2")
    k1 = g("kef") + hx * gy - hy * gx
    k0 = hx * ey - hy * ex
    disc = k1 * k1 - 4.0 * k0 * k2
    with np.errstate(divide="ignore", invalid="ignore"):
        valid = disc >= -1e-12 * (k1 * k1)
        w = np.sqrt(np.maximum(disc, 0.0))
        q = -0.5 * (k1 + np.copysign(w, k1))
        v = k0 / q                                    # the root that survives k2 -> 0
        if np.any(k2 != 0):
            v2 = q / k2
            v = np.where(np.abs(v2 - 0.5) < np.abs(v - 0.5), v2, v)
        # u from h = u (e + g v) + v f, least squares over both coordinates (rotation-safe).
        dx = ex + gx * v
        dy = ey + gy * v
        u = safe_div((hx - fx * v) * dx + (hy - fy * v) * dy, dx * dx + dy * dy)
        # One Newton step polishes the closed form to machine precision.
        rx = ex * u + fx * v + gx * (u * v) - hx
        ry = ey * u + fy * v + gy * (u * v) - hy
        jvx = fx + gx * u
        jvy = fy + gy * u
        det = dx * jvy - dy * jvx
        ok = det != 0
        sdet = det + ~ok
        u = u - ok * ((rx * jvy - ry * jvx) / sdet)
        v = v - ok * ((dx * ry - dy * rx) / sdet)
        margin = np.minimum(np.minimum(u, 1.0 - u), np.minimum(v, 1.0 - v))
    valid &= np.isfinite(margin)
    margin[~valid] = -np.inf
    return u, v, margin


def _invert_triangles(coef, pid, x, y):
    """Duffy parameters of triangles from barycentric coordinates (see inverse_triangle);
    margin: the smallest barycentric coordinate."""
    area2 = coef["area2"][pid]
    nz = area2 != 0
    sarea = area2 + ~nz
    hx = x - coef["ax"][pid]
    hy = y - coef["ay"][pid]
    cx, cy = coef["cx"][pid], coef["cy"][pid]
    ex, ey = coef["ex"][pid], coef["ey"][pid]
    lb = (hx * cy - hy * cx) / sarea
    lc = (ex * hy - ey * hx) / sarea
    la = 1.0 - lb - lc
    one_v = 1.0 - lc
    big = one_v > 1e-12
    u = np.where(big, lb / np.where(big, one_v, 1.0), 0.5)
    margin = np.minimum(np.minimum(la, lb), lc)
    margin[~nz] = -np.inf
    return u, lc, margin


# ------------------------------------------------------------------------------------------
# Texels -> elements
# ------------------------------------------------------------------------------------------
def texel_elements(hierarchy, texel_map: TexelMap) -> np.ndarray:
    """Leaf element id of every texel of ``texel_map`` (concatenated order).

    Roots are patches (element id == patch id), so this is ``locate(patch, u, v)``.
    """
    if texel_map.n_texels == 0:
        return np.zeros(0, np.int64)
    return hierarchy.locate(texel_map.patch, texel_map.u, texel_map.v)


def element_means(values, element_ids, n_elements, hierarchy=None):
    """Mean texel value per element and texel count.

    values (T, C), element_ids (T,) -> means (n, C), counts (n,).  Elements without texels get
    NaN.  With ``hierarchy`` the sums are pulled up the tree (see :func:`pull_up_means`), so
    every element -- not only leaves -- gets the mean of all the texels it covers (the B-hat
    of eq 4.1), and texel-less elements inherit their nearest ancestor's mean.
    """
    values = np.asarray(values, np.float64)
    values2 = values.reshape(len(values), -1)
    element_ids = np.asarray(element_ids, np.int64)
    if hierarchy is not None and n_elements != hierarchy.n:
        raise ValueError("with a hierarchy, n_elements must be hierarchy.n")
    counts = np.bincount(element_ids, minlength=n_elements).astype(np.float64)
    sums = np.stack([np.bincount(element_ids, weights=values2[:, j], minlength=n_elements)
                     for j in range(values2.shape[1])], axis=-1)
    return _means(sums, counts, n_elements, hierarchy, values.shape[1:])


# texels located in the hierarchy at once by texel_element_means: bounded working memory
MEANS_BLOCK = 1 << 20


def texel_element_means(hierarchy, texel_map: TexelMap, values):
    """:func:`element_means` (with the hierarchy) of per-texel ``values`` (T, C) over the
    elements the texels of ``texel_map`` fall in, located block by block (a photo-resolution
    map's element ids are never held whole)."""
    T, n = texel_map.n_texels, hierarchy.n
    if T <= MEANS_BLOCK:
        return element_means(values, texel_elements(hierarchy, texel_map), n, hierarchy)
    C = int(np.prod(np.shape(values)[1:]))
    counts = np.zeros(n)
    sums = np.zeros((n, C))
    for start in range(0, T, MEANS_BLOCK):
        stop = min(T, start + MEANS_BLOCK)
        ids = texel_elements(hierarchy, texel_map.rows(start, stop))
        part = np.asarray(values[start:stop], np.float64).reshape(stop - start, C)
        counts += np.bincount(ids, minlength=n)
        for j in range(C):
            sums[:, j] += np.bincount(ids, weights=part[:, j], minlength=n)
    return _means(sums, counts, n, hierarchy, np.shape(values)[1:])


def _means(sums, counts, n_elements, hierarchy, shape):
    if hierarchy is not None:
        sums, counts = _pull_up_sums(hierarchy, sums, counts)
    with np.errstate(invalid="ignore", divide="ignore"):
        means = sums / counts[:, None]
    means[counts == 0] = np.nan
    if hierarchy is not None:
        means = _push_down_missing(hierarchy, means, counts)
    return means.reshape((n_elements,) + tuple(shape)), counts.astype(np.int64)


def pull_up_means(hierarchy, means, counts):
    """Means of inner elements as the texel-count-weighted mean of their children's.

    ``means`` (n, C) / ``counts`` (n,) may hold values for any elements (typically leaves);
    a parent's own direct texels, if any, are kept and added.  Returns new (means, counts).
    """
    means = np.nan_to_num(np.asarray(means, np.float64))
    counts = np.asarray(counts, np.float64)
    sums, counts = _pull_up_sums(hierarchy, means * counts[:, None], counts)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = sums / counts[:, None]
    out[counts == 0] = np.nan
    return _push_down_missing(hierarchy, out, counts), counts.astype(np.int64)


def _levels(hierarchy):
    level = hierarchy.level[: hierarchy.n].astype(np.int64)
    order = np.argsort(level, kind="stable")
    bounds = np.searchsorted(level[order], np.arange(level.max(initial=0) + 2))
    return order, bounds


def _pull_up_sums(hierarchy, sums, counts):
    sums = sums.copy()
    counts = counts.copy()
    n = hierarchy.n
    parent = hierarchy.parent[:n]
    order, bounds = _levels(hierarchy)
    for lev in range(len(bounds) - 2, 0, -1):         # deepest level first, roots excluded
        ids = order[bounds[lev]:bounds[lev + 1]]
        if len(ids) == 0:
            continue
        par = parent[ids]
        counts += np.bincount(par, weights=counts[ids], minlength=n)[: len(counts)]
        for j in range(sums.shape[1]):
            sums[:, j] += np.bincount(par, weights=sums[ids, j], minlength=n)[: len(counts)]
    return sums, counts


def _push_down_missing(hierarchy, means, counts):
    n = hierarchy.n
    parent = hierarchy.parent[:n]
    order, bounds = _levels(hierarchy)
    for lev in range(1, len(bounds) - 1):
        ids = order[bounds[lev]:bounds[lev + 1]]
        ids = ids[counts[ids] == 0]
        if len(ids):
            means[ids] = means[parent[ids]]
    return means


# ------------------------------------------------------------------------------------------
# Smooth display: values interpolated from element vertices
# ------------------------------------------------------------------------------------------
def _leaf_values(hierarchy, leaf_values, leaves):
    leaf_values = np.asarray(leaf_values, np.float64)
    if len(leaf_values) == hierarchy.n:
        return leaf_values[leaves]
    if len(leaf_values) == len(leaves):
        return leaf_values
    raise ValueError("leaf_values must have one row per element or per leaf (Hierarchy.leaves())")


def vertex_values(hierarchy, leaf_values, across_patches: bool = False, tol: float = 1e-7):
    """Per-leaf corner values (n_leaves, 4, C), in ``Hierarchy.leaves()`` order.

    A corner's value is the area-weighted mean of the values of the leaves sharing that corner:
    within a patch corners are keyed by their exact (dyadic) parameter position; with
    ``across_patches`` they are keyed by their 3D position (quantised to ``tol`` times the
    scene size) and normal, so coplanar neighbouring patches blend across their shared edge
    while creases stay sharp.  T-junctions (a coarse leaf next to finer ones) are not
    smoothed: the coarse leaf interpolates its own four corners only.

    ``leaf_values`` is (n_elements, C) indexed by element id, or (n_leaves, C).
    """
    leaves = hierarchy.leaves()
    vals = _leaf_values(hierarchy, leaf_values, leaves)
    vals2 = vals.reshape(len(vals), -1)
    nl = len(leaves)
    if across_patches:
        corners = hierarchy.corners[leaves]                     # (nl, 4, 3)
        size = longest_side(hierarchy.corners[: hierarchy.n])
        q = np.rint(corners / (tol * size)).astype(np.int64)
        nq = np.rint(hierarchy.normal[leaves] * 1e3).astype(np.int64)  # ~0.06 degree bins
        nq = np.broadcast_to(nq[:, None, :], (nl, 4, 3))
        keys = np.concatenate([q, nq], axis=-1).reshape(nl * 4, 6)
    else:
        patch = hierarchy.patch[leaves]
        param = hierarchy.param[leaves]                          # (nl, 4, 2)
        qp = np.rint(param * _PARAM_QUANTUM).astype(np.int64)
        # Triangles (a, b, c, c): the whole v = 1 edge is the apex.
        pc = hierarchy.corners[patch]
        tri = np.all(pc[:, 2] == pc[:, 3], axis=-1)
        top = qp[..., 1] == int(_PARAM_QUANTUM)
        qp[..., 0] = np.where(tri[:, None] & top, 0, qp[..., 0])
        keys = np.concatenate([np.broadcast_to(patch[:, None, None], (nl, 4, 1)), qp],
                              axis=-1).reshape(nl * 4, 3)
    _, inv = np.unique(keys, axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    nk = int(inv.max()) + 1 if len(inv) else 0
    wts = np.repeat(hierarchy.area[leaves], 4)
    wsum = np.bincount(inv, weights=wts, minlength=nk)
    wsum = np.where(wsum > 0, wsum, 1.0)
    out = np.empty((nl * 4, vals2.shape[1]))
    rep = np.repeat(vals2, 4, axis=0)
    for j in range(vals2.shape[1]):
        out[:, j] = (np.bincount(inv, weights=wts * rep[:, j], minlength=nk) / wsum)[inv]
    return out.reshape((nl, 4) + vals.shape[1:])


class CornerInterpolation:
    """Per-texel values (T, C) bilinear in their leaf's four corner values (n_leaves, 4, C):
    the texels' leaves and parameters found once, for any number of value sets."""

    CHUNK = 1 << 16        # texels interpolated at once

    def __init__(self, hierarchy, texel_map: TexelMap, element_ids=None):
        leaves = hierarchy.leaves()
        if element_ids is None:
            element_ids = texel_elements(hierarchy, texel_map)
        pos = np.full(hierarchy.n, -1, np.int64)
        pos[leaves] = np.arange(len(leaves))
        self.leaf = pos[element_ids]
        if np.any(self.leaf < 0):
            raise ValueError("element_ids must be leaves of the hierarchy")
        param = hierarchy.param[element_ids]                      # axis-aligned boxes
        u0, v0 = param[:, 0, 0], param[:, 0, 1]
        s = np.clip((texel_map.u - u0) / (param[:, 2, 0] - u0), 0.0, 1.0)[:, None]
        t = np.clip((texel_map.v - v0) / (param[:, 2, 1] - v0), 0.0, 1.0)[:, None]
        self.weights = ((1 - s) * (1 - t), s * (1 - t), s * t, (1 - s) * t)

    def __call__(self, corner_values):
        cv = np.asarray(corner_values, np.float64)
        cv = cv.reshape(cv.shape[0], 4, -1)
        out = np.empty((len(self.leaf), cv.shape[2]))
        for c0 in range(0, len(out), self.CHUNK):      # no (T, 4, C) copy of the corners
            sl = slice(c0, c0 + self.CHUNK)
            cv2 = cv[self.leaf[sl]]
            out[sl] = sum(w[sl] * cv2[:, i] for i, w in enumerate(self.weights))
        return out.reshape((len(out),) + np.shape(corner_values)[2:])


def interpolate_corner_values(hierarchy, corner_values, texel_map: TexelMap, element_ids=None):
    """Per-texel value (T, C) bilinear in the leaf's four corner values (n_leaves, 4, C)."""
    return CornerInterpolation(hierarchy, texel_map, element_ids)(corner_values)


def vertex_interpolate(hierarchy, leaf_values, texel_map: TexelMap, element_ids=None,
                       across_patches: bool = False, interpolation=None):
    """Per-texel values (T, C) interpolated from element-vertex values (seed 000 footnote:
    smooth display).  Corner values: :func:`vertex_values`; interpolation:
    :func:`interpolate_corner_values` (or ``interpolation``, a CornerInterpolation made
    for the same hierarchy and texels)."""
    corner = vertex_values(hierarchy, leaf_values, across_patches=across_patches)
    if interpolation is not None:
        return interpolation(corner)
    return interpolate_corner_values(hierarchy, corner, texel_map, element_ids)


# ------------------------------------------------------------------------------------------
# Seam padding
# ------------------------------------------------------------------------------------------
def dilate_seams(image, coverage, pixels: int = 4):
    """Fill uncovered texels bordering covered ones with the mean of their covered
    8-neighbours, ``pixels`` rings deep, so bilinear filtering / mip-mapping at UV seams does
    not pull in background.  Covered texels are never modified.

    image (H, W) or (H, W, C); integer images are converted to float32.  Uses OpenCV's
    ``filter2D`` when available (about 20x faster than the numpy fallback on 4k textures).
    Returns (new image, new coverage mask).
    """
    img = np.array(image, dtype=np.result_type(np.asarray(image).dtype, np.float32), copy=True)
    squeeze = img.ndim == 2
    if squeeze:
        img = img[..., None]
    cov = np.asarray(coverage, bool).copy()
    neighbour_sum = _neighbour_sum_cv2 if _cv2() is not None else _neighbour_sum_numpy
    for _ in range(int(pixels)):
        if cov.all() or not cov.any():
            break
        covf = cov.astype(img.dtype)
        cnt = neighbour_sum(covf[..., None])[..., 0]
        new = ~cov & (cnt > 0.5)
        if not new.any():
            break
        acc = neighbour_sum(img * covf[..., None])
        acc /= np.maximum(cnt, 1.0)[..., None]
        np.copyto(img, acc, where=new[..., None])     # boolean fancy indexing is ~5x slower
        cov |= new
    if squeeze:
        img = img[..., 0]
    return img, cov


def _cv2():
    try:
        import cv2  # noqa: PLC0415
    except ImportError:  # pragma: no cover - opencv is a declared dependency
        return None
    return cv2


_KERNEL = np.ones((3, 3), np.float32)
_KERNEL[1, 1] = 0.0


def _neighbour_sum_cv2(a):
    """Sum over the 8 neighbours (zero outside the image) of (H, W, C)."""
    cv2 = _cv2()
    if a.shape[2] <= 4:
        a = np.ascontiguousarray(a)
        return cv2.filter2D(a, -1, _KERNEL, borderType=cv2.BORDER_CONSTANT).reshape(a.shape)
    out = np.empty_like(a)
    for c0 in range(0, a.shape[2], 4):                 # filter2D handles up to 4 channels
        part = np.ascontiguousarray(a[..., c0:c0 + 4])
        res = cv2.filter2D(part, -1, _KERNEL, borderType=cv2.BORDER_CONSTANT)
        out[..., c0:c0 + 4] = res.reshape(part.shape)
    return out


def _neighbour_sum_numpy(a):
    h, w = a.shape[:2]
    pv = np.pad(a, ((1, 1), (1, 1), (0, 0)))
    acc = np.zeros_like(a)
    for dy in (0, 1, 2):
        for dx in (0, 1, 2):
            if dy != 1 or dx != 1:
                acc += pv[dy:dy + h, dx:dx + w]
    return acc


# ------------------------------------------------------------------------------------------
# Neighbours and means
# ------------------------------------------------------------------------------------------

def adjacent_texel_pairs(texel_map: TexelMap, fraction: float = 1.0, seed: int = 0) -> np.ndarray:
    """Index pairs (into the concatenated texel arrays) of 4-adjacent covered texels.  With
    ``fraction`` < 1, each pair is kept with that probability (seeded), image by image, so
    that a photo-resolution map's whole list is never held."""
    out = []
    off = texel_map.offsets
    rng = np.random.default_rng(seed)
    for i, im in enumerate(texel_map.images):
        if len(im) == 0:
            continue
        hh, ww = im.shape
        grid = np.full(hh * ww, -1, np.int64)
        grid[im.texel_index] = off[i] + np.arange(len(im))
        grid = grid.reshape(hh, ww)
        for a, b in ((grid[:, :-1], grid[:, 1:]), (grid[:-1, :], grid[1:, :])):
            a, b = a.ravel(), b.ravel()
            ok = (a >= 0) & (b >= 0)
            if fraction < 1.0:
                ok &= rng.random(len(ok)) < fraction
            out.append(np.stack([a[ok], b[ok]], 1))
    return np.concatenate(out) if out else np.zeros((0, 2), np.int64)


def count_adjacent_texel_pairs(texel_map: TexelMap) -> int:
    """How many pairs :func:`adjacent_texel_pairs` lists (from the coverage masks)."""
    n = 0
    for im in texel_map.images:
        if len(im):
            c = im.coverage
            n += int(np.count_nonzero(c[:, :-1] & c[:, 1:]) + np.count_nonzero(c[:-1] & c[1:]))
    return n


def neighbour_element_pairs(texel_map: TexelMap, element_ids) -> np.ndarray:
    """Unique pairs of distinct elements owning 4-adjacent texels of the same image (so patch
    edges that are continuous in UV count as neighbours, seams do not)."""
    p = adjacent_texel_pairs(texel_map)
    a, b = element_ids[p[:, 0]], element_ids[p[:, 1]]
    ok = a != b
    if not ok.any():
        return np.zeros((0, 2), np.int64)
    return np.unique(np.stack([np.minimum(a[ok], b[ok]), np.maximum(a[ok], b[ok])], 1), axis=0)


def patch_means(texel_map: TexelMap, values, n_patches: int):
    """Mean texel value (p, 3) and texel count (p,) of every patch."""
    if texel_map.n_texels <= MEANS_BLOCK:
        patch = texel_map.patch
        cnt = np.bincount(patch, minlength=n_patches)
        means = np.stack([np.bincount(patch, values[:, c], n_patches) for c in range(3)], 1)
        return means / np.maximum(cnt, 1)[:, None], cnt
    cnt = np.zeros(n_patches, np.int64)
    sums = np.zeros((n_patches, 3))
    off = texel_map.offsets
    for i, im in enumerate(texel_map.images):     # image by image: no whole-map copies
        vals = values[off[i]:off[i + 1]]
        cnt += np.bincount(im.patch, minlength=n_patches)
        for c in range(3):
            sums[:, c] += np.bincount(im.patch, vals[:, c], n_patches)
    return sums / np.maximum(cnt, 1)[:, None], cnt
