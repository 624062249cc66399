# SPDX-License-Identifier: GPL-3.0-or-later
"""An irradiance volume so that EEVEE lights virtual objects with the relit room (issue 11).

Cycles lights a virtual object with the relit surfaces' emission by itself; EEVEE lets emission
light other surfaces only through its light probes, so without one a virtual object gets the
lamps' direct light and nothing of the room's (about half of its light in the demo office:
benchmarks/results/object_appearance.md).  ``fit_volume`` puts one irradiance volume over the
relit geometry, a sample every ``spacing`` metres (at most MAX_RESOLUTION per axis); Blender's
own light-probe bake then captures the relit emission.

The bake is a still of the lamps as they are when it runs.  So that dimming or keyframing the
lamps still shows on the objects, the volume's intensity is driven (a simple expression: farm
safe) by sum_k w_k I_k / sum_k w_k I_k(bake), w_k lamp k's share of the relit room's light and
I_k = power / power at precompute, as the relit materials' own drivers; exact when the lamps
change together, a share-weighted blend otherwise.  Lamps that are emissive meshes count with
their share at I = 1.
"""

import bpy
import numpy as np
from mathutils import Vector

from . import ids, materials, state
from .drivers import add_driver

PROBE_NAME = "Relight Irradiance Volume"
SPACING = 0.25              # m between the volume's samples
MAX_RESOLUTION = 32         # samples per axis
MARGIN = 0.98               # inside the walls: samples on them see behind them
BAKED_KEY = "relight_baked_intensity"   # sum_k w_k I_k when the volume was baked
SHARES_KEY = "relight_lamp_shares"      # {lamp: its share of the relit room's light}


def relit_bounds(scene):
    """(lo, hi) world corners of the box around the objects with relit materials, or None."""
    pts = []
    for obj in {o for o, _, _ in materials.relit_slots(scene, ids.scene_key(scene))}:
        pts.append(np.array([obj.matrix_world @ Vector(c) for c in obj.bound_box]))
    if not pts:
        return None
    pts = np.concatenate(pts)
    return pts.min(axis=0), pts.max(axis=0)


def find_volume(scene):
    key = ids.scene_key(scene)
    return next((o for o in scene.objects
                 if o.type == "LIGHT_PROBE" and ids.ours(o, key)), None)


def lamp_shares(result, names):
    """{lamp: share of the relit room's light (luminance summed over every texel)} from a
    ShadowFreeResult whose maps are in the order of ``names``."""
    lum = np.array([0.2126, 0.7152, 0.0722], np.float32)
    total = np.zeros(len(names))
    for i, tex in result.texture.items():
        m = result.maps[i]                               # (k, H, W, 3)
        total += np.einsum("khwc,hwc,c->k", m[..., :3], tex[..., :3], lum, optimize=True)
    total = np.where(np.isfinite(total) & (total > 0), total, 0.0)
    s = total.sum()
    return {n: (float(v / s) if s > 0 else 1.0 / len(names)) for n, v in zip(names, total)}


def intensity_terms(scene, shares):
    """([(variable, light data, power at precompute, share)], constant share): the lamps the
    driver follows, and the share of the ones it cannot (emissive meshes, missing lights)."""
    terms, constant = [], 0.0
    for name, w in shares.items():
        obj = state.lamp_object(scene, name)
        if obj is not None and obj.type == "LIGHT" and ids.POWER0 in obj.data:
            terms.append((f"p{len(terms)}", obj.data, float(obj.data[ids.POWER0]), w))
        else:
            constant += w
    return terms, constant


def current_level(terms, constant):
    """sum_k w_k I_k for the lamps as they are now."""
    return constant + sum(w * (light.energy / p0 if p0 > 0 else 0.0)
                          for _, light, p0, w in terms)


def fit_volume(scene, shares, spacing=SPACING):
    """Create or refit ``scene``'s irradiance volume over the relit geometry and drive its
    intensity; returns the probe object (None when nothing is relit)."""
    bounds = relit_bounds(scene)
    if bounds is None:
        return None
    lo, hi = bounds
    key = ids.scene_key(scene, create=True)
    probe = find_volume(scene)
    if probe is None:
        data = bpy.data.lightprobes.new(PROBE_NAME, "VOLUME")
        probe = bpy.data.objects.new(PROBE_NAME, data)
        scene.collection.objects.link(probe)
        ids.tag(probe, key)
        ids.tag(data, key)
    size = np.maximum(hi - lo, 1e-3)
    probe.location = tuple(map(float, (lo + hi) / 2))
    probe.rotation_euler = (0.0, 0.0, 0.0)
    probe.scale = tuple(map(float, size / 2 * MARGIN))
    res = np.clip(np.ceil(size / spacing), 2, MAX_RESOLUTION).astype(int)
    data = probe.data
    for axis, n in zip("xyz", res):
        _set(data, f"resolution_{axis}", int(n))
    _set(data, "capture_emission", True)
    _set(data, "capture_indirect", True)
    _set(data, "capture_world", False)
    data[SHARES_KEY] = {n: float(w) for n, w in shares.items()}
    terms, constant = intensity_terms(scene, shares)
    data[BAKED_KEY] = current_level(terms, constant)
    drive_intensity(scene, data)
    return probe


def drive_intensity(scene, data):
    """(Re)write the volume's intensity driver from its lamp shares, the level it was baked at
    and each lamp's present power at precompute (``relight_power0``, which Match Lamp Powers
    changes together with the relit materials' drivers)."""
    if data.animation_data is not None:
        for fc in list(data.animation_data.drivers):
            data.animation_data.drivers.remove(fc)
    terms, constant = intensity_terms(scene, dict(data.get(SHARES_KEY, {})))
    level = float(data.get(BAKED_KEY, 0.0))
    if terms and level > 0:
        # one coefficient per lamp (w / (P0 level)), 6 digits: a driver expression holds 255
        # characters, ~16 lamps this way
        parts = [f"{w / (p0 * level):.6g}*{var}" for var, _, p0, w in terms if p0 > 0]
        expr = "+".join(parts + ([f"{constant / level:.6g}"] if constant > 0 else []))
        add_driver(data, expr, [(var, "LIGHT", light, "energy") for var, light, _, _ in terms],
                   prop="intensity")


def _set(data, name, value):
    """Blender 4.3+ names a volume's settings ``name`` (LightProbeVolume); 4.2 ``grid_<name>``."""
    setattr(data, name if hasattr(data, name) else f"grid_{name}", value)


def resolution(data):
    return tuple(getattr(data, f"resolution_{a}", None) or getattr(data, f"grid_resolution_{a}")
                 for a in "xyz")
