"""Which side of each face is the photographed one, and faces lit on both sides.

The core's patches are one-sided: a face receives and reflects light on the side its normal
points to.  Cycles shades both sides of a diffuse face in a render, so a model from another
program can have faces turned any way and still look right; a room shell whose normals point
out of the room would receive no light at all here.  Before the precompute every non-lamp face
is looked at from both sides:

* its lamps' direct light on each side (lamp_irradiance at five points of the face, with
  visibility, every lamp at its scene intensity);
* whether the camera (the scene's viewpoint) sees that side;
* how open the side is: the fraction of cosine-distributed rays from it that leave the scene
  without hitting anything (the outside of a room shell is open, its inside is not).

The side the camera sees (and only that one) is the photographed side.  A face the camera sees
from neither side (or both) is turned round when its back is lit (above DIM_LIGHT of a typical
face's light) at least twice as brightly as its front, or (unlit, in a scene without a camera)
when its front is open while its back is enclosed.  Light on the outside of the room (an open
side, e.g. a sun on the roof) does not count.  A face lit on both sides (each at least TWO_SIDED_SHARE of the other,
the photographed side being the front) also gets a back: a copy facing the other way that
reflects light with the front's reflectance but has no texels of its own (the photo shows one
side).  Faces lit only indirectly on their back (a table top's underside) stay one-sided.

A closed object modelled inside out (a box whose normals point in) shows its inside to its own
faces: most rays from a face's front meet the face's own object (OWN_SHARE), few from its
back.  Such a face, where neither the camera nor the lamps decide, is turned round (its
outside is what the photo shows), and a face whose back is a closed object's inside is never
turned to it, however that inside is lit (a lamp in a box); the room the camera stands in is
no such object (enclosure.py).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geometry.extent import bounding_diagonal
from ..geometry.patch import bilinear_point, reverse_winding
from ..geometry.raycast import ray_offset
from ..progress import tick
from ..scene import SceneData
from ..texture.colour import luminance
from .direct import lamp_irradiance
from .enclosure import enclosing_group

TWO_SIDED_SHARE = 0.15
DIM_LIGHT = 0.01
OPEN_RAYS = 16
# of a side's rays meeting the face's own object: its inside.  Not 0.9: a box standing on the
# floor has its bottom where the floor is, and the rays from its inside towards the bottom meet
# the floor's coincident face about as often as the bottom (a 0.4 m box's sides: 0.75-0.88 of
# their rays met the box; which faces passed 0.9 hung on the rays' seed)
OWN_SHARE = 0.7
LIGHT_RAYS = 8
CHUNK = 1 << 15         # faces looked at at once
_PROBES = np.array([[0.5, 0.5], [0.15, 0.15], [0.85, 0.15], [0.85, 0.85], [0.15, 0.85]])


@dataclass
class Orientation:
    """What ``orient`` did: ``scene`` (faces turned round, backs appended after the input's
    patches), ``flipped`` (p,) bool over the input's patches, ``back_of`` (b,) the input patch
    each appended back belongs to."""
    scene: SceneData
    flipped: np.ndarray
    back_of: np.ndarray

    def per_group(self, which):
        """{group: count} of the input's flipped patches (``"flipped"``) or of the patches that
        got a back (``"two_sided"``)."""
        group = np.asarray(self.scene.group)
        ids = np.flatnonzero(self.flipped) if which == "flipped" else self.back_of
        g, c = np.unique(group[ids], return_counts=True)
        return {int(a): int(b) for a, b in zip(g, c)}


def _cosine_directions(normals, n, rng):
    """(p, n, 3) cosine-distributed directions around each normal."""
    a = np.where(np.abs(normals[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t1 = np.cross(a, normals)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(normals, t1)
    u, v = rng.random((len(normals), n)), rng.random((len(normals), n))
    r, ph = np.sqrt(u), 2 * np.pi * v
    z = np.sqrt(np.maximum(1 - u, 0.0))
    return (r * np.cos(ph))[..., None] * t1[:, None] + (r * np.sin(ph))[..., None] * t2[:, None] \
        + z[..., None] * normals[:, None]


def side_evidence(scene: SceneData, occluder, patches, seed=0):
    """Per patch of ``patches``: (lit (p, 2), camera (p, 2) bool, open (p, 2)) for its front
    (column 0) and back (column 1).  Looked at CHUNK faces at a time: a scan's 200k faces'
    rays at once held 620 MB (benchmarks/results/scan.md)."""
    rng = np.random.default_rng(seed)
    _, normal = scene.area_normal()
    size = bounding_diagonal(scene.corners)
    eps = ray_offset(size)
    patches = np.asarray(patches)
    lit = np.zeros((len(patches), 2))
    camera = np.zeros((len(patches), 2), bool)
    openness = np.zeros((len(patches), 2))
    own = np.zeros((len(patches), 2))
    for first in range(0, len(patches), CHUNK):
        tick(first / max(len(patches), 1))
        part = slice(first, first + CHUNK)
        _evidence(scene, occluder, patches[part], normal, size, eps, rng,
                  seed + 2 * (first // CHUNK), lit[part], camera[part], openness[part],
                  own[part])
    return lit, camera, openness, own


def _evidence(scene, occluder, patches, normal, size, eps, rng, seed, lit, camera, openness,
              own):
    """side_evidence for one chunk of faces, written into ``lit``, ``camera``, ``openness``
    and ``own`` (the share of a side's rays that meet the face's own object first)."""
    c = scene.corners[patches]
    n = normal[patches]
    pts = bilinear_point(c[:, None], _PROBES[None, :, 0], _PROBES[None, :, 1])     # (p, 5, 3)
    centre = pts[:, 0]
    for side, sign in ((0, 1.0), (1, -1.0)):
        nn = sign * n
        _, O = lamp_irradiance(scene, pts + eps * nn[:, None], nn, occluder, LIGHT_RAYS,
                               seed + side)
        lit[:, side] = luminance((O * scene.lamp_intensity[None, :, None]).sum(axis=1))
        if scene.viewpoint is not None:
            vp = np.asarray(scene.viewpoint, float)
            facing = np.einsum("ij,ij->i", vp[None] - centre, nn) > 0
            seen = facing.copy()
            if occluder is not None and facing.any():
                seen[facing] = ~occluder.segments_occluded(centre[facing] + eps * nn[facing],
                                                           np.broadcast_to(vp, centre[facing].shape))
            camera[:, side] = seen
        if occluder is not None:
            d = _cosine_directions(nn, OPEN_RAYS, rng)                          # (p, r, 3)
            o = np.repeat(centre + eps * nn, OPEN_RAYS, axis=0)
            hit, prim = occluder.first_hit(o, d.reshape(-1, 3), tmax=4 * size)
            openness[:, side] = (~np.isfinite(hit)).reshape(-1, OPEN_RAYS).mean(axis=1)
            faces_of = getattr(occluder, "patch_of_triangle", None)
            if faces_of is not None:
                group = np.asarray(scene.group)
                met = np.where(prim >= 0, group[faces_of[np.maximum(prim, 0)]], -1)
                mine = met.reshape(-1, OPEN_RAYS) == group[patches][:, None]
                own[:, side] = mine.mean(axis=1)


def orient(scene: SceneData, occluder, seed=0) -> Orientation:
    """Turn faces to their photographed side and give faces lit on both sides a back (see
    the module docstring)."""
    faces = np.flatnonzero(scene.lamp < 0)
    p = scene.n_patches
    if len(faces) == 0:
        return Orientation(scene, np.zeros(p, bool), np.zeros(0, np.int64))
    lit, camera, openness, own = side_evidence(scene, occluder, faces, seed)
    # The outside of a room (rays from it leave the scene) is not a side anyone photographed,
    # even where a sun lights it: its light does not count.
    outside = openness > 0.5
    lit = np.where(outside & ~outside[:, ::-1], 0.0, lit)
    peak = lit.max(axis=1)
    # direct light below DIM_LIGHT of a typical lit face's is noise, not a lit side
    floor = DIM_LIGHT * float(np.percentile(peak, 90)) if len(peak) else 0.0
    some = peak > floor
    back_lit = some & (lit[:, 1] > 2.0 * lit[:, 0])
    seen_back = camera[:, 1] & ~camera[:, 0]
    seen_front = camera[:, 0] & ~camera[:, 1]
    unlit = ~some
    # Without a camera, openness decides for unlit faces (with one it is not needed, and a face
    # lying on another -- a box's bottom on the floor -- looks open from below).
    back_enclosed = unlit & (scene.viewpoint is None) & outside[:, 0] & ~outside[:, 1]
    # a closed object's inside faces its own faces (not the room the camera is in)
    room = enclosing_group(scene, occluder, scene.viewpoint) if scene.viewpoint is not None \
        else None
    not_room = np.asarray(scene.group)[faces] != (-1 if room is None else room)
    inside_out = (own[:, 0] >= OWN_SHARE) & (own[:, 1] < 1.0 - OWN_SHARE) & not_room
    inside_back = (own[:, 1] >= OWN_SHARE) & (own[:, 0] < 1.0 - OWN_SHARE) & not_room
    # The side the camera sees is the photographed one; else the lit side, but never a closed
    # object's inside (a lamp in a box lights that, not what the photo shows); else the
    # outside of a closed object; else the inside.
    flip = np.where(seen_back | seen_front, seen_back,
                    ((back_lit | back_enclosed) & ~inside_back)
                    | (inside_out & ~(some & ~back_lit)))
    both = some & (lit.min(axis=1) >= TWO_SIDED_SHARE * peak)
    flipped = np.zeros(p, bool)
    flipped[faces[flip]] = True
    back_of = faces[both]
    if not flipped.any() and len(back_of) == 0:
        return Orientation(scene, flipped, back_of)
    new = object.__new__(SceneData)
    new.__dict__.update(scene.__dict__)
    corners = scene.corners.copy()
    corners[flipped] = reverse_winding(scene.corners[flipped])
    uv = None
    if scene.uv is not None:
        uv = scene.uv.copy()
        uv[flipped] = reverse_winding(scene.uv[flipped])
    b = len(back_of)
    new.corners = np.concatenate([corners, reverse_winding(corners[back_of])])
    new.rho = np.concatenate([scene.rho, scene.rho[back_of]])
    new.emission = np.concatenate([scene.emission, np.zeros((b, 3))])
    new.lamp = np.concatenate([scene.lamp, np.full(b, -1, scene.lamp.dtype)])
    new.occluder = np.concatenate([scene.occluder, np.zeros(b, bool)])   # the front blocks
    new.group = np.concatenate([scene.group, scene.group[back_of]])
    new.virtual = np.concatenate([scene.virtual, scene.virtual[back_of]])
    if uv is not None:
        new.uv = np.concatenate([uv, reverse_winding(uv[back_of])])
    if scene.image is not None:
        new.image = np.concatenate([scene.image, np.full(b, -1, scene.image.dtype)])
    return Orientation(new, flipped, back_of)
