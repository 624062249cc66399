"""A coarse proxy of a dense mesh for the radiosity solve (scans of 50k-200k triangles).

Hierarchical radiosity cannot make an element larger than an input face, so on a scanned room
(a dense, irregular, noisy triangle mesh) every one of its 100k faces would be a leaf, with the
links and memory that follow, whatever the preset asks for.  The indirect light does not need
that detail: it varies on the scale of the room, and the per-texel direct light (ray-cast on
the full mesh: core/relight/texel.py) carries the sharp shadows.  So the solve runs on a proxy:

1. the non-emitting faces, welded by position, are decimated by quadric error metrics (seed 003,
   Garland-Heckbert edge collapses; the ``fast_simplification`` wheel, a binding of
   Fast-Quadric-Mesh-Simplification) to about ``faces`` triangles: flat walls become a few large
   triangles that the hierarchy then subdivides where the light asks for it, while edges,
   corners and furniture keep the triangles their shape needs;
2. the lamp patches (emissive meshes, area lights) are kept as they are;
3. every input face is mapped to the proxy triangle closest to its centroid on the same side
   (``locate``), which gives each proxy triangle its reflectance (area-weighted mean) and group,
   and every texel to a proxy triangle and its parameters, where the indirect light is read
   (core/relight/proxy_texels.py).

``Proxy.deviation`` (distance from each input face's centroid to the proxy) is what the proxy
costs geometrically; its cost in light is measured in benchmarks/bench_scan.py against the
Cycles truth of the clean room.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from ..geometry.extent import bounding_diagonal
from ..geometry.patch import quad_area_normal
from ..numerics import nonzero, safe_div
from ..scene import SceneData

CANDIDATES = 12         # nearest sample points whose triangles are tested first
SAMPLES_PER_FACE = 8    # proxy sample points per average proxy triangle
CHUNK = 1 << 14         # points located at once (12-48 candidate triangles each)
PLANAR = np.cos(np.radians(10.0))
PLANE_ANGLE = np.cos(np.radians(5.0))
PLANE_OFFSET = 10.0     # x the roughness: how far from a plane a proxy triangle may lie in it
SMOOTH_FACES = 2.0      # shading normals averaged over this many face sizes
WELD = 1e-7             # vertices closer than this x the scene's size are one vertex


@dataclass
class Proxy:
    scene: SceneData            # proxy triangles (a, b, c, c), then the lamp patches
    of_patch: np.ndarray        # (P,) proxy patch of every input patch
    deviation: np.ndarray       # (P,) distance from each input patch's centroid to the proxy
    input_faces: int            # triangles given to the decimation
    normals: np.ndarray         # (P,) shading normals of the input faces (smooth_normals)
    roughness: float            # robust RMS height of the faces over their neighbourhood's plane
    back_of: np.ndarray         # the proxy triangles whose backs were appended (in order)
    seconds: float = 0.0

    @property
    def n_patches(self):
        return self.scene.n_patches


def _triangles(corners):
    """Input patches as triangles: quads split along a-c, triangles (a, b, c, c) once."""
    tri = corners[:, [0, 1, 2]]
    quad = ~np.all(corners[:, 2] == corners[:, 3], axis=1)
    return np.concatenate([tri, corners[quad][:, [0, 2, 3]]])


def decimate(triangles, faces, scale):
    """Welded vertices (n, 3) and triangles (m, 3) of ``triangles`` (t, 3, 3) decimated to about
    ``faces`` triangles."""
    pts = triangles.reshape(-1, 3)
    key = np.round(pts / (WELD * scale)).astype(np.int64)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    verts = pts[first]
    tris = inverse.reshape(-1, 3)
    tris = tris[(tris[:, 0] != tris[:, 1]) & (tris[:, 1] != tris[:, 2]) & (tris[:, 0] != tris[:, 2])]
    if len(tris) <= faces:
        return verts, tris
    try:
        import fast_simplification  # noqa: PLC0415  (a runtime dependency)
    except ImportError:                          # a platform without its wheel
        return cluster_vertices(verts, tris, faces)
    out_pts, out_tris = fast_simplification.simplify(verts.astype(np.float64), tris.astype(np.int64),
                                                     target_count=int(faces))
    return np.asarray(out_pts, np.float64), np.asarray(out_tris, np.int64)


def cluster_vertices(verts, tris, faces):
    """The fallback decimation (Rossignac-Borrel vertex clustering): vertices merged per cell
    of a grid sized for about ``faces`` triangles, triangles that collapse dropped.  Coarser
    than QEM where the surface bends, about as good on a room's planes."""
    a = verts[tris]
    area = 0.5 * np.linalg.norm(np.cross(a[:, 1] - a[:, 0], a[:, 2] - a[:, 0]), axis=1).sum()
    cell = np.sqrt(2.0 * area / max(faces, 1))
    for _ in range(8):
        key = np.floor((verts - verts.min(axis=0)) / cell).astype(np.int64)
        _, rep, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
        inv = inv.ravel()
        t = inv[tris]
        t = t[(t[:, 0] != t[:, 1]) & (t[:, 1] != t[:, 2]) & (t[:, 0] != t[:, 2])]
        if len(t):                               # one of each set of merged triangles
            t = t[np.sort(np.unique(np.sort(t, axis=1), axis=0, return_index=True)[1])]
        if len(t) <= 1.5 * faces:
            break
        cell *= 1.25
    n = int(inv.max()) + 1
    pos = np.stack([np.bincount(inv, verts[:, c], n) for c in range(3)], 1)
    pos /= np.bincount(inv, minlength=n)[:, None]
    return pos, t


