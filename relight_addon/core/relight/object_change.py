"""What virtual objects change in a solved room, computed only where they can change it.

Seed 000 §4.4.2 inserts an object by dynamic hierarchical radiosity: only the links whose shaft
meets the object are tested again.  Here the room's solution is kept whole and each lamp's
irradiance gains the object's change, cast only in the directions and at the places the object
can reach:

* direct light per texel: the texels whose view of a lamp can meet an object's bounding sphere
  (``settled.may_be_shadowed``) are cast past the room and the objects, with the same rays as
  past the room alone; the difference is the object's shadow;
* indirect light per leaf: rays from the leaf into each object's bounding cone (the only
  directions in which its view changes) replace, where they meet the object first, the room's
  solved radiosity behind it by the object's own.  The object's radiosity is one gather: the
  lamps' direct light on it and the room's radiosity seen by cosine rays, with the object's own
  shadow on the room taken off where they meet it (its underside sees the floor it shades),
  and a second bounce between objects;
* lamps that are not patches are cast again on the leaves that can be in an object's shadow;
* that change of every leaf's irradiance, times its reflectance, propagates through the room's
  own transport (one solve per lamp), and is read at the texels as the indirect light is;
* near an object (a few bounding radii) the leaves are too coarse for what changes there: a
  contact's dark ring is a few centimetres wide, and a wall beside an object sees the floor in
  its shadow.  There the texels cast their own rays into the object's cone and over their
  hemisphere (the room in the objects' shadows), and that replaces what they read of the
  leaves' object term and first bounce;
* the object and the room near it see each other in their change (a sphere's underside sees
  the floor it darkens, which sees it): the objects' radiosity and the texels near them are
  gathered again along the same rays, from the room's whole change of the first gather, and
  the room they see is read per texel (the maps' light there), not per leaf.

The maps gain (direct change + indirect change) / D, D the irradiance the photo was lit by, so
they are untouched where the objects change nothing.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np

from ..geometry.patch import bilinear_point
from ..geometry.raycast import make_occluder, ray_offset
from ..geometry.sampling import cosine_directions, quadrature, random_points, \
    stratified_unit_square
from ..lights import light_irradiance
from ..radiosity.precompute import lights_on_elements
from ..texture.mapping import inverse_bilinear, inverse_triangle, texel_subset
from .direct import lamp_irradiance
from .settled import may_be_shadowed, may_be_shadowed_at
from .texel import footprint_points, texel_footprint_cells
from .transport import Transport

CONE_RAYS = 64          # per texel near an object and object, into the object's bounding cone
# per leaf and object: the leaves' change travels through the room's transport, which
# smooths it, and near the objects the texels' own rays replace it
LEAF_RAYS = 32
FACE_RAYS = 32          # per side of an object face, gathering the room's radiosity (office: 128
                        # gave the same shadows within 0.07 CIEDE2000 for 0.3 s more)
FACE_RAY_BUDGET = 1 << 18   # rays over all the objects' faces (a dense mesh: fewer per face)
MIN_SOLID_ANGLE = 1e-3  # sr: an object seen smaller than this from a leaf changes nothing there
# points per texel side for the objects' shadows (the maps' direct light has 2: a 10 cm texel
# at a box's shadow edge needs more; office, box at its second position: 3.62 -> 3.16 CIEDE2000
# in its shadow with 4); at most half the texel rays: a lamp's first rays meet every point
FOOTPRINT = 4
SHADE_RAYS = 8          # per lamp, from a room point an object's face sees (each face sees many)
OBJECT_BOUNCES = 2      # gathers of the objects' radiosity (the second adds object to object)
# bounding radii from an object's centre within which its change of the indirect light is cast
# per texel (NEAR_IN), and past which the leaves' is read alone (NEAR_OUT); linear between
NEAR_IN, NEAR_OUT = 2.5, 3.5
NEAR_PASSES = 2         # gathers near the objects (the second sees the first's whole change)
# within NEAR_DENSE bounding radii of an object a texel casts CONE_RAYS rays, past it (where the
# change is small, and its noise with it) CONE_RAYS // FAR_SHARE
NEAR_DENSE, FAR_SHARE = 1.6, 4


class EitherOccluder:
    """Segments blocked by the room (may be None) or by the objects."""

    def __init__(self, room, objects):
        self.room, self.objects = room, objects

    def segments_occluded(self, origins, ends, *args, **kwargs):
        out = np.asarray(self.objects.segments_occluded(origins, ends), bool).copy()
        free = np.flatnonzero(~out)
        if self.room is not None and len(free):
            out[free] = self.room.segments_occluded(np.asarray(origins)[free],
                                                    np.asarray(ends)[free])
        return out


class ObjectsOnlyOccluder:
    """Segments the objects block and the room does not: lit through such an occluder, a lamp's
    occluded light is its unoccluded light minus what the objects take away (the room's own
    shadows are left out), so one cast gives the change.  The room is tested only on the few
    segments the objects block."""

    def __init__(self, room, objects):
        self.room, self.objects = room, objects

    def segments_occluded(self, origins, ends, *args, **kwargs):
        out = np.asarray(self.objects.segments_occluded(origins, ends), bool).copy()
        hit = np.flatnonzero(out)
        if self.room is not None and len(hit):
            out[hit] = ~np.asarray(self.room.segments_occluded(np.asarray(origins)[hit],
                                                               np.asarray(ends)[hit]), bool)
        return out


@dataclass
class VirtualObjects:
    """The virtual objects' faces (their patches of a scene, in order) and bounding spheres."""
    corners: np.ndarray      # (n, 4, 3)
    normal: np.ndarray       # (n, 3)
    rho: np.ndarray          # (n, 3)
    owner: np.ndarray        # (n,) object index of each face
    centre: np.ndarray       # (m, 3)
    radius: np.ndarray       # (m,)
    triangles: np.ndarray    # (t, 3, 3)
    occluder: object         # ray caster of the triangles; patch_of_triangle: face index

    @staticmethod
    def of(scene, extra: slice) -> "VirtualObjects":
        ids = np.arange(extra.start, extra.stop)
        _, normal = scene.area_normal()
        tris, patches = scene.occluder_triangles(with_patches=True)
        keep = (patches >= extra.start) & (patches < extra.stop)
        tris, faces = tris[keep], patches[keep] - extra.start
        groups, owner = np.unique(scene.group[ids], return_inverse=True)
        centre = np.zeros((len(groups), 3))
        radius = np.zeros(len(groups))
        for o in range(len(groups)):
            pts = scene.corners[ids[owner == o]].reshape(-1, 3)
            centre[o] = 0.5 * (pts.min(0) + pts.max(0))
            radius[o] = np.linalg.norm(pts - centre[o], axis=1).max()
        occluder = make_occluder(tris) if len(tris) else None
        if occluder is not None:
            occluder.patch_of_triangle = faces
        return VirtualObjects(scene.corners[ids], normal[ids], scene.rho[ids], owner, centre,
                              radius, tris, occluder)


