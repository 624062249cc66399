"""Fingerprints of a scene's parts, that Update compares to know what changed since the last run.

A scene is the photographed surfaces, its lamps (each on its own, by label) and the virtual
objects.  Powers are never part of a fingerprint (the relit materials follow them through
drivers); a lamp's colour is (relative, as the photo sees it).  So a lamp dimmed, renamed (its
label stays), switched off or deleted changes no surface's fingerprint, and a virtual lamp or
object changes only its own.
"""
from __future__ import annotations

import hashlib

import numpy as np

from .scene import SceneData


def _hash(arrays, extra=()) -> str:
    h = hashlib.sha256()
    for a in arrays:
        a = np.ascontiguousarray(a)
        h.update(str((a.dtype.str, a.shape)).encode())
        h.update(a.tobytes())
    for e in extra:
        h.update(repr(e).encode())
    return h.hexdigest()


def _partition(group):
    """Groups as a partition numbered by first patch (objects read in between renumber them)."""
    if not len(group):
        return np.zeros(0, np.int64)
    _, first, inverse = np.unique(group, return_index=True, return_inverse=True)
    return np.argsort(np.argsort(first))[inverse.ravel()]


def scene_parts(data: SceneData) -> dict:
    """{"geometry": the surfaces' geometry (what the radiosity mesh and links depend on),
    "surfaces": the same with reflectances, UVs and photos, "objects": the virtual objects,
    "lamps": {label: that lamp's geometry and colour}}."""
    surf = np.flatnonzero((np.asarray(data.lamp) < 0) & ~np.asarray(data.virtual, bool))
    geometry = [data.corners[surf], data.occluder[surf], _partition(data.group[surf])]
    textures = [data.rho[surf]] + [a[surf] for a in (data.uv, data.image) if a is not None]
    photos = [np.ascontiguousarray(getattr(im, "texels", im)) for im in data.images]
    obj = np.flatnonzero(np.asarray(data.virtual, bool))
    objects = [data.corners[obj], data.rho[obj], _partition(data.group[obj])]
    lamps = {}
    emission = np.asarray(data.emission, np.float64)
    lights = data.lights
    light_arrays = lights.fingerprint_arrays()
    for k, label in enumerate(data.lamp_names):
        sel = np.flatnonzero(np.asarray(data.lamp) == k)
        peak = emission[sel].max() if len(sel) else 0.0
        colour = emission[sel] / peak if peak > 0 else np.zeros_like(emission[sel])
        rows = np.flatnonzero(lights.lamp == k)
        # a light's own lamp index is left out: lamps read in between renumber the others
        parts = [a[rows] for j, a in enumerate(light_arrays) if j != 1]
        lamps[str(label)] = _hash([data.corners[sel], colour, data.occluder[sel]] + parts)
    return {"geometry": _hash(geometry), "surfaces": _hash(geometry + textures + photos),
            "objects": _hash(objects), "lamps": lamps}