def build_proxy(scene: SceneData, faces: int, back_of=None) -> Proxy:
    """The proxy of ``scene`` with about ``faces`` triangles besides its lamp patches.
    ``back_of``: the faces whose backs core/relight/orient.py appended after the others (lit
    on both sides); the proxy triangles that stand mostly for them get backs too."""
    import time  # noqa: PLC0415
    t0 = time.perf_counter()
    back_of = np.zeros(0, np.int64) if back_of is None else np.asarray(back_of, np.int64)
    fronts = scene.n_patches - len(back_of)
    scale = bounding_diagonal(scene.corners)
    lamp = scene.lamp >= 0
    surf = np.flatnonzero(~lamp[:fronts])
    tris_in = _triangles(scene.corners[surf])
    verts, tris = decimate(tris_in, max(faces - int(lamp.sum()), 4), scale)
    tri = verts[tris]
    corners = np.concatenate([tri, tri[:, 2:3]], axis=1)
    keep = quad_area_normal(corners)[0] > 0
    corners = corners[keep]
    n = len(corners)
    lamps = np.flatnonzero(lamp)
    proxy = SceneData(
        np.concatenate([corners, scene.corners[lamps]]),
        rho=np.concatenate([np.full((n, 3), 0.5), scene.rho[lamps]]),
        emission=np.concatenate([np.zeros((n, 3)), scene.emission[lamps]]),
        lamp=np.concatenate([np.full(n, -1), scene.lamp[lamps]]),
        lamp_names=list(scene.lamp_names),
        occluder=np.concatenate([np.ones(n, bool), scene.occluder[lamps]]),
        group=np.concatenate([np.zeros(n, np.int32), scene.group[lamps]]),
        viewpoint=scene.viewpoint, lamp_intensity=scene.lamp_intensity, lights=scene.lights)
    # Input patches onto the proxy: lamps onto their copies (matched by position), the other
    # faces onto the closest proxy triangle that faces the same way.
    area, normal = scene.area_normal()
    centroid = scene.corners.mean(axis=1)
    of_patch = np.empty(scene.n_patches, np.int64)
    deviation = np.zeros(scene.n_patches)
    on_surface = proxy.lamp < 0
    of_patch[surf], _, _, deviation[surf] = locate(proxy, centroid[surf], normal[surf],
                                                   allowed=on_surface)
    if len(lamps):
        copies = np.flatnonzero(proxy.lamp >= 0)
        tree = cKDTree(proxy.corners[copies].mean(axis=1))
        of_patch[lamps] = copies[tree.query(centroid[lamps])[1]]
    proxy_back_of = np.zeros(0, np.int64)
    if len(back_of):
        proxy, proxy_back_of = _with_backs(proxy, of_patch, area_front=scene.area_normal()[0],
                                           back_of=back_of, surf=surf)
        back_copy = np.full(proxy.n_patches, -1)
        back_copy[proxy_back_of] = np.arange(len(proxy_back_of)) + proxy.n_patches \
            - len(proxy_back_of)
        front_tri = of_patch[back_of]
        of_patch[fronts:] = np.where(back_copy[front_tri] >= 0, back_copy[front_tri], front_tri)
        deviation[fronts:] = deviation[back_of]
        on_surface = proxy.lamp < 0
    # Reflectance: area-weighted mean of the input faces each proxy triangle stands for;
    # group: the one covering most of its area (the panel names surfaces by group).
    p = proxy.n_patches
    w = np.bincount(of_patch, area, p)
    rho = np.stack([np.bincount(of_patch, area * scene.rho[:, c], p) for c in range(3)], 1)
    fallback = safe_div(area @ scene.rho[:, :], area.sum())
    rho = np.where(w[:, None] > 0, rho / nonzero(w)[:, None], fallback)
    rho[~on_surface] = proxy.rho[~on_surface]
    groups, g_inv = np.unique(scene.group, return_inverse=True)
    share = np.zeros((p, len(groups)))
    np.add.at(share, (of_patch, g_inv), area)
    group = np.where(on_surface, groups[share.argmax(axis=1)], proxy.group).astype(np.int32)
    proxy = proxy.with_rho(rho)
    proxy.group = group
    # Shading normals over about two faces around each (the scan's noise averaged out).
    edge = np.sqrt(2.0 * np.median(area[surf])) if len(surf) else 0.0
    normals, roughness = smooth_normals(scene, SMOOTH_FACES * edge) if edge > 0 else (normal, 0.0)
    # Where the faces lie along a plane (a wall, a table top: within PLANAR of it), the plane's
    # normal, over many more faces than the neighbourhood's.
    sums = np.zeros((p, 3))
    np.add.at(sums, of_patch, area[:, None] * normal)
    plane = plane_normals(sums, proxy.corners[:, :3].mean(axis=1),
                          max(PLANE_OFFSET * roughness, WELD * scale))
    planar = np.einsum("ij,ij->i", normals, plane[of_patch]) > PLANAR
    normals = np.where(planar[:, None], plane[of_patch], normals)
    return Proxy(proxy, of_patch, deviation, len(tris_in), normals, roughness,
                 proxy_back_of, time.perf_counter() - t0)


