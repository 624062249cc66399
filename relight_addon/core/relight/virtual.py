"""Virtual lamps and objects (seed 000 §4.4): what is not in the photo, added to a precompute.

Virtual lamps.

Light transport is linear in the lamps, so a lamp added after the precompute only needs its own
basis on the existing radiosity mesh and links, its own direct light per texel, and its map
M_v = H_occ,v / D with D the irradiance the photo was lit by (kept by texel mode): the shadow-free
texture, the other maps and the reflectances stay as they are.  The lamps are given as core
``Lights`` (a Blender area light too, as an AREA light: no new patches, so no new links); its
exitance factor is the real lamps' common factor (the user's power units are the real lamps').
The new lamps' direct light on every leaf is reflected through the existing transport, so they
light the room with its interreflections and are shadowed by its geometry.

Virtual objects.  The photo shows the room without them, so the shadow-free texture and the
irradiance the photo was lit by come from the room alone; what they change is each lamp's light
on the room: their shadows, and the light they block and reflect.  ``add_objects`` adds that
change (object_change.py: cast only where the objects can reach, on the room's own solution) to
every map; away from the objects the maps are untouched.
"""
from __future__ import annotations

import copy
import dataclasses

import numpy as np

from ..lights import Lights
from ..radiosity.precompute import lights_on_elements
from .maps import map_images
from .texel_maps import lamp_maps


def _with_lamps(scene, lights: Lights, names):
    """A shallow copy of ``scene`` with the lamps ``names`` (lights indexed 0..) appended, off in
    the photo (intensity 0)."""
    k0 = scene.n_lamps
    new = copy.copy(scene)
    rows = dataclasses.replace(lights, lamp=lights.lamp + k0)
    new.lamp_names = list(scene.lamp_names) + list(names)
    new.lamp_intensity = np.concatenate([scene.lamp_intensity, np.zeros(len(names))])
    new.lights = Lights.concat([scene.lights, rows])
    return new, rows


def _only_lights(scene, rows):
    """``scene`` with no lamp patches and only the light ``rows``: what the new lamps light."""
    new = copy.copy(scene)
    new.lamp = np.full_like(scene.lamp, -1)
    new.emission = np.zeros_like(scene.emission)
    new.lights = rows
    return new


