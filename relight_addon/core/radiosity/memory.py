# SPDX-License-Identifier: GPL-3.0-or-later
"""A conservative estimate of the peak memory of a precompute (bpy-free).

Used before a precompute starts so that a scene too large for the machine is refused with a
clear message instead of swapping or being killed.  It estimates what the precompute adds to
the process (its arrays, the solver's, the threads' temporaries) over BASE_BYTES for Python,
numpy and scipy; the scene already read is not counted.  Every line below is fitted above
measured peaks (``ru_maxrss`` after the precompute minus before it, plus BASE_BYTES): the
measurements are in benchmarks/results/ (scaling.md, mgf.md, scan.md, texel_scaling.md, and
constants_history.md for the fits).

* leaves ``L``: every input patch is split in quadtree fashion while its elements stay larger
  than ``min_area * total area``.  Per patch that is at most ``4**floor(log4(a / (min_area*A)))``
  leaves (at least 1), and over the scene at most ``patches + 1 / min_area`` (the subdivided
  leaves each cover at least ``min_area`` of the total area).  This is an upper bound; the
  refinement oracles usually stop earlier.
* the solve: ``SOLVE_BYTES[preset] = (fixed, per leaf, per patch, at most)``: fixed + per
  leaf x L + per patch x patches, or ``at most`` x L where that is less (draft: small scenes,
  whose memory grows from nothing rather than from the fixed part), and never less than a
  coarser preset's.  The links and their leaf-level entries per leaf depend on the scene and
  on the preset, so each preset has its own line, fitted 15 % above the upper envelope of its
  measured solves (a solve's peak varies by +-12 % from run to run).
* A mesh solved on a proxy (radiosity.proxy: more than PROXY_FACTOR x the preset's proxy
  faces) goes through phases one after another, and its peak is the largest of them: the
  mesh's (turning faces, decimating, placing the texels: ``MESH_BYTES`` + ``FACE_BYTES`` per
  input face + ``PLACE_TEXEL_BYTES`` per texel of its photos), the proxy's solve
  (``PROXY_SOLVE_BYTES[preset]``: fixed + per proxy triangle), and the texel work over what
  the solution holds meanwhile (``PROXY_HELD`` of the solve).  The same case varies by
  +-14 % from run to run, so these lines sit ~10 % above the runs' mean rather than above the
  largest.
* Shadow-free textures (core/relight/shadowfree.py) add, for scenes with images, per texel of
  every used image: while the direct light of every texel and lamp is kept (TEXEL_CACHE_BYTES)
  ``TEXEL_BYTES + TEXEL_LAMP_BYTES * lamps`` and a ray-casting chunk of ``RAY_CHUNK_BYTES``
  (fitted 10 % above); past it (photo resolution: the light cast and the maps written block
  by block, the exitance fit on a sample) ``STREAM_TEXEL_BYTES + STREAM_TEXEL_LAMP_BYTES *
  lamps`` over ``STREAM_BYTES`` (the fit's sample and a block): the photos read, the texel
  map, the textures and maps written.
"""
from __future__ import annotations

import ctypes
import importlib
import math
import sys
import threading
from functools import lru_cache

import numpy as np

from .presets import PRESETS, PROXY_FACTOR, get_preset

BASE_BYTES = 60 * 2**20
# the solve: fixed, per leaf (bound) and per patch bytes of each preset, and at most so many
# bytes a leaf (bound) where that is less: small scenes (module docstring)
SOLVE_BYTES = {"draft": (298 * 2**20, 0, 73 * 2**10, 360 * 2**10),
               "medium": (262 * 2**20, 51 * 2**10, 87 * 2**10, 0),
               "high": (442 * 2**20, 7 * 2**10, 172 * 2**10, 0),
               "ultra": (568 * 2**20, 36 * 2**10, 0, 0)}
TEXEL_BYTES = 200
TEXEL_LAMP_BYTES = 130
RAY_CHUNK_BYTES = 170 * 2**20    # two ray-casting threads of 8k texels (texel.TEXEL_CHUNK)
STREAM_BYTES = 280 * 2**20
STREAM_TEXEL_BYTES = 60
STREAM_TEXEL_LAMP_BYTES = 18
# the direct light of every texel and lamp (unoccluded and occluded, float64: 48 bytes) is kept
# while it takes at most this much; a larger map is cast block by block when it is read
TEXEL_CACHE_BYTES = 256 * 2**20
# A mesh solved on a proxy (module docstring): its mesh phase (fixed, per input face), the
# proxy's solve (fixed, per proxy triangle) per preset (the links per triangle grow with the
# preset: high's and ultra's lines go through the origin), and the share of the solve held
# while the texels are lit.  Ultra's from one solve.
MESH_BYTES = 300 * 2**20
FACE_BYTES = 512
PLACE_TEXEL_BYTES = 48
PROXY_SOLVE_BYTES = {"draft": (370 * 2**20, 70 * 2**10),
                     "medium": (370 * 2**20, 70 * 2**10),
                     "high": (0, 265 * 2**10),
                     "ultra": (0, 1600 * 2**10)}