def plane_normals(sums, centres, tolerance):
    """Unit normals (p, 3) of the planes the proxy triangles lie in.  ``sums``: each triangle's
    area-weighted sum of its input faces' normals; triangles whose mean normals agree within
    PLANE_ANGLE and whose ``centres`` lie within ``tolerance`` of one plane (seeded by the
    largest triangles first) share that plane's normal, the mean over all their faces.  One
    triangle's mean is not enough on a scan: 2 mm of noise tilts a 1.5 cm face by ~8 degrees,
    and the ~17-70 faces of a proxy triangle leave its mean 1-2 degrees off, a step in the
    direct light at every triangle's edge (4 % at 70 degrees' incidence) that the shadow-edge
    fit read as indirect light: family room 0's scan on a 6,000-triangle proxy fitted rho^ 0.56
    (the clean room 0.45) and relit with a lamp off at 1.10 CIEDE2000 (0.58 with the planes'
    normals).  A triangle that no plane takes keeps its own mean."""
    weight = np.linalg.norm(sums, axis=1)
    unit = sums / nonzero(weight)[:, None]
    label = np.where(weight > 0, -1, -2)
    for i in np.argsort(-weight, kind="stable"):
        if label[i] != -1:
            continue
        free = np.flatnonzero(label == -1)
        n = unit[i]
        near = (unit[free] @ n > PLANE_ANGLE) & (np.abs((centres[free] - centres[i]) @ n) < tolerance)
        label[free[near]] = i
    out = unit.copy()
    inside = np.flatnonzero(label >= 0)
    total = np.zeros_like(sums)
    np.add.at(total, label[inside], sums[inside])
    total /= nonzero(np.linalg.norm(total, axis=1))[:, None]
    out[inside] = total[label[inside]]
    return out


