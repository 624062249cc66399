"""Independent truths for the AR tests and benchmark (no code of core/ar): brute-force
integration of an environment map over the hemisphere, and shadow factors ray traced through
an occluder (Embree through a mesh, or analytic spheres) under the same map."""
from __future__ import annotations

import os

import numpy as np

os.environ.setdefault("OPENCV_IO_ENABLE_OPENEXR", "1")   # before cv2 is first imported

LUM = np.array([0.2126, 0.7152, 0.0722])


def bundled_hdris():
    """{name: path} of the studio-light HDRIs shipped in the bpy wheel (found without bpy)."""
    import glob
    import importlib.util
    spec = importlib.util.find_spec("bpy")
    if spec is None or not spec.submodule_search_locations:
        return {}
    root = list(spec.submodule_search_locations)[0]
    files = sorted(glob.glob(os.path.join(root, "*", "datafiles", "studiolights", "world",
                                          "*.exr")))
    return {os.path.splitext(os.path.basename(f))[0]: f for f in files}


def load_exr(path):
    """(H, W, 3) float64 linear RGB, top row first, as stored (negatives kept)."""
    import cv2
    img = cv2.imread(path, cv2.IMREAD_UNCHANGED)
    if img is None:
        raise OSError(f"cannot read {path}")
    return img[..., 2::-1].astype(np.float64)


def fibonacci(n):
    """(n, 3) unit vectors of a Fibonacci lattice: nearly uniform normals."""
    k = np.arange(n) + 0.5
    z = 1 - 2 * k / n
    ph = np.pi * (1 + 5 ** 0.5) * k
    return np.stack([np.sqrt(1 - z * z) * np.cos(ph), np.sqrt(1 - z * z) * np.sin(ph), z], 1)


def pixel_directions(h, w):
    """(h, w, 3) unit directions of the pixel centres, Blender's equirect convention, top row
    first (written here again, independently of core.ar.envmap)."""
    j = (np.arange(w) + 0.5) / w
    i = (np.arange(h) + 0.5) / h
    lon = (0.5 - j) * 2 * np.pi                       # u = 0.5 - atan2(y, x) / 2 pi
    lat = (0.5 - i) * np.pi                           # row 0 at the zenith
    LON, LAT = np.meshgrid(lon, lat)
    return np.stack([np.cos(LAT) * np.cos(LON), np.cos(LAT) * np.sin(LON), np.sin(LAT)], -1)


def pixel_solid_angles(h, w):
    edges = (0.5 - np.arange(h + 1) / h) * np.pi
    return 2 * np.pi / w * (np.sin(edges[:-1]) - np.sin(edges[1:]))


def brute_irradiance(env, normals, chunk=64):
    """(m, 3) integral of L max(w.n, 0) dw over every pixel of ``env`` (H, W, 3)."""
    h, w = env.shape[:2]
    d = pixel_directions(h, w).reshape(-1, 3).astype(np.float32)
    lw = (np.maximum(env, 0) * pixel_solid_angles(h, w)[:, None, None]).reshape(-1, 3)
    lw = lw.astype(np.float32)
    normals = np.atleast_2d(normals)
    out = np.empty((len(normals), 3))
    for a in range(0, len(normals), chunk):
        cos = np.maximum(normals[a:a + chunk].astype(np.float32) @ d.T, 0)
        out[a:a + chunk] = cos @ lw
    return out


class SphereOccluder:
    """segments_occluded for a union of analytic spheres (the truth for sphere sets)."""

    def __init__(self, centres, radii):
        self.c = np.asarray(centres, float).reshape(-1, 3)
        self.r = np.asarray(radii, float).ravel()

    def segments_occluded(self, origins, ends, eps=1e-6):
        d = ends - origins
        length = np.linalg.norm(d, axis=1)
        u = d / length[:, None]
        hit = np.zeros(len(origins), bool)
        for c, r in zip(self.c, self.r):
            oc = c - origins
            b = np.einsum("ij,ij->i", u, oc)
            disc = b * b - (np.einsum("ij,ij->i", oc, oc) - r * r)
            s = np.sqrt(np.maximum(disc, 0))
            hit |= (disc >= 0) & (b + s > eps * length) & (b - s < (1 - eps) * length)
        return hit


def traced_shadow_factor(occluder, points, normal, env, rays=1024, seed=0, distance=100.0,
                         lift=1e-5, chunk=1 << 20):
    """(n,) luminance shadow factor of receivers ``points`` sharing ``normal``: the map's
    irradiance seen past ``occluder`` over the unoccluded one.  Directions are drawn per pixel
    with probability proportional to luminance x cos x solid angle (systematic sampling with a
    fresh offset per receiver, uniform jitter inside the pixel), so the estimate is the fraction
    of unoccluded rays; standard error <= 0.5 / sqrt(rays), less with the stratification."""
    h, w = env.shape[:2]
    dirs = pixel_directions(h, w).reshape(-1, 3)
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    weight = (np.maximum(env, 0) @ LUM).ravel() * np.repeat(pixel_solid_angles(h, w), w)
    weight = weight * np.maximum(dirs @ n, 0)
    cdf = np.cumsum(weight)
    cdf /= cdf[-1]
    rng = np.random.default_rng(seed)
    points = np.asarray(points, float)
    out = np.empty(len(points))
    per = max(1, chunk // rays)
    for a in range(0, len(points), per):
        p = points[a:a + per]
        m = len(p)
        xi = (np.arange(rays)[None] + rng.random((m, 1))) / rays
        pix = np.minimum(np.searchsorted(cdf, xi.ravel()), h * w - 1)
        row, col = np.divmod(pix, w)
        jx, jy = rng.random(len(pix)), rng.random(len(pix))
        lon = (0.5 - (col + jx) / w) * 2 * np.pi
        # uniform in solid angle inside the pixel: sin(latitude) uniform between its edges
        s0 = np.sin((0.5 - row / h) * np.pi)
        s1 = np.sin((0.5 - (row + 1) / h) * np.pi)
        sl = s1 + jy * (s0 - s1)
        cl = np.sqrt(np.maximum(1 - sl * sl, 0))
        d = np.stack([cl * np.cos(lon), cl * np.sin(lon), sl], -1)
        o = np.repeat(p + lift * n, rays, axis=0)
        occ = occluder.segments_occluded(o, o + distance * d, eps=1e-7)
        out[a:a + per] = 1.0 - occ.reshape(m, rays).mean(1)
    return out