def _leaf_lookup(sol):
    """Hit point on a patch of the solution -> index of the leaf there (in ``sol.leaves``)."""
    h = sol.hierarchy
    slot = np.full(h.n, -1, np.int64)
    slot[sol.leaves] = np.arange(len(sol.leaves))
    corners = sol.scene.corners

    def lookup(patch, x, with_uv=False):
        c = corners[patch]
        n = h.normal[patch]
        e1 = c[:, 1] - c[:, 0]
        e1 /= np.maximum(np.linalg.norm(e1, axis=1, keepdims=True), 1e-300)
        e2 = np.cross(n, e1)
        rel = c - c[:, :1]
        c2 = np.stack([np.einsum("nij,nj->ni", rel, e1), np.einsum("nij,nj->ni", rel, e2)], -1)
        q = x - c[:, 0]
        q2 = np.stack([np.einsum("ij,ij->i", q, e1), np.einsum("ij,ij->i", q, e2)], -1)
        tri = np.all(c[:, 2] == c[:, 3], axis=-1)
        u = np.full(len(patch), 0.5)
        v = np.full(len(patch), 0.5)
        if (~tri).any():
            u[~tri], v[~tri], _ = inverse_bilinear(c2[~tri], q2[~tri])
        if tri.any():
            u[tri], v[tri] = inverse_triangle(c2[tri], q2[tri])[:2]
        u = np.clip(np.nan_to_num(u, nan=0.5), 0.0, 1.0)
        v = np.clip(np.nan_to_num(v, nan=0.5), 0.0, 1.0)
        leaf = slot[h.locate(patch, u, v)]
        return (leaf, u, v) if with_uv else leaf
    return lookup