def _with_backs(proxy: SceneData, of_patch, area_front, back_of, surf):
    """``proxy`` with a back (a reversed copy that reflects but does not block, as orient.py
    makes them) appended for every triangle whose faces are mostly lit on both sides, and the
    triangles that got one."""
    two = np.zeros(len(area_front), bool)
    two[back_of] = True
    p = proxy.n_patches
    total = np.bincount(of_patch[surf], area_front[surf], p)
    both = np.bincount(of_patch[surf], area_front[surf] * two[surf], p)
    front = np.flatnonzero((proxy.lamp < 0) & (both > 0.5 * np.maximum(total, 1e-300)))
    new = object.__new__(SceneData)
    new.__dict__.update(proxy.__dict__)
    c = proxy.corners[front]
    new.corners = np.concatenate([proxy.corners, c[:, [0, 2, 1, 1]]])     # (a, c, b, b)
    new.rho = np.concatenate([proxy.rho, proxy.rho[front]])
    new.emission = np.concatenate([proxy.emission, np.zeros((len(front), 3))])
    new.lamp = np.concatenate([proxy.lamp, np.full(len(front), -1, proxy.lamp.dtype)])
    new.occluder = np.concatenate([proxy.occluder, np.zeros(len(front), bool)])
    new.group = np.concatenate([proxy.group, proxy.group[front]])
    new.virtual = np.concatenate([proxy.virtual, np.zeros(len(front), bool)])
    return new, front


def closest_on_triangles(p, a, b, c):
    """Closest points of triangles (a, b, c) to points p, as barycentric (l_a, l_b, l_c)
    (Ericson, Real-Time Collision Detection 5.1.5, vectorised over regions)."""
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = np.einsum("ij,ij->i", ab, ap), np.einsum("ij,ij->i", ac, ap)
    bp = p - b
    d3, d4 = np.einsum("ij,ij->i", ab, bp), np.einsum("ij,ij->i", ac, bp)
    cp = p - c
    d5, d6 = np.einsum("ij,ij->i", ab, cp), np.einsum("ij,ij->i", ac, cp)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    with np.errstate(invalid="ignore", divide="ignore"):
        denom = va + vb + vc
        lb, lc = vb / denom, vc / denom                          # inside the face
        t_ab = d1 / (d1 - d3)
        t_ac = d2 / (d2 - d6)
        t_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
    la = 1.0 - lb - lc
    out = np.stack([la, lb, lc], 1)
    regions = [
        ((d1 <= 0) & (d2 <= 0), (1, 0, 0), None),
        ((d3 >= 0) & (d4 <= d3), (0, 1, 0), None),
        ((d6 >= 0) & (d5 <= d6), (0, 0, 1), None),
        ((vc <= 0) & (d1 >= 0) & (d3 <= 0), None, ("ab", t_ab)),
        ((vb <= 0) & (d2 >= 0) & (d6 <= 0), None, ("ac", t_ac)),
        ((va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0), None, ("bc", t_bc)),
    ]
    done = np.zeros(len(p), bool)
    for mask, vertex, edge in regions:
        m = mask & ~done
        if vertex is not None:
            out[m] = vertex
        else:
            name, t = edge
            t = t[m]
            zero = np.zeros_like(t)
            out[m] = {"ab": lambda: np.stack([1 - t, t, zero], 1),
                      "ac": lambda: np.stack([1 - t, zero, t], 1),
                      "bc": lambda: np.stack([zero, 1 - t, t], 1)}[name]()
        done |= m
    return np.nan_to_num(out, nan=1.0 / 3.0)


