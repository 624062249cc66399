"""Moving objects' exact direct shadows where they stand ("settled", issue 11).

A moving object's shadow is drawn at render time from its spheres (sphere_shadow.py) so that it
follows drags and animation; where it stands when Update runs, the shadow of its real triangles
is computed once here and the relit materials use it while the object stays there.  Per texel
and lamp, V_k = E_k(past the objects) / E_k(unoccluded): the lamp's direct irradiance seen past
the objects' triangles (and nothing else: the room's own shadows are in the maps already), the
same quantity the spheres approximate, so the material's ``1 - a_k (1 - V_k)`` takes either.
"""
from __future__ import annotations

import numpy as np

from ..geometry.raycast import make_occluder
from ..scene import bilinear_point
from ..texture.colour import LUMINANCE
from .texel import TexelLight

RAYS = 32                  # per footprint point and lamp
SAMPLES = 2                # footprint points per texel side (as the maps' direct light)
UNLIT = 1e-9               # of the brightest texel's irradiance: no light to shadow


def texel_points(scene, texel_map):
    """(T, 3) world positions and (T, 3) normals of the covered texels' centres."""
    tm = texel_map
    pts = bilinear_point(scene.corners[tm.patch][:, None], tm.u[:, None], tm.v[:, None])[:, 0]
    return pts, scene.area_normal()[1][tm.patch]


def object_visibility(scene, texel_map, triangles, rays=RAYS, samples=SAMPLES,
                      seed=0) -> np.ndarray:
    """(T, k) part of each lamp's direct light on the texels of ``texel_map`` (averaged over
    each texel's footprint, as a photo texel and the maps average it) that passes the
    ``triangles`` (t, 3, 3, world); 1 where a lamp gives no light."""
    T, k = texel_map.n_texels, scene.n_lamps
    if T == 0 or len(triangles) == 0:
        return np.ones((T, k))
    occluder = make_occluder(np.asarray(triangles, float))
    U, O = TexelLight(scene, texel_map, occluder, rays, samples, seed).direct()
    u, o = U @ LUMINANCE, O @ LUMINANCE
    lit = u > UNLIT * max(float(u.max(initial=0.0)), 1e-300)
    V = np.ones((T, k))
    V[lit] = np.clip(o[lit] / u[lit], 0.0, 1.0)
    return V
