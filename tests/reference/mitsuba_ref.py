"""Mitsuba 3 ground truth for patch irradiance / radiosity of a :class:`SceneData`.

Independent of the Relight solver: the scene is handed to Mitsuba's ``volpath`` path tracer
and the incident irradiance of each requested patch is measured with Mitsuba's stock
``irradiancemeter`` sensor attached to that patch's mesh.

What the irradiance meter measures (mitsuba3 ``src/sensors/irradiancemeter.cpp``): it samples
a point uniformly by area on its shape (``sample_position``), a cosine-weighted direction in
the hemisphere around the shape's normal at that point, and weights the traced radiance by
pi.  The pixel mean is therefore the area-averaged incident irradiance (W/m^2) on the FRONT
side of the patch (our normal side; the meshes are built with the patch's winding and no
vertex normals, so the face normal is the patch normal).  ``tests/test_mitsuba_reference.py``
checks it against analytic form factors.

Scene translation
-----------------
* one Mitsuba mesh per patch, the quad ``(a, b, c, d)`` as triangles ``(a, b, c)`` and
  ``(a, c, d)`` (degenerate halves of triangles ``(a, b, c, c)`` are dropped);
* occluders get a ``diffuse`` BSDF with ``rho``.  Mitsuba 3 BSDFs are one-sided: a ray that
  hits the back side sees black and the path ends there, and a surface never reflects light
  arriving at its back -- exactly the radiosity convention (use ``twosided`` to get the other
  behaviour; we deliberately do not);
* emitters get an ``area`` emitter with radiance ``E / pi`` (one-sided, front only);
* NON-occluders (``scene.occluder == False``, e.g. Blender area lights) get the ``null`` BSDF:
  rays pass straight through them, they still emit from the front.  This needs the ``volpath``
  integrator (the plain ``path`` integrator returns 0 for emitters on null surfaces in 3.9.1);
  volpath does not count a null crossing as a bounce.  A non-occluder must have rho == 0
  (raises otherwise).  volpath's emitter-sampling shadow rays also cross null surfaces.

``max_depth`` uses Mitsuba's convention, counted from the patch: 1 = light arriving directly
from emitters only (H_direct, i.e. the form factors times the exitances); k = light that
reflected at most k - 1 times before reaching the patch; -1 = unlimited (unbiased, Russian
roulette).

Noise: every patch is rendered in ``repeats`` independent passes (different seeds) of
``spp / repeats`` samples; the mean is returned and the standard error of the mean is
``std(passes, ddof=1) / sqrt(repeats)`` (itself uncertain by ~25 % with 8 passes).  The meter
does no emitter sampling at the patch (the first segment is cosine-sampled, later bounces use
volpath's NEE + MIS), so the noise is dominated by the direct light of small lamps: the
Cornell box at 2**22 spp per patch gives <= ~0.4 % relative standard error.  Known bias:
grazing sensor rays (cos < ~1e-2) can re-hit their own patch from behind (float32 offset),
making H low by ~1e-4 relative -- far below the tolerances used.

Cache: results are stored under ``<repo>/.cache/mitsuba/<key>/p<patch>.npy`` (or under
``$RELIGHT_MITSUBA_CACHE``; gitignored; one (2, 3) array [H, stderr] per patch, written as
soon as the patch is done) with ``<key>`` a SHA-256 of the geometry, rho, emission, occluder
flags, spp, max_depth, seed, repeats, the Mitsuba version, variant and this module's
``CACHE_FORMAT``.

Variant: ``scalar_rgb`` (env ``RELIGHT_MITSUBA_VARIANT`` overrides).  ``llvm_ad_rgb`` aborts on
this machine (LLVM 15 "Cannot select fminimum"; LLVM 14 is refused as too old).
"""
from __future__ import annotations

import hashlib
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

REPO_ROOT = Path(__file__).resolve().parents[2]
if str(REPO_ROOT) not in sys.path:  # allow `pytest tests/...` without installing the package
    sys.path.insert(0, str(REPO_ROOT))

from relight_addon.core.scene import SceneData, quad_area_normal

CACHE_FORMAT = 2
CACHE_DIR = Path(os.environ.get("RELIGHT_MITSUBA_CACHE") or REPO_ROOT / ".cache" / "mitsuba")
VARIANT = os.environ.get("RELIGHT_MITSUBA_VARIANT", "scalar_rgb")
DEFAULT_SPP = 1 << 20
DEFAULT_REPEATS = 8
FILM_WIDTH = 2  # >1 pixel so that scalar Mitsuba splits the work over 2 threads

_mi = None


