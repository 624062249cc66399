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

# Tolerance (in patch parameter units) for a texel centre lying exactly on a patch edge.
INSIDE_TOLERANCE = 1e-9
# Candidate (patch, texel) pairs processed at once; bounds peak memory to a few hundred MB.
CHUNK_PAIRS = 1 << 18
# Parameter quantisation used to identify shared element corners (params are dyadic).
_PARAM_QUANTUM = float(1 << 30)


# ------------------------------------------------------------------------------------------
# Texel map
# ------------------------------------------------------------------------------------------
@dataclass
class ImageTexels:
    """The covered texels of one image.

    shape        (H, W)
    texel_index  (t,) int64    flat texel index ``y * W + x``, increasing
    patch        (t,) int64    owning patch
    u, v         (t,) float64  the patch's bilinear parameters at the texel centre
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

    def __getitem__(self, k) -> ImageTexels:
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


# ------------------------------------------------------------------------------------------
# Inverse maps
# ------------------------------------------------------------------------------------------
def _cross(x, y):
    return x[..., 0] * y[..., 1] - x[..., 1] * y[..., 0]


def inverse_bilinear(corners: np.ndarray, p: np.ndarray, newton: int = 1):
    """Parameters (u, v) with ``bilinear(corners, u, v) == p`` for 2D quads.

    corners (n, 4, 2), p (n, 2).  Closed form (quadratic in v, numerically stable roots; the
    root closest to the unit square is kept, so either orientation works), then ``newton``
    Newton steps to polish to machine precision.  Returns u, v and a ``valid`` mask (real root).
    """
    a, b, c, d = (corners[:, i, :] for i in range(4))
    e = b - a
    f = d - a
    g = a - b + c - d
    h = p - a
    k2 = _cross(g, f)
    k1 = _cross(e, f) + _cross(h, g)
    k0 = _cross(h, e)
    disc = k1 * k1 - 4.0 * k0 * k2
    scale = np.maximum(np.abs(k1) * np.abs(k1), 1e-300)
    valid = disc >= -1e-12 * scale
    w = np.sqrt(np.maximum(disc, 0.0))
    q = -0.5 * (k1 + np.where(k1 >= 0, w, -w))
    with np.errstate(divide="ignore", invalid="ignore"):
        v1 = np.where(q != 0, k0 / np.where(q != 0, q, 1.0), 0.0)   # the root that survives k2 -> 0
        v2 = np.where(k2 != 0, q / np.where(k2 != 0, k2, 1.0), np.inf)
    dist1 = np.abs(v1 - 0.5)
    dist2 = np.where(np.isfinite(v2), np.abs(v2 - 0.5), np.inf)
    v = np.where(dist2 < dist1, v2, v1)
    v = np.where(np.isfinite(v), v, 0.0)
    u = _solve_u(e, f, g, h, v)
    for _ in range(newton):
        u, v = _newton(a, e, f, g, p, u, v)
    return u, v, valid


def _solve_u(e, f, g, h, v):
    """u from h = u (e + g v) + v f, least squares over both coordinates (rotation-safe)."""
    den = e + g * v[:, None]
    num = h - f * v[:, None]
    dd = np.einsum("ij,ij->i", den, den)
    return np.einsum("ij,ij->i", num, den) / np.maximum(dd, 1e-300)


def _newton(a, e, f, g, p, u, v):
    r = a + e * u[:, None] + f * v[:, None] + g * (u * v)[:, None] - p
    ju = e + g * v[:, None]
    jv = f + g * u[:, None]
    det = _cross(ju, jv)
    ok = np.abs(det) > 1e-300
    sdet = np.where(ok, det, 1.0)
    du = (r[:, 0] * jv[:, 1] - r[:, 1] * jv[:, 0]) / sdet
    dv = (ju[:, 0] * r[:, 1] - ju[:, 1] * r[:, 0]) / sdet
    return np.where(ok, u - du, u), np.where(ok, v - dv, v)


def inverse_triangle(corners: np.ndarray, p: np.ndarray):
    """(u, v) of the Duffy map of triangles (a, b, c, c) from barycentric coordinates.

    ``P(u, v) = (1-u)(1-v) a + u (1-v) b + v c`` so ``v = lambda_c`` and
    ``u = lambda_b / (1 - v)`` (``u = 1/2`` at the apex).  Also returns the smallest barycentric
    coordinate (>= 0 inside).
    """
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    area2 = _cross(b - a, c - a)
    sarea = np.where(area2 != 0, area2, 1.0)
    lb = _cross(p - a, c - a) / sarea
    lc = _cross(b - a, p - a) / sarea
    la = 1.0 - lb - lc
    v = lc
    one_v = 1.0 - v
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.where(one_v > 1e-12, lb / np.where(one_v > 1e-12, one_v, 1.0), 0.5)
    margin = np.minimum(np.minimum(la, lb), lc)
    margin = np.where(area2 != 0, margin, -np.inf)
    return u, v, margin


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


def _rasterize_image(uv, ids, h, w, chunk_pairs) -> ImageTexels:
    n = h * w
    best = np.full(n, -np.inf)
    owner = np.full(n, -1, np.int64)
    best_u = np.zeros(n)
    best_v = np.zeros(n)
    n_hits = np.zeros(n, np.int32)
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
        count = nx * ny
        coef = _patch_coefficients(pts, uv_patch_is_triangle(uv))
        live = np.flatnonzero(count > 0)
        # Chunk boundaries over patches so that each chunk expands to <= chunk_pairs pairs
        # (a single huge patch makes its own chunk).
        csum = np.cumsum(count[live])
        starts = [0]
        while starts[-1] < len(live):
            base = csum[starts[-1] - 1] if starts[-1] else 0
            end = int(np.searchsorted(csum, base + chunk_pairs, side="right"))
            starts.append(max(end, starts[-1] + 1))
        for s0, s1 in zip(starts[:-1], starts[1:]):
            sel = live[s0:s1]
            cnt = count[sel]
            pid = np.repeat(sel, cnt)
            first = np.cumsum(cnt) - cnt
            off = np.arange(int(cnt.sum()), dtype=np.int64) - np.repeat(first, cnt)
            oy, ox = np.divmod(off, np.repeat(nx[sel], cnt))
            x = x0[pid] + ox
            y = y0[pid] + oy
            u, v, margin = _invert(coef, pid, x.astype(np.float64), y.astype(np.float64))
            inside = margin >= -INSIDE_TOLERANCE
            if not inside.any():
                continue
            texel = (y * w + x)[inside]
            pid, u, v, margin = pid[inside], u[inside], v[inside], margin[inside]
            n_hits += np.bincount(texel, weights=margin > INSIDE_TOLERANCE, minlength=n).astype(np.int32)
            # Keep the best candidate per texel within the chunk, then merge with the running best.
            order = np.lexsort((margin, texel))
            ts = texel[order]
            last = np.ones(len(ts), bool)
            last[:-1] = ts[1:] != ts[:-1]
            pick = order[last]
            t = texel[pick]
            better = margin[pick] > best[t]
            t = t[better]
            pick = pick[better]
            best[t] = margin[pick]
            owner[t] = ids[pid[pick]]
            best_u[t] = u[pick]
            best_v[t] = v[pick]
    texel_index = np.flatnonzero(owner >= 0)
    coverage = (owner >= 0).reshape(h, w)
    return ImageTexels(
        shape=(h, w), texel_index=texel_index, patch=owner[texel_index],
        u=np.clip(best_u[texel_index], 0.0, 1.0), v=np.clip(best_v[texel_index], 0.0, 1.0),
        coverage=coverage, n_overlap=int(np.count_nonzero(n_hits > 1)))


def _patch_coefficients(pts, tri):
    """Per-patch constants of the inverse maps (texel-space corners pts (m, 4, 2))."""
    a, b, c, d = (pts[:, i, :] for i in range(4))
    e = b - a
    f = d - a
    g = a - b + c - d
    # Triangles: barycentric constants (c - a) and the doubled signed area.
    ca = c - a
    area2 = _cross(e, ca)
    return dict(a=a, e=e, f=f, g=g, k2=_cross(g, f), kef=_cross(e, f), ca=ca, area2=area2, tri=tri)


def _invert(coef, pid, x, y):
    """Inverse map of candidates (patch pid, texel-space point (x, y)); margin >= 0 inside."""
    u = np.empty(len(pid))
    v = np.empty(len(pid))
    margin = np.empty(len(pid))
    tri = coef["tri"][pid]
    all_quads = not tri.any()
    qi = slice(None) if all_quads else np.flatnonzero(~tri)
    if all_quads or len(qi):
        pq = pid[qi]
        px, py = x[qi], y[qi]
        ax, ay = coef["a"][pq].T
        ex, ey = coef["e"][pq].T
        fx, fy = coef["f"][pq].T
        gx, gy = coef["g"][pq].T
        hx = px - ax
        hy = py - ay
        k2 = coef["k2"][pq]
        k1 = coef["kef"][pq] + hx * gy - hy * gx
        k0 = hx * ey - hy * ex
        disc = k1 * k1 - 4.0 * k0 * k2
        valid = disc >= -1e-12 * np.maximum(k1 * k1, 1e-300)
        w = np.sqrt(np.maximum(disc, 0.0))
        q = -0.5 * (k1 + np.copysign(w, k1))
        qnz = q != 0
        v1 = np.where(qnz, k0 / np.where(qnz, q, 1.0), 0.0)     # the root that survives k2 -> 0
        knz = k2 != 0
        v2 = np.where(knz, q / np.where(knz, k2, 1.0), np.inf)
        vq = np.where(np.abs(v2 - 0.5) < np.abs(v1 - 0.5), v2, v1)
        # u from h = u (e + g v) + v f, least squares over both coordinates (rotation-safe).
        dx = ex + gx * vq
        dy = ey + gy * vq
        uq = ((hx - fx * vq) * dx + (hy - fy * vq) * dy) / np.maximum(dx * dx + dy * dy, 1e-300)
        # One Newton step polishes the closed form to machine precision.
        rx = ex * uq + fx * vq + gx * uq * vq - hx
        ry = ey * uq + fy * vq + gy * uq * vq - hy
        jux, juy = dx, dy
        jvx = fx + gx * uq
        jvy = fy + gy * uq
        det = jux * jvy - juy * jvx
        ok = np.abs(det) > 1e-300
        sdet = np.where(ok, det, 1.0)
        uq = np.where(ok, uq - (rx * jvy - ry * jvx) / sdet, uq)
        vq = np.where(ok, vq - (jux * ry - juy * rx) / sdet, vq)
        m = np.minimum(np.minimum(uq, 1.0 - uq), np.minimum(vq, 1.0 - vq))
        u[qi], v[qi], margin[qi] = uq, vq, np.where(valid, m, -np.inf)
    if not all_quads:
        ti = np.flatnonzero(tri)
        if len(ti):
            pt = pid[ti]
            ax, ay = coef["a"][pt].T
            ex, ey = coef["e"][pt].T
            cx, cy = coef["ca"][pt].T
            area2 = coef["area2"][pt]
            hx = x[ti] - ax
            hy = y[ti] - ay
            nz = area2 != 0
            sarea = np.where(nz, area2, 1.0)
            lb = (hx * cy - hy * cx) / sarea
            lc = (ex * hy - ey * hx) / sarea
            la = 1.0 - lb - lc
            one_v = 1.0 - lc
            big = one_v > 1e-12
            u[ti] = np.where(big, lb / np.where(big, one_v, 1.0), 0.5)
            v[ti] = lc
            margin[ti] = np.where(nz, np.minimum(np.minimum(la, lb), lc), -np.inf)
    return u, v, margin


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
    counts = np.bincount(element_ids, minlength=n_elements).astype(np.float64)
    sums = np.stack([np.bincount(element_ids, weights=values2[:, j], minlength=n_elements)
                     for j in range(values2.shape[1])], axis=-1)
    if hierarchy is not None:
        sums, counts = _pull_up_sums(hierarchy, sums, counts)
    with np.errstate(invalid="ignore", divide="ignore"):
        means = sums / counts[:, None]
    means[counts == 0] = np.nan
    if hierarchy is not None:
        means = _push_down_missing(hierarchy, means, counts)
    return means.reshape((n_elements,) + values.shape[1:]), counts.astype(np.int64)


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
        allc = hierarchy.corners[: hierarchy.n].reshape(-1, 3)
        size = max(float(np.ptp(allc, axis=0).max()) if len(allc) else 1.0, 1e-300)
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


def interpolate_corner_values(hierarchy, corner_values, texel_map: TexelMap, element_ids=None):
    """Per-texel value (T, C) bilinear in the leaf's four corner values (n_leaves, 4, C)."""
    leaves = hierarchy.leaves()
    if element_ids is None:
        element_ids = texel_elements(hierarchy, texel_map)
    pos = np.full(hierarchy.n, -1, np.int64)
    pos[leaves] = np.arange(len(leaves))
    lp = pos[element_ids]
    if np.any(lp < 0):
        raise ValueError("element_ids must be leaves of the hierarchy")
    param = hierarchy.param[element_ids]                          # axis-aligned boxes
    u0, v0 = param[:, 0, 0], param[:, 0, 1]
    du = param[:, 2, 0] - u0
    dv = param[:, 2, 1] - v0
    s = np.clip((texel_map.u - u0) / du, 0.0, 1.0)[:, None]
    t = np.clip((texel_map.v - v0) / dv, 0.0, 1.0)[:, None]
    cv = np.asarray(corner_values, np.float64)
    cv2 = cv.reshape(cv.shape[0], 4, -1)[lp]
    a, b, c, d = cv2[:, 0], cv2[:, 1], cv2[:, 2], cv2[:, 3]
    out = (1 - s) * (1 - t) * a + s * (1 - t) * b + s * t * c + (1 - s) * t * d
    return out.reshape((len(out),) + cv.shape[2:])