def _samples(proxy: SceneData, ids):
    """Points on the triangles ``ids`` such that every point of a triangle is within ``h`` of
    one of its own (a barycentric grid of edge at most h; h from about SAMPLES_PER_FACE points
    per average triangle), the triangle of each, and h."""
    area = proxy.area_normal()[0][ids]
    h = float(np.sqrt(area.sum() / (SAMPLES_PER_FACE * max(len(ids), 1)))) or 1.0
    c = proxy.corners[ids]
    longest = np.max([np.linalg.norm(c[:, i] - c[:, (i + 1) % 3], axis=1) for i in range(3)], 0)
    m = np.maximum(np.ceil(longest / h), 1).astype(np.int64)
    pts, tri = [], []
    for mm in np.unique(m):
        sel = np.flatnonzero(m == mm)
        i, j = np.meshgrid(np.arange(mm + 1), np.arange(mm + 1), indexing="ij")
        keep = i + j <= mm
        wb, wc = (i[keep] / mm)[None, :, None], (j[keep] / mm)[None, :, None]
        cs = c[sel]
        p = (1 - wb - wc) * cs[:, None, 0] + wb * cs[:, None, 1] + wc * cs[:, None, 2]
        pts.append(p.reshape(-1, 3))
        tri.append(np.repeat(ids[sel], keep.sum()))
    return np.concatenate(pts), np.concatenate(tri), h


def _nearest_on(proxy, tri_normal, p, nrm, cand):
    """For points p (m, 3) with normals and candidate triangles (m, k): the best candidate
    (the closest facing one, else the closest), its barycentrics and distance."""
    m, k = cand.shape
    rep = np.repeat(p, k, axis=0)
    tri = proxy.corners[cand.ravel()]
    bary = closest_on_triangles(rep, tri[:, 0], tri[:, 1], tri[:, 2])
    q = np.einsum("ij,ijk->ik", bary, tri[:, :3])
    d = np.linalg.norm(rep - q, axis=1).reshape(m, k)
    facing = np.einsum("ij,ij->i", np.repeat(nrm, k, axis=0),
                       tri_normal[cand.ravel()]).reshape(m, k) > 0.0
    score = d + np.where(facing, 0.0, np.inf)
    none = ~np.isfinite(score).any(axis=1)
    score[none] = d[none]
    best = np.argmin(score, axis=1)
    rows = np.arange(m)
    return cand[rows, best], bary[rows * k + best], d[rows, best], score[rows, best]


def locate(proxy: SceneData, points, normals, allowed=None):
    """Proxy triangle, Duffy parameters (u, v) and distance of every point: the closest point
    on the proxy's triangles that face the same way as its normal (any triangle when none
    near it does).  Exact: the triangles tested are those of every sample point within the
    best distance found + h (every triangle has a sample within h of each of its points)."""
    find = finder(proxy, allowed)
    n_pts = len(points)
    patch = np.empty(n_pts, np.int64)
    u, v, dist = np.empty(n_pts), np.empty(n_pts), np.empty(n_pts)
    for c0 in range(0, n_pts, CHUNK):
        sl = slice(c0, c0 + CHUNK)
        patch[sl], u[sl], v[sl], dist[sl] = find(points[sl], normals[sl])
    return patch, u, v, dist


