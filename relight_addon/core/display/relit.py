"""numpy twin of the relit-preview shader (relight_addon/blender/shaders/relit_frag.glsl).

What a relit material shows (blender/write.py), a shading point at a time:

    T x sum_l  s_l M_l (1 - a_l (1 - V_l))

T the shadow-free texture, M_l lamp l's map (rgb) and a_l its direct part (the map's alpha),
s_l the lamp's present scale (its power and colour over those the map was computed at: the
material's "I" and "C" nodes), V_l the part of lamp l seen past the moving objects' spheres
(core/relight/sphere_shadow.sphere_visibility, each object within its own silhouette sphere,
the objects multiplied; an object's spheres are evaluated only where its bound can shadow the
lamp, sphere_shadow.may_shadow, which leaves V unchanged).  The viewport's draw handler (blender/relit_draw.py) evaluates it in
GLSL with the spheres and lamps as uniform arrays, so a drag recompiles nothing; this is its
twin, the same operations in the same order, for the tests.
"""
from __future__ import annotations

import numpy as np

from ..relight.sphere_shadow import bounding_sphere, sphere_visibility

MAX_LAMPS = 8         # lamps a preview draws (a layer of the maps texture each)
MAX_OBJECTS = 8       # moving objects
MAX_SPHERES = 128     # spheres of all moving objects together


def lamp_visibility(points, lamp_pos, lamp_radius, objects):
    """V (n,) of one lamp from ``points`` (n, 3) past ``objects``: [(centres (m, 3), radii (m,),
    hull (centre, radius) or None)], world space."""
    v = np.ones(len(points))
    if lamp_radius < 0:                   # a lamp with no place: unshadowed
        return v
    for centres, radii, hull in objects:
        if len(radii):
            v = v * sphere_visibility(points, lamp_pos, lamp_radius, centres, radii, hull)
    return v


def relit_colour(t_rgb, maps, scales, visibility):
    """The relit colour (n, 3): ``t_rgb`` (n, 3) the texture, ``maps`` (L, n, 4) each lamp's map
    (rgb, alpha the direct part), ``scales`` (L, 3) each lamp's scale, ``visibility`` (L, n)."""
    total = np.zeros_like(np.asarray(t_rgb, float))
    for m, s, v in zip(maps, scales, visibility):
        total = total + m[:, :3] * np.asarray(s, float) * (1.0 - m[:, 3] * (1.0 - v))[:, None]
    return np.asarray(t_rgb, float) * total


def pack_uniforms(lamps, scales, objects):
    """The shader's uniforms: ``lamps`` [(position (3,), radius)], ``scales`` [(3,)] (at most
    MAX_LAMPS; a radius < 0: no shadow), ``objects`` as lamp_visibility's (at most MAX_OBJECTS,
    and whole objects up to MAX_SPHERES spheres in all; the rest dropped).  Arrays padded to their GLSL sizes, float32."""
    lamps, scales = list(lamps)[:MAX_LAMPS], list(scales)[:MAX_LAMPS]
    lamp = np.zeros((MAX_LAMPS, 4), np.float32)
    scale = np.zeros((MAX_LAMPS, 4), np.float32)
    for i, ((p, r), s) in enumerate(zip(lamps, scales)):
        lamp[i] = [*np.asarray(p, float), float(r)]
        scale[i, :3] = np.asarray(s, float)
    spheres = np.zeros((MAX_SPHERES, 4), np.float32)
    hulls = np.zeros((MAX_OBJECTS, 4), np.float32)
    bounds = np.zeros((MAX_OBJECTS, 4), np.float32)
    ends = np.zeros(MAX_OBJECTS, np.int32)
    n = k = 0
    for centres, radii, hull in list(objects)[:MAX_OBJECTS]:
        if n + len(radii) > MAX_SPHERES:      # a whole object or none (a part: half a shadow)
            continue
        m = len(radii)
        spheres[n:n + m, :3] = np.asarray(centres, float)[:m]
        spheres[n:n + m, 3] = np.asarray(radii, float)[:m]
        n += m
        if hull is not None:
            hulls[k] = [*np.asarray(hull[0], float), float(hull[1])]
        if m:
            centre, radius = bounding_sphere(spheres[n - m:n, :3], spheres[n - m:n, 3])
            bounds[k] = [*centre, radius]
        ends[k] = n
        k += 1
    return {"lamps": lamp, "lamp_scale": scale, "n_lamps": len(lamps), "spheres": spheres,
            "hulls": hulls, "bounds": bounds, "object_end": ends, "n_objects": k}