class TexelChange:
    """Per-texel values (k, T, 3) of a texel map of the solution's own patches, read at points
    given by (patch, u, v): the texel whose square holds the point's texture coordinates."""

    def __init__(self, scene, tm, values):
        self.values = values
        self.uv, self.image = scene.uv, scene.image
        self.parts = []
        for start, im in zip(tm.offsets[:-1], tm.images):
            order = np.argsort(im.texel_index, kind="stable")
            self.parts.append((np.asarray(im.texel_index)[order], start + order, im.shape))

    def with_values(self, values):
        """The same texels holding ``values`` (k, T, 3)."""
        new = copy.copy(self)
        new.values = values
        return new

    def at(self, patch, u, v):
        """(k, m, 3) the values at the points, and (m,) whether a texel holds each."""
        out = np.zeros((self.values.shape[0], len(patch), 3))
        found = np.zeros(len(patch), bool)
        if self.uv is None or self.image is None or not len(patch):
            return out, found
        uv = bilinear_point(self.uv[patch][:, None], u[:, None], v[:, None])[:, 0]
        image = self.image[patch]
        for i, (pixels, texel, (H, W)) in enumerate(self.parts):
            rows = np.flatnonzero(image == i)
            if not len(rows) or not len(pixels):
                continue
            x = np.clip((uv[rows, 0] * W).astype(np.int64), 0, W - 1)
            y = np.clip((uv[rows, 1] * H).astype(np.int64), 0, H - 1)
            want = y * W + x
            at = np.minimum(np.searchsorted(pixels, want), len(pixels) - 1)
            ok = pixels[at] == want
            out[:, rows[ok]] = self.values[:, texel[at[ok]]]
            found[rows[ok]] = True
        return out, found


def _room_radiosity_along(sol, room, lookup, origins, directions, before=None, hits=False,
                          lit=None):
    """(k, n, 3) solved room radiosity first met along each ray (0 where none, and where the
    room is met no nearer than ``before`` (n,): hidden by something else), the distance to it,
    and whether it is a lamp patch; with ``hits`` also the rays whose radiosity is read and the
    leaf (in ``sol.leaves``) each meets.  ``lit``: a TexelChange of each lamp's irradiance per
    texel, as the maps have it; where a texel holds a (non-lamp) hit, its radiosity is the
    leaf's reflectance times that texel's light, not the leaf's mean (a floor leaf across a
    table's shadow edge is lit on average, the floor under the table is not)."""
    k = len(sol.basis)
    t, prim = room.first_hit(origins, directions) if room is not None else \
        (np.full(len(origins), np.inf), np.full(len(origins), -1))
    B = np.zeros((k, len(origins), 3))
    lamp = np.zeros(len(origins), bool)
    hit = np.flatnonzero((prim >= 0) if before is None else (prim >= 0) & (t < before))
    leaf = np.zeros(0, np.int64)
    if len(hit):
        patch = room.patch_of_triangle[prim[hit]]
        x = origins[hit] + t[hit, None] * directions[hit]
        if lit is None:
            leaf = lookup(patch, x)
        else:
            leaf, u, v = lookup(patch, x, with_uv=True)
        B[:, hit] = sol.basis[:, leaf]
        lamp[hit] = sol.scene.lamp[patch] >= 0
        if lit is not None:
            own = np.flatnonzero(~lamp[hit])
            H, found = lit.at(patch[own], u[own], v[own])
            at = own[found]
            B[:, hit[at]] = H[:, found] * np.asarray(sol.system.rho, float)[leaf[at]][None]
    return (B, t, lamp, hit, leaf) if hits else (B, t, lamp)


class _RoomSeen:
    """Points ``p`` (m, 3) of the room's patches ``patch`` met by rays of ``directions``: the
    change of their radiosity (k, m, 3) for a per-texel change of the irradiance (a
    TexelChange on the maps' texels: the objects' direct shadows, or their whole change): the
    reflectance of the leaf there times the change at the texel that holds the point; where no
    texel holds it, the objects' direct shadow cast (SHADE_RAYS rays per lamp) where an object
    can shadow the point; 0 on lamp patches and on a face's back.  The casting and the lookups
    are done once; :meth:`change` reads any change on the same texels."""

    def __init__(self, objects: VirtualObjects, sol, room, lookup, p, patch, directions, scale,
                 seed, texels=None):
        self.k, self.m = len(sol.basis), len(p)
        self.near = np.zeros(0, np.int64)
        if not len(p):
            return
        n = sol.hierarchy.normal[patch]
        self.near = near = np.flatnonzero((sol.scene.lamp[patch] < 0)
                                          & (np.einsum("ij,ij->i", n, directions) < 0))
        if not len(near):
            return
        leaf, self.u, self.v = lookup(patch[near], p[near], with_uv=True)
        self.patch = patch[near]
        self.rho = np.asarray(sol.system.rho, float)[leaf]                       # (m, 3)
        found = np.zeros(len(near), bool) if texels is None else \
            texels.at(self.patch, self.u, self.v)[1]
        cast = np.flatnonzero(~found)
        self.cast = cast[may_be_shadowed_at(sol.scene, p[near[cast]], np.zeros(len(cast)),
                                            objects.triangles)]
        self.cast_dE = np.zeros((self.k, len(self.cast), 3))
        if len(self.cast):
            s = np.ones(self.k) if sol.emission_scale is None else \
                np.asarray(sol.emission_scale, float)
            whole, past = lamp_irradiance(sol.scene, p[near[self.cast]], n[near[self.cast]],
                                          ObjectsOnlyOccluder(room, objects.occluder),
                                          SHADE_RAYS, int(seed), offset=ray_offset(scale))
            self.cast_dE = np.moveaxis((past - whole) * s[None, :, None], 1, 0)

    def change(self, texels=None):
        out = np.zeros((self.k, self.m, 3))
        if not len(self.near):
            return out
        dE = np.zeros((self.k, len(self.near), 3)) if texels is None else \
            texels.at(self.patch, self.u, self.v)[0]
        dE[:, self.cast] = self.cast_dE
        out[:, self.near] = dE * self.rho[None]
        return out