def _mitsuba():
    global _mi
    if _mi is None:
        import mitsuba as mi
        mi.set_variant(VARIANT)
        _mi = mi
    elif _mi.variant() != VARIANT:
        _mi.set_variant(VARIANT)
    return _mi


def mitsuba_version() -> str:
    """Installed Mitsuba version (from the package metadata: no slow import for cache hits)."""
    try:
        from importlib.metadata import version
        return version("mitsuba")
    except Exception:
        return _mitsuba().__version__


# -- scene translation ----------------------------------------------------------------------
def _patch_triangles(corners: np.ndarray) -> np.ndarray:
    """(t, 3, 3) non-degenerate triangles (a, b, c), (a, c, d) of one quad."""
    tris = np.stack([corners[[0, 1, 2]], corners[[0, 2, 3]]])
    area = np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=-1)
    return tris[area > 1e-12 * max(area.max(), 1e-300)]


def _rgb(value):
    return {"type": "rgb", "value": [float(x) for x in value]}


def _sensor(mi, spp_per_pixel: int):
    return mi.load_dict({
        "type": "irradiancemeter",
        "sampler": {"type": "independent", "sample_count": int(spp_per_pixel)},
        "film": {"type": "hdrfilm", "width": FILM_WIDTH, "height": 1, "rfilter": {"type": "box"},
                 "pixel_format": "rgb", "component_format": "float32"},
    })


