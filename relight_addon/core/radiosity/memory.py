# SPDX-License-Identifier: GPL-3.0-or-later
"""A rough, conservative estimate of the peak memory of ``solve_radiosity`` (bpy-free).

Used before a precompute starts so that a scene too large for the machine is refused with a
clear message instead of swapping or being killed.  The model is fitted on
``benchmarks/results/scaling.md`` (cornell_box, draft and medium, 153 .. 10,625 patches):

* leaves ``L``: every input patch is split in quadtree fashion while its elements stay larger
  than ``min_area * total area``.  Per patch that is at most ``4**floor(log4(a / (min_area*A)))``
  leaves (at least 1), and over the scene at most ``patches + 1 / min_area`` (the subdivided
  leaves each cover at least ``min_area`` of the total area).  This is an upper bound; the
  refinement oracles usually stop earlier (measured: 0.5x the bound for medium at 153 patches,
  1x for the fine meshes where leaves == patches).
* links ``K ~ c * L * log2(L + 2)``, capped by the number of leaf pairs ``L (L - 1) / 2``.
  Measured ``K / (L log2 L)``: scaling.md draft 0.9 .. 7, medium 3.6 .. 7.9; cornell.md
  (17 patches) medium 2.6, high 2.0, ultra 3.7.  ``c = 6`` for every preset (the finer presets
  raise the memory through the leaf count, not through more links per leaf).
* bytes = BASE + LINK_BYTES * K + PATCH_BYTES * patches + LEAF_BYTES * L.  A least-squares fit
  of peak RSS over the 12 benchmark cases gives about 1.8-2.0 kB per link and 140 kB per
  input patch (cluster tree, visibility structures and the sparse factors of the solve) over a
  ~60 MB baseline (Python + numpy + scipy); the fit is within -30 % .. +50 % of every measured
  case.  ``LEAF_BYTES`` covers the per-element arrays of the subdivided leaves.
* A mesh solved on a proxy (radiosity.proxy: more than PROXY_FACTOR x the preset's proxy
  faces) is estimated as the proxy's solve plus ``FACE_BYTES`` per input face.
* Shadow-free textures (core/relight/shadowfree.py) add, for scenes with images, per texel of
  every used image: while the direct light of every texel and lamp is kept (texel.CACHE_BYTES)
  ``TEXEL_BYTES + TEXEL_LAMP_BYTES * lamps`` and a ray-casting chunk of ``RAY_CHUNK_BYTES``
  (measured on the office, 2 lamps, draft: 420-600 bytes a texel up to 1.17 M texels); past
  it (photo resolution: the light cast and the maps written block by block, the exitance fit
  on a sample) ``STREAM_TEXEL_BYTES + STREAM_TEXEL_LAMP_BYTES * lamps`` over
  ``STREAM_BYTES`` (the fit's sample and a block): the photos read, the texel map, the
  textures and maps written (measured: 648 MB at 4.7 M texels, 1650 MB at 16.5 M over the
  process's own 209 MB; benchmarks/results/texel_scaling.md).
"""
from __future__ import annotations

import ctypes
import math
import sys
from functools import lru_cache

import numpy as np

from .presets import PROXY_FACTOR, get_preset

BASE_BYTES = 60 * 2**20
LINK_BYTES = 2 * 1024
PATCH_BYTES = 144 * 1024
LEAF_BYTES = 8 * 1024
LINKS_PER_LEAF_LOG = 6.0
TEXEL_BYTES = 200
TEXEL_LAMP_BYTES = 250
RAY_CHUNK_BYTES = 170 * 2**20    # two ray-casting threads of 8k texels (texel.TEXEL_CHUNK)
STREAM_BYTES = 280 * 2**20
STREAM_TEXEL_BYTES = 60
STREAM_TEXEL_LAMP_BYTES = 18
# per input face of a mesh solved on a proxy: family room 0 as a scan of 25k-200k faces at
# medium (benchmarks/results/scan.md) took 471-774 MB over the read, 1.7 kB more a face
FACE_BYTES = 2 * 1024


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


def estimate_links(leaves) -> float:
    return min(LINKS_PER_LEAF_LOG * leaves * math.log2(leaves + 2.0), leaves * (leaves - 1.0) / 2.0)


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
        # the proxy's triangles are unknown before decimation: as many equal ones
        solve_areas = np.full(faces, float(np.sum(areas)) / faces)
        solve_patches = faces
        full = FACE_BYTES * patches
    else:
        solve_areas, solve_patches, full = areas, patches, 0
    leaves = estimate_leaves(solve_areas, quality.min_area)
    links = estimate_links(leaves)
    total = BASE_BYTES + LINK_BYTES * links + PATCH_BYTES * solve_patches + LEAF_BYTES * leaves
    return int(total + full + estimate_texel_memory(scene_data))


def estimate_texel_memory(scene_data) -> int:
    """Bytes the shadow-free texture step adds for the images the patches use."""
    images = getattr(scene_data, "images", None) or []
    image_of = getattr(scene_data, "image", None)
    if not images or image_of is None:
        return 0
    used = set(int(i) for i in np.unique(image_of) if i >= 0)
    texels = 0
    for i in used:
        tex = getattr(images[i], "texels", images[i])
        texels += int(np.prod(np.shape(tex)[:2]))
    lamps = int(getattr(scene_data, "n_lamps", 1))
    from ..relight.texel import CACHE_BYTES
    if 48 * texels * max(lamps, 1) > CACHE_BYTES:        # streamed (texel.TexelLight)
        return int(STREAM_BYTES + texels * (STREAM_TEXEL_BYTES + STREAM_TEXEL_LAMP_BYTES * lamps))
    return int(RAY_CHUNK_BYTES + texels * (TEXEL_BYTES + TEXEL_LAMP_BYTES * lamps))


def give_back_memory():
    """Return the C allocator's free pages to the system (glibc's malloc_trim; nothing
    elsewhere).  A block's arrays of a few MB are freed into the heaps of the threads that made
    them and would stay resident: on 16.5 M texels (bench_texel_scaling.py) 2.12 GB peak
    without, 2.03 GB with (before float32 texel parameters); in the radiosity solve of
    RenderPark's office at medium, 6.6 GB without, 5.0 GB with (the form factors' threads)."""
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