def vertex_interpolate(hierarchy, leaf_values, texel_map: TexelMap, element_ids=None,
                       across_patches: bool = False):
    """Per-texel values (T, C) interpolated from element-vertex values (seed 000 footnote:
    smooth display).  Corner values: :func:`vertex_values`; interpolation:
    :func:`interpolate_corner_values`."""
    corner = vertex_values(hierarchy, leaf_values, across_patches=across_patches)
    return interpolate_corner_values(hierarchy, corner, texel_map, element_ids)


# ------------------------------------------------------------------------------------------
# Seam padding
# ------------------------------------------------------------------------------------------
def dilate_seams(image, coverage, pixels: int = 4):
    """Fill uncovered texels bordering covered ones with the mean of their covered
    8-neighbours, ``pixels`` rings deep, so bilinear filtering / mip-mapping at UV seams does
    not pull in background.  Covered texels are never modified.

    Returns (new image, new coverage mask).
    """
    img = np.array(image, dtype=np.result_type(np.asarray(image).dtype, np.float32), copy=True)
    squeeze = img.ndim == 2
    if squeeze:
        img = img[..., None]
    cov = np.asarray(coverage, bool).copy()
    h, w = cov.shape
    for _ in range(int(pixels)):
        if cov.all() or not cov.any():
            break
        val = np.where(cov[..., None], img, 0)
        pv = np.pad(val, ((1, 1), (1, 1), (0, 0)))
        pc = np.pad(cov.astype(np.float32), 1)
        acc = np.zeros_like(img, dtype=np.float64)
        cnt = np.zeros((h, w), np.float64)
        for dy in (0, 1, 2):
            for dx in (0, 1, 2):
                if dy == 1 and dx == 1:
                    continue
                acc += pv[dy:dy + h, dx:dx + w]
                cnt += pc[dy:dy + h, dx:dx + w]
        new = ~cov & (cnt > 0)
        if not new.any():
            break
        img[new] = (acc[new] / cnt[new][:, None]).astype(img.dtype)
        cov = cov | new
    if squeeze:
        img = img[..., 0]
    return img, cov