def build_mitsuba_scene(scene: SceneData, sensor_patches=(), spp: int = DEFAULT_SPP,
                        max_depth: int = -1):
    """Mitsuba scene for ``scene``; returns ``(mi_scene, {patch index: sensor})``.

    ``spp`` is the sample count per render of one sensor (split over the film's pixels)."""
    mi = _mitsuba()
    sensor_patches = set(int(i) for i in sensor_patches)
    spp_per_pixel = max(1, -(-int(spp) // FILM_WIDTH))
    bad = (~scene.occluder) & (scene.rho.max(axis=1) > 0)
    if bad.any():
        raise ValueError(f"Non-occluding patches must have rho == 0 (patches {np.flatnonzero(bad)[:5]})")
    null_bsdf = mi.load_dict({"type": "null"})
    bsdf_cache = {}
    desc = {"type": "scene", "integrator": {"type": "volpath", "max_depth": int(max_depth)}}
    sensors = {}
    for i in range(scene.n_patches):
        tris = _patch_triangles(scene.corners[i])
        props = mi.Properties()
        if scene.occluder[i]:
            key = tuple(scene.rho[i])
            if key not in bsdf_cache:
                bsdf_cache[key] = mi.load_dict({"type": "diffuse", "reflectance": _rgb(key)})
            props["bsdf"] = bsdf_cache[key]
        else:
            props["bsdf"] = null_bsdf
        if scene.emission[i].max() > 0:
            props["emitter"] = mi.load_dict({"type": "area", "radiance": _rgb(scene.emission[i] / np.pi)})
        if i in sensor_patches:
            sensors[i] = _sensor(mi, spp_per_pixel)
            props["sensor"] = sensors[i]
        vertices = tris.reshape(-1, 3).astype(np.float32)
        mesh = mi.Mesh(f"patch{i}", len(vertices), len(tris), props)
        params = mi.traverse(mesh)
        params["vertex_positions"] = vertices.ravel()
        params["faces"] = np.arange(len(vertices), dtype=np.uint32)
        params.update()
        desc[f"patch{i}"] = mesh
    return mi.load_dict(desc), sensors


# -- cache ----------------------------------------------------------------------------------
def _cache_dir(scene: SceneData, spp, max_depth, seed, repeats) -> Path:
    """One directory per (scene, settings); one file per patch, so partial runs are kept and
    any subset of patches shares the same entries."""
    h = hashlib.sha256()
    for arr in (scene.corners, scene.rho, scene.emission):
        h.update(np.ascontiguousarray(arr, dtype=np.float64).tobytes())
    h.update(np.ascontiguousarray(scene.occluder, dtype=np.uint8).tobytes())
    h.update(json.dumps([int(spp), int(max_depth), int(seed), int(repeats), mitsuba_version(),
                         VARIANT, CACHE_FORMAT, FILM_WIDTH, "volpath"]).encode())
    return CACHE_DIR / h.hexdigest()[:32]


def _cache_load(directory: Path, patch: int):
    path = directory / f"p{patch}.npy"
    if not path.exists():
        return None
    try:
        value = np.load(path)
        return value if value.shape == (2, 3) else None
    except Exception:  # corrupt / partial file: recompute
        return None


def _cache_store(directory: Path, patch: int, value: np.ndarray, meta: dict):
    directory.mkdir(parents=True, exist_ok=True)
    tmp = directory / f"p{patch}.{os.getpid()}.tmp.npy"
    np.save(tmp, value)
    os.replace(tmp, directory / f"p{patch}.npy")
    meta_path = directory / "meta.json"
    if not meta_path.exists():
        tmpj = directory / f"meta.{os.getpid()}.tmp.json"
        tmpj.write_text(json.dumps(meta, indent=1))
        os.replace(tmpj, meta_path)


# -- public API -----------------------------------------------------------------------------
def patch_irradiance(scene: SceneData, patches=None, spp: int = DEFAULT_SPP, max_depth: int = -1,
                     seed: int = 0, return_stderr: bool = False, repeats: int = DEFAULT_REPEATS,
                     cache: bool = True, verbose: bool = False):
    """Area-averaged incident irradiance (W/m^2, linear RGB) on the FRONT of each patch.

    patches    indices into the scene's patches (default: all), result rows follow this order
    spp        total samples per patch (split into ``repeats`` independent passes)
    max_depth  Mitsuba convention, see the module docstring (1 = direct only, -1 = all bounces)
    seed       base seed; patch p, pass r uses Mitsuba seed ``seed * 1000003 + 64 p + r``
    cache      read/write ``.cache/mitsuba/<hash of scene and settings>/p<index>.npy``
    Returns ``H`` (k, 3), or ``(H, stderr)`` with the standard error of the mean if
    ``return_stderr``.
    """
    patches = np.arange(scene.n_patches) if patches is None else np.atleast_1d(np.asarray(patches, int))
    repeats = max(2, int(repeats))
    directory = _cache_dir(scene, spp, max_depth, seed, repeats) if cache else None
    result = np.full((len(patches), 2, 3), np.nan)
    todo = []
    for k, p in enumerate(patches):
        hit = _cache_load(directory, int(p)) if cache else None
        if hit is None:
            todo.append(k)
        else:
            result[k] = hit
    if todo:
        mi = _mitsuba()
        mscene, sensors = build_mitsuba_scene(scene, {int(patches[k]) for k in todo},
                                              spp=max(1, spp // repeats), max_depth=max_depth)
        meta = {"n_patches": int(scene.n_patches), "spp": int(spp), "max_depth": int(max_depth),
                "seed": int(seed), "repeats": repeats, "mitsuba": mitsuba_version(),
                "variant": VARIANT, "format": CACHE_FORMAT}
        done = {}
        for k in todo:
            p = int(patches[k])
            if p in done:
                result[k] = done[p]
                continue
            t0 = time.perf_counter()
            passes = np.empty((repeats, 3))
            for r in range(repeats):
                img = mi.render(mscene, sensor=sensors[p], seed=(int(seed) * 1000003 + p * 64 + r) % (1 << 31))
                passes[r] = np.asarray(img, dtype=np.float64).reshape(-1, 3).mean(axis=0)
            value = np.stack([passes.mean(axis=0), passes.std(axis=0, ddof=1) / np.sqrt(repeats)])
            done[p] = result[k] = value
            if cache:
                _cache_store(directory, p, value, meta)
            if verbose:
                print(f"mitsuba_ref: patch {p}: H={value[0]} stderr={value[1]} "
                      f"({time.perf_counter() - t0:.1f} s)", flush=True)
    H, err = result[:, 0], result[:, 1]
    return (H, err) if return_stderr else H


def patch_radiosity(scene: SceneData, patches=None, spp: int = DEFAULT_SPP, max_depth: int = -1,
                    seed: int = 0, return_stderr: bool = False, repeats: int = DEFAULT_REPEATS,
                    cache: bool = True, verbose: bool = False):
    """Radiosity ``B = E + rho * H`` (W/m^2) of each requested patch, H from
    :func:`patch_irradiance` (same arguments).  With ``return_stderr`` also ``rho * stderr(H)``.
    """
    idx = np.arange(scene.n_patches) if patches is None else np.atleast_1d(np.asarray(patches, int))
    H, err = patch_irradiance(scene, idx, spp=spp, max_depth=max_depth, seed=seed,
                              return_stderr=True, repeats=repeats, cache=cache, verbose=verbose)
    B = scene.emission[idx] + scene.rho[idx] * H
    return (B, scene.rho[idx] * err) if return_stderr else B


def relative_stderr(value, stderr, floor: float = 1e-12):
    """Per-entry relative standard error ``stderr / |value|`` (0 where value is ~0)."""
    value = np.abs(np.asarray(value, float))
    return np.where(value > floor, np.asarray(stderr, float) / np.maximum(value, floor), 0.0)


def patch_areas(scene: SceneData) -> np.ndarray:
    return quad_area_normal(scene.corners)[0]