def add_lamps(result, lights: Lights, names, seed=0):
    """A copy of ``result`` (a texel-mode ShadowFreeResult) with the lamps ``lights`` (core
    Lights, ``lights.lamp`` indexing ``names``) added after its lamps: the solution gains their
    bases, the maps one image layer per new lamp, the lamp estimate their factors (the real
    lamps' geometric mean; no photo estimate: nan)."""
    if result.denominator is None:
        raise ValueError("virtual lamps are added to a per-texel result only")
    m = len(names)
    if m == 0:
        return result
    sol = result.solution
    scene, rows = _with_lamps(sol.scene, lights, names)
    k0 = sol.scene.n_lamps
    q = sol.quality
    size = sol.context.get("scale", 1.0)
    proxy = sol.context.get("proxy")
    # (a proxy's leaves are lit as the run lit them: shadowfree.proxy_lamp_view)
    occluder, lift = sol.lamp_view(result.occluder) if proxy is not None else (result.occluder, 0.0)
    # The new lamps' direct light on every leaf, then their bases on the existing system.
    lit_scene = _only_lights(scene, rows)
    occ, unocc = lights_on_elements(lit_scene, sol.hierarchy, sol.leaves, occluder,
                                    q.quadrature, q.rays, seed, size, lift)
    occ, unocc = occ[k0:], unocc[k0:]
    real = sol.emission_scale[sol.scene.lamp_intensity > 0]
    s = float(np.exp(np.mean(np.log(np.maximum(real, 1e-300))))) if len(real) else 1.0
    E = np.moveaxis(occ, 0, 2) * sol.system.rho[:, :, None] * s            # (L, 3, m)
    basis, _ = sol.system.solve(E, q.solver, tol=q.tol)
    new_sol = copy.copy(sol)
    new_sol.scene = scene
    new_sol.basis = np.concatenate([sol.basis, np.moveaxis(basis, 2, 0)])
    L = len(sol.leaves)
    old_occ = sol.light_occ if sol.light_occ is not None else np.zeros((k0, L, 3))
    old_unocc = sol.light_unocc if sol.light_unocc is not None else np.zeros((k0, L, 3))
    new_sol.light_occ = np.concatenate([old_occ, occ])
    new_sol.light_unocc = np.concatenate([old_unocc, unocc])
    new_sol.emission_scale = np.concatenate([sol.emission_scale, np.full(m, s)])
    # Per texel: direct by ray casting (the new lamps only), indirect from the new bases.
    opt = result.options
    texels_of = result.scene if result.scene is not None else sol.scene
    texel_scene = _with_lamps(texels_of, lights, names)[0]
    light = result.texel_light(_only_lights(texel_scene, rows), opt.seed + 101)
    new_maps, new_direct = lamp_maps(light, new_sol, np.arange(k0, k0 + m), s,
                                     result.denominator)
    maps = {i: np.concatenate([result.maps[i], new_maps[i]]) for i in result.maps}
    direct = None
    if result.direct is not None:
        direct = {i: np.concatenate([result.direct[i], new_direct[i]]) for i in result.direct}
    est = result.lamps
    lamps = dataclasses.replace(
        est, scale=np.concatenate([est.scale, np.full(m, s)]),
        photo_ratio=np.concatenate([est.photo_ratio, np.full(m, np.nan)]),
        uncertainty=np.concatenate([est.uncertainty, np.full(m, np.nan)]),
        photo_weight=np.concatenate([est.photo_weight, np.zeros(m)]),
        equal=np.concatenate([est.equal, np.ones(m)]), nnls=np.concatenate([est.nnls, np.zeros(m)]))
    # the texels' scene has every lamp of the maps: an object added later casts its change
    # for each of them (object_change.texel_direct_change)
    return dataclasses.replace(result, maps=maps, lamps=lamps, solution=new_sol, direct=direct,
                               room=None, scene=texel_scene if result.scene is not None else None)


def _lamps_of(result, keep, scene_of):
    """A copy of ``result`` with only the lamps ``keep`` (indices), in that order: the maps, the
    bases, the lights' leaf light and the estimate's rows; ``scene_of(scene)`` gives the
    solution's and the texels' scenes with those lamps."""
    sol = result.solution
    new_sol = copy.copy(sol)
    new_sol.scene = scene_of(sol.scene)
    new_sol.basis = sol.basis[keep]
    new_sol.emission_scale = sol.emission_scale[keep]
    if sol.light_occ is not None:
        new_sol.light_occ, new_sol.light_unocc = sol.light_occ[keep], sol.light_unocc[keep]
    est = result.lamps
    lamps = dataclasses.replace(est, **{f: getattr(est, f)[keep] for f in (
        "scale", "photo_ratio", "uncertainty", "photo_weight", "equal", "nnls")})
    direct = None if result.direct is None else {i: d[keep] for i, d in result.direct.items()}
    scene = None if result.scene is None else (
        new_sol.scene if result.scene is sol.scene else scene_of(result.scene))
    return dataclasses.replace(result, maps={i: m[keep] for i, m in result.maps.items()},
                               lamps=lamps, solution=new_sol, direct=direct, room=None,
                               scene=scene)


def keep_lamps(result, drop):
    """A copy of ``result`` without the lamps ``drop`` (indices of lamps that are lights, e.g.
    virtual lamps to be added again with :func:`add_lamps`)."""
    drop = sorted(set(int(k) for k in drop))
    if not drop:
        return result
    keep = np.array([k for k in range(result.solution.scene.n_lamps) if k not in drop])
    return _lamps_of(result, keep, lambda scene: scene.without_lamps(drop))


def _lights_only_from(scene, first):
    """``scene`` lit by its lamps ``first``.. alone (lights, not patches: the lamps add_lamps
    appends), renumbered from 0: no lamp patches, no emission (as :func:`_only_lights`)."""
    rows = np.flatnonzero(scene.lights.lamp >= first)
    lights = dataclasses.replace(scene.lights, **{f.name: getattr(scene.lights, f.name)[rows]
                                                  for f in dataclasses.fields(scene.lights)})
    lights.lamp = lights.lamp - first
    new = _only_lights(scene, lights)
    new.lamp_names = list(scene.lamp_names)[first:]
    new.lamp_intensity = np.asarray(scene.lamp_intensity)[first:]
    return new