PROXY_HELD = 0.4


def estimate_leaves(areas, min_area_fraction) -> float:
    """Upper bound on the number of leaf elements (see the module docstring)."""
    areas = np.asarray(areas, float)
    areas = areas[areas > 0]
    if len(areas) == 0:
        return 0.0
    total = float(areas.sum())
    ratio = areas / (min_area_fraction * total)
    levels = np.floor(np.log(np.maximum(ratio, 1.0)) / np.log(4.0))
    per_patch = float(np.sum(4.0 ** levels))
    return min(per_patch, len(areas) + 1.0 / min_area_fraction)


def solve_bytes(quality, areas) -> float:
    """The solve's bytes on patches of ``areas``: the largest of the lines of the preset and
    of the coarser ones (a finer preset never needs less).  A preset of another name is
    counted as the named one whose smallest element is nearest to its own."""
    name = _nearest_named(quality)
    patches = int(np.count_nonzero(np.asarray(areas) > 0))
    out = 0.0
    for k in _up_to(name):
        fixed, per_leaf, per_patch, at_most = SOLVE_BYTES[k]
        min_area = quality.min_area if k == name else PRESETS[k].min_area
        leaves = estimate_leaves(areas, min_area)
        line = fixed + per_leaf * leaves + per_patch * patches
        out = max(out, min(line, at_most * leaves) if at_most else line)
    return out


def estimate_precompute_memory(scene_data, preset, proxy=True, proxy_faces=0) -> int:
    """Estimated peak bytes of the precompute of ``scene_data`` at ``preset``: the solve, and
    the shadow-free textures' per-texel work.

    ``scene_data`` is a ``SceneData`` (only its patch areas are used) or, for tests and quick
    what-ifs, an array of patch areas.  ``preset`` is a preset name or a ``Quality``.  With
    ``proxy`` a mesh of more than PROXY_FACTOR x the preset's proxy faces (``proxy_faces``
    when given) is solved on a decimated proxy (radiosity.proxy), as the precompute does: its
    own faces then cost FACE_BYTES each and the solve is the proxy's.
    """
    quality = get_preset(preset)
    if hasattr(scene_data, "area_normal"):
        areas = scene_data.area_normal()[0]
    else:
        areas = np.asarray(scene_data, float)
    patches = int(np.count_nonzero(np.asarray(areas) > 0))
    faces = int(proxy_faces) or quality.proxy_faces
    if proxy and patches > PROXY_FACTOR * faces:
        return int(BASE_BYTES + max(_phases_of(scene_data, quality, patches, faces)[0].values()))
    return int(BASE_BYTES + solve_bytes(quality, areas) + estimate_texel_memory(scene_data))


def proxy_phases(quality, patches, faces, texel_bytes, texels=0) -> dict:
    """Bytes of each phase of a mesh of ``patches`` faces solved on a proxy of ``faces``
    triangles, whose photos have ``texels`` texels and cost ``texel_bytes`` to light (module
    docstring): {"mesh", "solve", "texels"}."""
    solve = max(fixed + per_triangle * faces             # never less than a coarser preset's
                for fixed, per_triangle in (PROXY_SOLVE_BYTES[k]
                                            for k in _up_to(_nearest_named(quality))))
    return {"mesh": MESH_BYTES + FACE_BYTES * patches + PLACE_TEXEL_BYTES * texels,
            "solve": solve,
            "texels": PROXY_HELD * solve + texel_bytes}


def proxy_need(scene_data, preset, proxy_faces=0) -> str:
    """What sets the peak of ``scene_data`` solved on a proxy (what to lower when it is too
    much): "faces" (the mesh's own phase), "solve" (the proxy's) or "photos" (placing their
    texels on the proxy, or lighting them)."""
    quality = get_preset(preset)
    patches = scene_data.n_patches
    phases, texels = _phases_of(scene_data, quality, patches,
                                int(proxy_faces) or quality.proxy_faces)
    largest = max(phases, key=phases.get)
    if largest == "mesh":
        return "photos" if PLACE_TEXEL_BYTES * texels > FACE_BYTES * patches else "faces"
    return "photos" if largest == "texels" else "solve"