def finder(proxy: SceneData, allowed=None):
    """:func:`locate` for one chunk of points (at most CHUNK), the proxy's samples and their
    tree built once."""
    ids = np.flatnonzero(proxy.lamp < 0 if allowed is None else allowed)
    spts, stri, h = _samples(proxy, ids)
    tree = cKDTree(spts)
    tri_normal = proxy.area_normal()[1]

    def find(points, normals):
        p = np.asarray(points, np.float64)
        nrm = np.asarray(normals, np.float64)
        todo = np.arange(len(p))
        best_t = np.empty(len(p), np.int64)
        best_b = np.empty((len(p), 3))
        best_d = np.empty(len(p))
        k = min(CANDIDATES, len(spts))
        while len(todo):
            # the points still to look at with 4x the candidates are taken a few at a time:
            # no round tests more pairs than the first (a texel map's points on a proxy:
            # 260 MB for one array of 16k points x 768 candidates)
            step = max(1, CHUNK * CANDIDATES // k)
            more = []
            for part in np.array_split(todo, -(-len(todo) // step)):
                ds, nearest = tree.query(p[part], k=k)
                ds, nearest = ds.reshape(len(part), k), nearest.reshape(len(part), k)
                t, b, d, score = _nearest_on(proxy, tri_normal, p[part], nrm[part],
                                             stri[nearest])
                best_t[part], best_b[part], best_d[part] = t, b, d
                # a nearer facing triangle can only have samples within score + h: all seen?
                more.append(part[(ds[:, -1] <= np.minimum(score, ds[:, 0] + 2 * h) + h)
                                 & (k < len(spts))])
            todo = np.concatenate(more)
            k = min(4 * k, len(spts))
        lb, lc = best_b[:, 1], best_b[:, 2]
        v = np.clip(lc, 0.0, 1.0)
        u = np.clip(np.where(v < 1.0 - 1e-12, safe_div(lb, 1.0 - v), 0.5), 0.0, 1.0)
        return best_t, u, v, best_d
    return find


def smooth_normals(scene: SceneData, radius: float, crease: float = 0.5):
    """Per-face shading normals (p, 3): the area-weighted mean normal of the faces whose
    centroids lie within ``radius`` and whose normals are within acos(``crease``) of the face's
    own; and the surface's roughness (see below).  A scan's faces carry its noise (a 2 mm bump tilts a 4 cm triangle by ~6 degrees, and
    the light on it by up to ~20 % at grazing incidence), the photographed surface does not."""
    area, normal = scene.area_normal()
    centroid = scene.corners.mean(axis=1)
    tree = cKDTree(centroid)
    pairs = tree.query_pairs(radius, output_type="ndarray")
    i, j = pairs[:, 0], pairs[:, 1]
    ok = np.einsum("ij,ij->i", normal[i], normal[j]) > crease
    i, j = i[ok], j[ok]
    acc = area[:, None] * normal
    np.add.at(acc, i, area[j, None] * normal[j])
    np.add.at(acc, j, area[i, None] * normal[i])
    smooth = acc / nonzero(np.linalg.norm(acc, axis=1))[:, None]
    # Roughness: the height of the centroids over the plane of their neighbourhood (its mean
    # point, the smoothed normal).
    mean = area[:, None] * centroid
    wsum = area.copy()
    np.add.at(mean, i, area[j, None] * centroid[j])
    np.add.at(mean, j, area[i, None] * centroid[i])
    np.add.at(wsum, i, area[j])
    np.add.at(wsum, j, area[i])
    mean /= nonzero(wsum)[:, None]
    height = np.einsum("ij,ij->i", centroid - mean, smooth)
    # robust (1.4826 x the median absolute height): a neighbourhood that takes in a parallel
    # surface nearby (a shelf over a table, a frame on a wall) is no bump of the surface
    roughness = float(1.4826 * np.median(np.abs(height))) if len(height) else 0.0
    return smooth, roughness