def _only_lamps_from(result, first):
    """``result`` seen as if its lamps ``first``.. (added by :func:`add_lamps`) were its only
    ones: what :func:`add_objects` casts the objects' change on for them alone."""
    keep = np.arange(first, result.solution.scene.n_lamps)
    return _lamps_of(result, keep, lambda scene: _lights_only_from(scene, first))


def add_lamps_beside_objects(with_objects, room, lights: Lights, names, scene):
    """:func:`add_lamps` for a result whose maps already hold the virtual objects of ``scene``
    (``with_objects``; ``room``: the same lamps without the objects).  The objects' change is
    linear in the lamps: the new lamps' maps gain it cast for them alone, and the other lamps
    keep their maps with the objects as they are, so that a lamp added beside objects costs
    one lamp's change instead of every lamp's.  The copy's ``room`` is the room with the new
    lamps, which a later Update moving the objects starts from."""
    k0 = room.solution.scene.n_lamps
    new_room = add_lamps(room, lights, names)
    alone = add_objects(_only_lamps_from(new_room, k0), scene)
    maps = {i: np.concatenate([with_objects.maps[i], alone.maps[i]]) for i in new_room.maps}
    return dataclasses.replace(new_room, maps=maps, room=new_room)


def add_objects(result, scene, progress=None):
    """A copy of ``result`` (the precompute of ``scene`` without its virtual objects, per
    texel) whose maps include the virtual objects of ``scene`` (``scene.virtual``): each lamp's
    irradiance changes by what object_change.py casts where the objects can reach, over the
    irradiance the photo was lit by.  ``room`` of the copy is ``result``, which an Update that
    only moves, adds or deletes objects starts from again."""
    from .maps import DISPLAY_EPS
    from .object_change import VirtualObjects, irradiance_change
    from .texel import texel_light_for
    if result.denominator is None:
        raise ValueError("virtual objects are added to a per-texel result only")
    objects = scene.virtual_last()
    extra = slice(int((~objects.virtual).sum()), objects.n_patches)
    if extra.start == extra.stop:
        return dataclasses.replace(result, room=None)
    opt = result.options
    proxy = result.solution.context.get("proxy")
    texel_scene = result.scene if result.scene is not None else result.solution.scene

    def make_light(tm, occluder, seed, samples=None):
        o = opt if samples is None else dataclasses.replace(opt, texel_samples=samples)
        return texel_light_for(texel_scene, tm, occluder, o, seed, proxy,
                            result.solution_texels if tm is result.texel_map else None)
    virtual = VirtualObjects.of(objects, extra)
    if not len(virtual.triangles):                  # no face that can block or reflect
        return dataclasses.replace(result, room=result)
    D = np.maximum(np.asarray(result.denominator, float), 0.0)                   # (T, 3)
    lit = D >= np.maximum(DISPLAY_EPS * D.max(axis=0, initial=0.0), 1e-300)
    old = _texel_maps(result)
    # each lamp's light per texel as the maps show it: the room the objects see, texel by texel
    delta = irradiance_change(result, virtual, make_light, opt.seed + 202, old * D[None])
    new = np.where(lit[None], np.maximum(old + delta / np.where(lit, D, 1.0)[None], 0.0), old)
    new_maps, _ = map_images(result.texel_map, new)
    return dataclasses.replace(result, maps=new_maps, room=result)


def _texel_maps(result):
    """The maps per texel (k, T, 3), read back from the result's images."""
    tm = result.texel_map
    k = result.solution.scene.n_lamps
    parts = []
    for i, im in enumerate(tm.images):
        if len(im) == 0:
            continue
        m = result.maps[i].reshape(k, -1, 3)
        parts.append(m[:, im.texel_index])
    return np.concatenate(parts, axis=1) if parts else np.zeros((k, 0, 3))