def _shadow_on_room(objects: VirtualObjects, sol, room, lookup, p, patch, directions, scale,
                    seed, texels=None):
    """(k, m, 3) :class:`_RoomSeen` ``change`` of the points ``p`` for ``texels``."""
    return _RoomSeen(objects, sol, room, lookup, p, patch, directions, scale, seed,
                     texels).change(texels)


def _per_face(face, values, n):
    """Sum over the rays of each face: (k, rays, 3) -> (k, n, 3)."""
    return np.stack([np.stack([np.bincount(face, values[j, :, c], n) for c in range(3)], -1)
                     for j in range(len(values))])


class ObjectRadiosity:
    """The radiosity of both sides (front, back) of every object face per lamp: its reflectance
    times the lamps' direct light on that side (``sol.scene.lights``) and the room's radiosity
    it sees (lamp patches included; ``lit``: per texel where a texel holds the point), with
    ``OBJECT_BOUNCES`` gathers between the objects.  A closed mesh's backs face its inside and
    come out dark; an open one (a plane) shows its back lit, as Cycles renders it.  The rays
    are cast once; calling it with a change of the room's light per texel (``texels``, a
    TexelChange) gives (2, k, n, 3) with the room seen in that change: an object seen from its
    own faces is mostly the room near it, which is in its shadow (a sphere's underside sees the
    floor where the sphere shades it, not the lit floor of the photo)."""

    def __init__(self, objects: VirtualObjects, sol, room, lookup, scale, rays, seed,
                 texels=None, lit=None):
        k = self.k = len(sol.basis)
        n = self.n = len(objects.corners)
        self.objects = objects
        rng = np.random.default_rng([int(seed), 0x0B1])
        s = np.ones(k) if sol.emission_scale is None else np.asarray(sol.emission_scale, float)
        offset = ray_offset(scale)
        pts, _ = quadrature(objects.corners, 2)                               # (n, 4, 3)
        per = max(1, min(FACE_RAYS, FACE_RAY_BUDGET // max(2 * n, 1)) // pts.shape[1])
        self.face = face = np.repeat(np.arange(n), pts.shape[1] * per)
        self.sides = []
        for sign in (1.0, -1.0):
            normal = sign * objects.normal
            H = np.zeros((k, n, 3))
            lights = sol.scene.lights
            if len(lights):
                _, O = light_irradiance(lights, pts, normal,
                                        EitherOccluder(room, objects.occluder), rays,
                                        int(rng.integers(2**31)), scale, offset)
                for i, lamp in enumerate(lights.lamp):
                    H[lamp] += O[:, i] * s[lamp]
            nrm = normal[face]
            x1, x2 = stratified_unit_square(len(pts.reshape(-1, 3)), per, rng)
            d = cosine_directions(nrm, x1.reshape(-1, 1), x2.reshape(-1, 1))
            o = np.repeat(pts.reshape(-1, 3), per, axis=0) + offset * nrm
            t_obj, prim = objects.occluder.first_hit(o, d)
            t_obj = np.where(prim >= 0, t_obj, np.inf)
            B_room, t_room, _, hit, leaf = _room_radiosity_along(sol, room, lookup, o, d, t_obj,
                                                                 hits=True, lit=lit)
            seen = _RoomSeen(objects, sol, room, lookup, o[hit] + t_room[hit, None] * d[hit],
                             sol.hierarchy.patch[sol.leaves[leaf]], d[hit], scale,
                             rng.integers(2**31), texels)
            other = objects.occluder.patch_of_triangle[np.maximum(prim, 0)]
            obj_first = (prim >= 0) & (t_obj < t_room)
            other_front = np.einsum("ij,ij->i", d, objects.normal[other]) < 0
            self.sides.append((H, _per_face(face, B_room, n), face[hit], seen, obj_first, other,
                               other_front))
        self.count = np.bincount(face, minlength=n).astype(float)[None, :, None]

    def __call__(self, texels=None):
        k, n, face, count, rho = self.k, self.n, self.face, self.count, self.objects.rho
        sides = [(H, G + _per_face(at, seen.change(texels), n), *rest)
                 for H, G, at, seen, *rest in self.sides]
        B = np.stack([rho[None] * (H + G / count) for H, G, *_ in sides])
        for _ in range(OBJECT_BOUNCES - 1):
            new = []
            for H, G, obj_first, other, other_front in sides:
                src = np.zeros((k, len(face), 3))
                hit = np.flatnonzero(obj_first)
                src[:, hit] = np.where(other_front[hit][None, :, None], B[0][:, other[hit]],
                                       B[1][:, other[hit]])
                new.append(rho[None] * (H + (G + _per_face(face, src, n)) / count))
            B = np.stack(new)
        return B


def object_radiosity(objects: VirtualObjects, sol, room, lookup, scale, rays, seed, texels=None,
                     lit=None):
    """(2, k, n, 3) :class:`ObjectRadiosity` of the objects with the room in ``texels``."""
    return ObjectRadiosity(objects, sol, room, lookup, scale, rays, seed, texels, lit)(texels)


def _cone_directions(axis, cos_max, x1, x2):
    """Uniform unit directions in the cones of half-angle arccos(cos_max) around ``axis``."""
    helper = np.where(np.abs(axis[:, :1]) < 0.9, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    t1 = np.cross(axis, helper)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(axis, t1)
    cos_t = 1.0 - x1 * (1.0 - cos_max)
    sin_t = np.sqrt(np.maximum(1.0 - cos_t ** 2, 0.0))
    phi = 2.0 * np.pi * x2
    return (sin_t * np.cos(phi))[:, None] * t1 + (sin_t * np.sin(phi))[:, None] * t2 \
        + cos_t[:, None] * axis


def _cone_rays(c, R, o, n_o, x1, x2, rays):
    """One ray per origin ``o`` (n, 3) (normals ``n_o``) into the bounding cone of the sphere
    (c, R), from uniform numbers ``x1``, ``x2`` (n,): its directions and weights (the cone's
    solid angle x cosine / pi over ``rays``, the rays an origin's group casts; from within the
    sphere the whole hemisphere, cosine-distributed)."""
    to = c - o
    d_o = np.linalg.norm(to, axis=1)
    inside = d_o <= R
    cos_max = np.sqrt(np.maximum(1.0 - (R / np.maximum(d_o, 1e-300)) ** 2, 0.0))
    d = _cone_directions(to / np.maximum(d_o, 1e-300)[:, None], cos_max, x1, x2)
    cos_n = np.einsum("ij,ij->i", d, n_o)
    w = 2.0 * np.pi * (1.0 - cos_max) / rays * np.maximum(cos_n, 0.0) / np.pi
    if inside.any():
        d[inside] = cosine_directions(n_o[inside], x1[inside, None], x2[inside, None])
        w[inside] = 1.0 / rays
    return d, w


class _ConeHits:
    """The rays (o, d, w) of groups ``which`` (r,) in 0..n-1 cast into object ``obj``'s cone
    that meet that object before the room (cast once); :meth:`sums` gives, for the objects'
    radiosity ``B_obj``, per group (k, n, 3) what the object shows minus the room's radiosity
    it hides (lamp patches left out), and (k, n, 3) the lamp patches' radiosity it hides
    (their direct light)."""

    def __init__(self, objects: VirtualObjects, obj, sol, room, lookup, o, d, w, which, n,
                 lit=None):
        self.k, self.n = len(sol.basis), n
        live = np.flatnonzero(w > 0)
        o, d, w, which = o[live], d[live], w[live], which[live]
        t_obj, prim = objects.occluder.first_hit(o, d)
        face = objects.occluder.patch_of_triangle[np.maximum(prim, 0)]
        # a ray counts for the object whose cone it was cast in (another's cone covers the rest)
        mine = (prim >= 0) & (objects.owner[face] == obj)
        B_room, t_room, lamp = _room_radiosity_along(sol, room, lookup, o[mine], d[mine],
                                                     lit=lit)
        first = t_obj[mine] < t_room
        idx = np.flatnonzero(mine)[first]
        B_room, lamp = B_room[:, first], lamp[first]
        self.face = face[idx]
        self.front = np.einsum("ij,ij->i", d[idx], objects.normal[self.face]) < 0
        # what the object shows replaces what was behind it (a lamp patch: direct light)
        self.behind_lamp = np.where(lamp[None, :, None], B_room, 0.0)
        self.behind_rest = B_room - self.behind_lamp
        self.w, self.at = w[idx], which[idx]

    def sums(self, B_obj):
        k, n = self.k, self.n
        ind, lamp_lost = np.zeros((k, n, 3)), np.zeros((k, n, 3))
        gain = np.where(self.front[None, :, None], B_obj[0][:, self.face],
                        B_obj[1][:, self.face])
        for j in range(k):
            for ch in range(3):
                ind[j, :, ch] = np.bincount(self.at, self.w * (gain[j, :, ch]
                                                               - self.behind_rest[j, :, ch]), n)
                lamp_lost[j, :, ch] = np.bincount(self.at, self.w * self.behind_lamp[j, :, ch],
                                                  n)
        return ind, lamp_lost


def _seen_through_cone(objects: VirtualObjects, obj, B_obj, sol, room, lookup, o, d, w, which,
                       n, lit=None):
    """:class:`_ConeHits` ``sums`` of the rays for ``B_obj``."""
    return _ConeHits(objects, obj, sol, room, lookup, o, d, w, which, n, lit).sums(B_obj)


def leaf_change(objects: VirtualObjects, B_obj, sol, room, lookup, scale, seed,
                rays=LEAF_RAYS):
    """Change of every leaf's irradiance per lamp (k, L, 3) where it sees an object (``B_obj``
    (2, k, n, 3): its faces' fronts and backs): (from lamp patches, from the rest), both at the
    solution's exitance factors."""
    h = sol.hierarchy
    leaves = sol.leaves
    k, L = len(sol.basis), len(leaves)
    d_dir, d_ind = np.zeros((k, L, 3)), np.zeros((k, L, 3))
    rng = np.random.default_rng([int(seed), 0xC0E])
    x = h.centroid[leaves]
    nrm = h.normal[leaves]
    r_leaf = np.linalg.norm(h.corners[leaves] - x[:, None], axis=2).max(axis=1)
    offset = ray_offset(scale)
    for obj in range(len(objects.radius)):
        c, R = objects.centre[obj], objects.radius[obj]
        to_c = c - x
        dist = np.linalg.norm(to_c, axis=1)
        sin_a = np.clip(R / np.maximum(dist - r_leaf, 1e-300), 0.0, 1.0)
        solid = 2.0 * np.pi * (1.0 - np.sqrt(1.0 - sin_a ** 2))
        sel = np.flatnonzero((np.einsum("ij,ij->i", nrm, to_c) > -(R + r_leaf))
                             & ((dist <= R + r_leaf) | (solid > MIN_SOLID_ANGLE)))
        if not len(sel):
            continue
        o = random_points(h.corners[leaves[sel]], rays, rng).reshape(-1, 3)
        which = np.repeat(np.arange(len(sel)), rays)
        n_o = nrm[sel][which]
        o = o + offset * n_o
        x1, x2 = stratified_unit_square(len(sel), rays, rng)
        d, w = _cone_rays(c, R, o, n_o, x1.ravel(), x2.ravel(), rays)
        ind, lost = _seen_through_cone(objects, obj, B_obj, sol, room, lookup, o, d, w, which,
                                       len(sel))
        d_ind[:, sel] += ind
        d_dir[:, sel] -= lost
    return d_dir, d_ind


class NearChange:
    """The objects' change of the indirect light at the texels ``tm`` of ``scene`` near them,
    cast per texel (``leaf_change`` casts it per leaf; a leaf read at its texels blurs a
    contact's dark ring over the leaf): ``weight`` (T,), of this per-texel change against the
    leaves' (1 within NEAR_IN bounding radii of an object, 0 past NEAR_OUT, linear between);
    calling it with the objects' radiosity ``B_obj`` and a change of the room's light per texel
    ``texels`` gives (k, T, 3): what the objects show minus the room's non-lamp radiosity they
    hide, and the room near them in that change, seen from the same texels (cosine rays over
    the hemisphere).  ``rays`` rays per texel within NEAR_DENSE bounding radii of an object,
    ``rays // FAR_SHARE`` past it, over a ``samples`` x ``samples`` grid of its footprint, cast
    once."""

    def __init__(self, objects: VirtualObjects, sol, room, lookup, scene, tm, scale, seed,
                 rays=CONE_RAYS, samples=FOOTPRINT, texels=None, lit=None):
        self.k, self.T = len(sol.basis), tm.n_texels
        self.weight = np.zeros(self.T)
        self.cones, self.seen = [], []
        if self.T == 0:
            return
        rng = np.random.default_rng([int(seed), 0x7E1])
        x = bilinear_point(scene.corners[tm.patch][:, None], tm.u[:, None], tm.v[:, None])[:, 0]
        nrm = scene.area_normal()[1][tm.patch]
        offset = ray_offset(scale)
        centre, size = texel_footprint_cells(tm)
        dense = np.zeros(self.T, bool)
        for obj in range(len(objects.radius)):
            dist = np.linalg.norm(objects.centre[obj] - x, axis=1) / objects.radius[obj]
            dense |= dist < NEAR_DENSE
        tiers = ((dense, rays), (~dense, max(rays // FAR_SHARE, 1)))

        def origins(sel, n):
            pts, S = footprint_points(scene, tm.patch[sel], tm.u[sel], tm.v[sel], centre[sel],
                                      size[sel], samples)
            which = np.repeat(np.arange(len(sel)), n)
            n_o = nrm[sel][which]
            o = pts.reshape(len(sel), S, 3)[which, np.tile(np.arange(n) % S, len(sel))] \
                + offset * n_o
            return o, n_o, which
        for obj in range(len(objects.radius)):
            c, R = objects.centre[obj], objects.radius[obj]
            to_c = c - x
            dist = np.linalg.norm(to_c, axis=1)
            w_obj = np.clip((NEAR_OUT - dist / R) / (NEAR_OUT - NEAR_IN), 0.0, 1.0)
            near = (w_obj > 0) & (np.einsum("ij,ij->i", nrm, to_c) > -R)
            for tier, n in tiers:
                sel = np.flatnonzero(near & tier)
                if not len(sel):
                    continue
                o, n_o, which = origins(sel, n)
                x1, x2 = stratified_unit_square(len(sel), n, rng)
                d, w = _cone_rays(c, R, o, n_o, x1.ravel(), x2.ravel(), n)
                self.cones.append((sel, _ConeHits(objects, obj, sol, room, lookup, o, d, w,
                                                  which, len(sel), lit)))
            self.weight[near] = np.maximum(self.weight[near], w_obj[near])
        # the room near the objects seen from the same texels (what the objects hide of it is
        # counted above)
        for tier, n in tiers:
            sel = np.flatnonzero((self.weight > 0) & tier)
            if not len(sel):
                continue
            o, n_o, which = origins(sel, n)
            x1, x2 = stratified_unit_square(len(sel), n, rng)
            d = cosine_directions(n_o, x1.reshape(-1, 1), x2.reshape(-1, 1))
            t, prim = room.first_hit(o, d)
            hit = np.flatnonzero(prim >= 0)
            t_obj, got = objects.occluder.first_hit(o[hit], d[hit])
            hit = hit[(got < 0) | (t_obj >= t[hit])]              # not hidden by an object
            self.seen.append((sel, which[hit], n, _RoomSeen(
                objects, sol, room, lookup, o[hit] + t[hit, None] * d[hit],
                room.patch_of_triangle[prim[hit]], d[hit], scale, rng.integers(2**31), texels)))

    def __call__(self, B_obj, texels=None):
        out = np.zeros((self.k, self.T, 3))
        for sel, cone in self.cones:
            out[:, sel] += cone.sums(B_obj)[0]
        for sel, which, n, seen in self.seen:
            dB = seen.change(texels)
            for j in range(self.k):
                for ch in range(3):
                    out[j, sel, ch] += np.bincount(which, dB[j, :, ch], len(sel)) / n
        return out


def texel_indirect_change(objects: VirtualObjects, B_obj, sol, room, lookup, scene, tm, scale,
                          seed, rays=CONE_RAYS, samples=FOOTPRINT, texels=None, lit=None):
    """(T,) the weight and (k, T, 3) the change of :class:`NearChange` for ``B_obj`` and
    ``texels``."""
    near = NearChange(objects, sol, room, lookup, scene, tm, scale, seed, rays, samples, texels,
                      lit)
    return near.weight, near(B_obj, texels)


def light_change(objects: VirtualObjects, sol, room, scale, quality, seed):
    """(k, L, 3) change of the direct light of ``sol.scene.lights`` on the leaves (at the
    solution's exitance factors), cast again only where an object can shadow them.  The leaves
    see the lights as the solve lit them (a proxy's: against the full mesh, lifted;
    shadowfree.proxy_lamp_view), so an object takes away only light they had."""
    h, leaves = sol.hierarchy, sol.leaves
    k = len(sol.basis)
    out = np.zeros((k, len(leaves), 3))
    if not len(sol.scene.lights):
        return out
    x = h.centroid[leaves]
    r_leaf = np.linalg.norm(h.corners[leaves] - x[:, None], axis=2).max(axis=1)
    sel = np.flatnonzero(may_be_shadowed_at(sol.scene, x, r_leaf, objects.triangles))
    if not len(sel):
        return out
    s = np.ones(k) if sol.emission_scale is None else np.asarray(sol.emission_scale, float)
    lamp_room, lift = sol.lamp_view(room)
    past, whole = lights_on_elements(sol.scene, h, leaves[sel],
                                     ObjectsOnlyOccluder(lamp_room, objects.occluder),
                                     quality.quadrature, quality.rays, int(seed), scale, lift)
    out[:, sel] = (past - whole) * s[:, None, None]
    return out


def texel_direct_change(result, objects: VirtualObjects, make_light, seed):
    """(k, T, 3) change of each lamp's direct light on the texels (at the exitance factors),
    cast only where an object can shadow it, on FOOTPRINT x FOOTPRINT points per texel.
    ``make_light(tm, occluder, seed, samples)``: the run's TexelLight on texels ``tm``."""
    tm = result.texel_map
    scene = result.scene if result.scene is not None else result.solution.scene
    k = scene.n_lamps
    out = np.zeros((k, tm.n_texels, 3))
    mask = may_be_shadowed(scene, tm, objects.triangles)
    if not mask.any():
        return out
    sub = texel_subset(tm, mask)
    whole, past = make_light(sub, ObjectsOnlyOccluder(result.occluder, objects.occluder), seed,
                             FOOTPRINT).direct()
    s = np.asarray(result.exitance_scale, float)
    out[:, mask] = np.moveaxis((past - whole) * s[None, :, None], 1, 0)
    return out


def irradiance_change(result, objects: VirtualObjects, make_light, seed=0, texel_light=None):
    """(k, T, 3) change of each lamp's irradiance on the texels of a texel-mode result that the
    virtual ``objects`` bring: their shadows and the light they block and reflect."""
    sol = result.solution
    q = sol.quality
    scale = sol.context.get("scale", 1.0)
    room = sol.context.get("occluder")
    if room is None or getattr(room, "patch_of_triangle", None) is None:
        room = sol.scene.make_occluder()
    lookup = _leaf_lookup(sol)
    direct = texel_direct_change(result, objects, make_light, seed + 1)
    texel_scene = result.scene if result.scene is not None else sol.scene
    # the objects' shadows on the room where their rays meet it, as the maps have them (a
    # radiosity proxy's patches are not the texels': there they are cast again)
    texels = lit = None
    if sol.context.get("proxy") is None:
        texels = TexelChange(texel_scene, result.texel_map, direct)
        lit = None if texel_light is None else \
            TexelChange(texel_scene, result.texel_map, texel_light)
    gather = ObjectRadiosity(objects, sol, room, lookup, scale, q.rays, seed, texels, lit)
    B_obj = gather(texels)
    d_dir, d_ind = leaf_change(objects, B_obj, sol, room, lookup, scale, seed)
    d_light = light_change(objects, sol, room, scale, q, seed)
    # What the leaves reflect of their change travels through the room's own links.
    rho = np.asarray(sol.system.rho, float)
    dE = rho[:, :, None] * np.moveaxis(d_dir + d_ind + d_light, 0, 2)             # (L, 3, k)
    dB = np.moveaxis(sol.system.solve(dE, q.solver, tol=q.tol)[0], 2, 0)          # (k, L, 3)
    tr = Transport(sol)

    def bounce(x):
        return tr.per_lamp(tr.occ, x) - tr.per_lamp(tr.dir_occ, x)
    ind = d_ind + bounce(dB)
    read = make_light(result.texel_map, result.occluder, seed, None).reader(sol)
    leaf_texel = np.stack([read(x) for x in ind])
    # Near the objects, what they show and hide and the first bounce of their shadows are cast
    # per texel instead of read from the leaves (which blur a contact's dark ring over a leaf).
    near = NearChange(objects, sol, room, lookup, texel_scene, result.texel_map, scale, seed + 2,
                      texels=texels, lit=lit)
    w = near.weight
    sel = np.flatnonzero(w > 0)
    d_texel = leaf_texel.copy()
    if len(sel):
        first = d_ind + bounce(rho[None] * (d_dir + d_light))
        leaf_read = np.stack([read(x)[sel] for x in first])
        d_texel[:, sel] += w[sel, None] * (near(B_obj, texels)[:, sel] - leaf_read)
    # Under an object and beside it, the room and the object see each other in their change:
    # a sphere's underside sees the floor it darkens (direct and indirect), which sees it.  Each
    # further pass gathers the object's radiosity and the texels' light again, along the same
    # rays, from the room's whole change of the pass before, which then replaces all the
    # leaves give near the objects.
    for _ in range(NEAR_PASSES - 1):
        if texels is None or not len(sel):
            break
        texels = texels.with_values(d_texel + direct)
        d_texel = leaf_texel + w[None, :, None] * (near(gather(texels), texels) - leaf_texel)
    return d_texel + direct
