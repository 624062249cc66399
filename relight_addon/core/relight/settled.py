"""Moving objects' exact direct shadows where they stand ("settled", issue 11).

A moving object's shadow is drawn at render time from its spheres (sphere_shadow.py) so that it
follows drags and animation; where it stands when Update runs, the shadow of its real triangles
is computed once here and the relit materials use it while the object stays there.  Per texel
and lamp, V_k = E_k(past the objects) / E_k(unoccluded): the lamp's direct irradiance seen past
the objects' triangles (and nothing else: the room's own shadows are in the maps already), the
same quantity the spheres approximate, so the material's ``1 - a_k (1 - V_k)`` takes either.
Only texels whose view of a lamp's bounding sphere can meet an object's bounding sphere are
ray-traced (``may_be_shadowed``): the rest see every lamp whole.
"""
from __future__ import annotations

import numpy as np

from ..geometry.patch import bilinear_point
from ..geometry.raycast import make_occluder
from ..lights import AREA, SUN
from ..numerics import safe_div
from ..texture.colour import LUMINANCE
from ..texture.mapping import dilate_seams, texel_subset
from .maps import SEAM_PIXELS
from .texel import TexelLight

RAYS = 32                  # per footprint point and lamp
SAMPLES = 2                # footprint points per texel side (as the maps' direct light)
UNLIT = 1e-9               # of the brightest texel's irradiance: no light to shadow


def texel_points(scene, texel_map):
    """(T, 3) world positions and (T, 3) normals of the covered texels' centres."""
    tm = texel_map
    pts = bilinear_point(scene.corners[tm.patch][:, None], tm.u[:, None], tm.v[:, None])[:, 0]
    return pts, scene.area_normal()[1][tm.patch]


def _lamp_spheres(scene):
    """[(lamp, centre, radius, sun direction or None, sun angular radius)]: a bounding sphere
    of every light and emissive-face lamp (a sun: its direction and angular radius)."""
    out = []
    L = scene.lights
    for i in range(len(L)):
        if L.kind[i] == SUN:
            out.append((int(L.lamp[i]), None, 0.0, L.axes[i][2], 0.5 * float(L.angle[i])))
        elif L.kind[i] == AREA:
            out.append((int(L.lamp[i]), L.position[i], 0.5 * float(np.hypot(*L.size[i])), None,
                        0.0))
        else:
            out.append((int(L.lamp[i]), L.position[i], float(L.radius[i]), None, 0.0))
    lamp = np.asarray(scene.lamp)
    for k in np.unique(lamp[lamp >= 0]):
        pts = scene.corners[lamp == k].reshape(-1, 3)
        c = 0.5 * (pts.min(0) + pts.max(0))
        out.append((int(k), c, float(np.linalg.norm(pts - c, axis=1).max()), None, 0.0))
    return out


def _angle(a, b):
    cos = safe_div(np.einsum("ij,ij->i", a, b),
                   np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1))
    return np.arccos(np.clip(cos, -1.0, 1.0))


def may_be_shadowed(scene, texel_map, triangles, margin=1.25):
    """(T,) bool, conservative: texels where some lamp's bounding sphere, seen from the texel
    (grown by its footprint), can be hidden by the bounding sphere of ``triangles``."""
    x, _ = texel_points(scene, texel_map)
    # a texel's footprint: the patch's area shared by its texels
    patch = texel_map.patch
    area = scene.area_normal()[0]
    per = np.bincount(patch, minlength=len(area))
    foot = np.sqrt(area[patch] / np.maximum(per[patch], 1))
    return may_be_shadowed_at(scene, x, foot, triangles, margin)


def may_be_shadowed_at(scene, x, foot, triangles, margin=1.25):
    """(n,) bool, conservative: points ``x`` (n, 3) with a footprint of radius ``foot`` (n,)
    where some lamp of ``scene``, seen from the point, can be hidden by the bounding sphere of
    ``triangles``."""
    tri = np.asarray(triangles, float).reshape(-1, 3)
    c = 0.5 * (tri.min(0) + tri.max(0))
    R = margin * float(np.linalg.norm(tri - c, axis=1).max()) + foot
    to_c = c - x
    d_c = np.linalg.norm(to_c, axis=1)
    half_obj = np.arcsin(np.clip(safe_div(R, d_c), 0.0, 1.0))
    out = d_c <= R
    for _, centre, r, sun, sun_half in _lamp_spheres(scene):
        if sun is not None:
            out |= _angle(to_c, np.broadcast_to(sun, x.shape)) <= half_obj + sun_half
            continue
        to_l = centre - x
        d_l = np.linalg.norm(to_l, axis=1)
        half_lamp = np.arcsin(np.clip(safe_div(r + foot, d_l), 0.0, 1.0))
        out |= (d_c - R < d_l) & (_angle(to_c, to_l) <= half_obj + half_lamp)
    return out


def object_visibility(scene, texel_map, triangles, rays=RAYS, samples=SAMPLES,
                      seed=0) -> np.ndarray:
    """(T, k) part of each lamp's direct light on the texels of ``texel_map`` (averaged over
    each texel's footprint, as a photo texel and the maps average it) that passes the
    ``triangles`` (t, 3, 3, world); 1 where a lamp gives no light or cannot be hidden."""
    T, k = texel_map.n_texels, scene.n_lamps
    V = np.ones((T, k))
    if T == 0 or len(triangles) == 0:
        return V
    mask = may_be_shadowed(scene, texel_map, triangles)
    if not mask.any():
        return V
    occluder = make_occluder(np.asarray(triangles, float))
    U, O = TexelLight(scene, texel_subset(texel_map, mask), occluder, rays, samples, seed).direct()
    u, o = U @ LUMINANCE, O @ LUMINANCE
    lit = u > UNLIT * max(float(u.max(initial=0.0)), 1e-300)
    sub = np.ones(u.shape)
    sub[lit] = np.clip(o[lit] / u[lit], 0.0, 1.0)
    V[mask] = sub
    return V


def visibility_images(texel_map, V, seam_pixels=SEAM_PIXELS) -> list:
    """Per image of ``texel_map``, (H, W, k) float32 of the per-texel ``V`` (T, k): 1 where no
    face is, dilated across UV seams as the maps are (bilinear filtering at a seam must not
    pull the fill's 1 into a shadow)."""
    out = []
    for v, im in zip(texel_map.scatter(np.asarray(V, np.float32), fill=1.0), texel_map.images):
        if im.coverage.any() and float(v.min(initial=1.0)) < 1.0:
            v, _ = dilate_seams(v, im.coverage, seam_pixels)
        out.append(v)
    return out