def _phases_of(scene_data, quality, patches, faces):
    """:func:`proxy_phases` of a scene's ``patches`` faces and its photos, and their texels."""
    texels, lamps = _texels_and_lamps(scene_data)
    return proxy_phases(quality, patches, faces, _texel_bytes(texels, lamps), texels or 0), \
        texels or 0


def _up_to(name):
    """The named presets from the coarsest to ``name``."""
    order = sorted(SOLVE_BYTES, key=lambda k: -PRESETS[k].min_area)
    return order[:order.index(name) + 1]


def _nearest_named(quality):
    """The named preset ``quality`` is (or, made with Quality.with_, whose smallest element is
    nearest to its own)."""
    if quality.name in SOLVE_BYTES:
        return quality.name
    return min(SOLVE_BYTES, key=lambda k: abs(math.log(PRESETS[k].min_area / quality.min_area)))


def estimate_texel_memory(scene_data) -> int:
    """Bytes the shadow-free texture step adds for the images the patches use."""
    return _texel_bytes(*_texels_and_lamps(scene_data))


def _texel_bytes(texels, lamps) -> int:
    """That for ``texels`` texels (None: no images) lit by ``lamps`` lamps."""
    if texels is None:
        return 0
    if 48 * texels * max(lamps, 1) > TEXEL_CACHE_BYTES:        # streamed (texel.TexelLight)
        return int(STREAM_BYTES + texels * (STREAM_TEXEL_BYTES + STREAM_TEXEL_LAMP_BYTES * lamps))
    return int(RAY_CHUNK_BYTES + texels * (TEXEL_BYTES + TEXEL_LAMP_BYTES * lamps))


def _texels_and_lamps(scene_data):
    """Texels of the images the patches use (None: no images), and the lamps."""
    images = getattr(scene_data, "images", None) or []
    image_of = getattr(scene_data, "image", None)
    lamps = int(getattr(scene_data, "n_lamps", 1))
    if not images or image_of is None:
        return None, lamps
    texels = 0
    for i in set(int(i) for i in np.unique(image_of) if i >= 0):
        tex = getattr(images[i], "texels", images[i])
        texels += int(np.prod(np.shape(tex)[:2]))
    return texels, lamps


def give_back_memory():
    """Return the C allocator's free pages to the system (glibc's malloc_trim; nothing
    elsewhere).  A block's arrays of a few MB are freed into the heaps of the threads that made
    them and would stay resident."""
    trim = _malloc_trim()
    if trim is not None:
        trim(0)


@lru_cache(maxsize=1)
def _malloc_trim():
    if not sys.platform.startswith("linux"):
        return None
    try:
        return ctypes.CDLL("libc.so.6").malloc_trim
    except (OSError, AttributeError):          # not glibc (musl)
        return None


def resized(array, n):
    """``array`` (1-D) grown or shrunk to ``n`` items, in place when numpy owns its buffer:
    realloc moves a large buffer's pages (mremap) instead of copying them, so a 400 MB array
    grown by its tail is not held twice, as np.concatenate would hold it, and a shrunk one
    gives its tail back.  Only a buffer made by ``growable`` grows without a copy.  No view of
    ``array`` may be alive (it would point at freed memory).  New items are zeros or
    uninitialised: the caller writes them."""
    if array.flags.owndata and array.base is None and array.flags.c_contiguous and array.ndim == 1:
        try:
            array.resize(n, refcheck=False)
            return array
        except (ValueError, MemoryError):
            pass
    out = growable(n, array.dtype)
    k = min(n, len(array))
    out[:k] = array[:k]
    return out


_HUGEPAGE_LOCK = threading.Lock()


def growable(n, dtype):
    """np.empty(n, dtype) whose buffer ``resized`` grows in place.  numpy asks the kernel for
    huge pages on arrays of 4 MB and more (madvise), and glibc's realloc then copies such a
    buffer instead of remapping it: a 400 MB array grown by 20 % peaked at 800 MB (measured,
    numpy 1.26, glibc 2.36), which made the form factors' join the office's peak at medium.
    Allocated with that advice off (numpy's private switch; where it is missing, a plain
    np.empty).  The switch is the process's: call it outside worker threads (another thread's
    large arrays made meanwhile would go without the advice, slower only)."""
    switch = _hugepage_switch()
    if switch is None:
        return np.empty(n, dtype)
    with _HUGEPAGE_LOCK:
        was = switch(False)
        try:
            return np.empty(n, dtype)
        finally:
            switch(was)


@lru_cache(maxsize=1)
def _hugepage_switch():
    for module in ("numpy._core.multiarray", "numpy.core.multiarray"):
        try:
            return getattr(importlib.import_module(module), "_set_madvise_hugepage")
        except (ImportError, AttributeError):
            continue
    return None
