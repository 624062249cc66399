"""When the model cannot explain the photo, say so, and name the lamp or surface.

The precompute always gives an answer; these checks tell the user when it should not be
trusted, instead of a bare misfit number:

* a photographed surface brighter than its lamps can explain (its reflectance clipped at the
  estimate's ceiling on more than CLIPPED_SHARE of it): a lamp missing from the scene, a lamp
  set too weak, an overexposed photo;
* a lamp the photo sees very differently from its set power (the shadow-edge fit's ratio
  outside [1 / OFF_FACTOR, OFF_FACTOR] while its uncertainty is below half of that): the user
  should check it (the message says whether the photo's estimate was used);
* a lamp whose map is zero on every photographed texel (inside or behind geometry);
* a lamp closer to a surface than TOUCHING of the scene's size or than its own radius: the
  light right next to it is not resolved;
* a lamp inside a closed object (every ray from it meets that object, and the camera is not
  inside it too): it lights the object's inside only, which the photo does not show;
* a light solve that stopped at its iteration bound without converging.
"""
from __future__ import annotations

import numpy as np

from ..numerics import nonzero, safe_div
from ..texture.colour import luminance
from .albedo import RHO_ESTIMATE_MAX
from .enclosure import enclosed_lamps

CLIPPED_SHARE = 0.05
OFF_FACTOR = 2.0
TOUCHING = 0.002            # of the scene's bounding diagonal (1 cm in a 5 m room)


def clipped_surfaces(sol, use_patch, group_names):
    """[(name, share)] of the photographed groups whose reflectance hit the ceiling on more
    than CLIPPED_SHARE of their area."""
    patch = sol.system.patch
    use = use_patch[patch]
    if not use.any():
        return []
    a = sol.system.leaf_area
    clipped = (sol.system.rho >= RHO_ESTIMATE_MAX - 1e-9).any(axis=1) & use
    group = np.asarray(sol.scene.group)[patch]
    out = []
    for g in np.unique(group[use]):
        sel = use & (group == g)
        share = float(a[sel & clipped].sum() / a[sel].sum())
        if share > CLIPPED_SHARE:
            out.append((group_names(int(g)), share))
    return out


def _point_triangle_distance(p, tris):
    """Distance from point p (3,) to each triangle (t, 3, 3): to its plane when p projects
    inside it, else to its nearest edge."""
    a, b, c = tris[:, 0], tris[:, 1], tris[:, 2]
    ab, ac = b - a, c - a
    n = np.cross(ab, ac)
    nn = nonzero((n * n).sum(1))
    ap = p - a
    h = (ap * n).sum(1) / nn
    q = p - h[:, None] * n                                    # p projected on the plane
    aq = q - a
    d00, d01, d11 = (ab * ab).sum(1), (ab * ac).sum(1), (ac * ac).sum(1)
    d20, d21 = (aq * ab).sum(1), (aq * ac).sum(1)
    den = nonzero(d00 * d11 - d01 * d01)
    v = (d11 * d20 - d01 * d21) / den
    w = (d00 * d21 - d01 * d20) / den
    inside = (v >= 0) & (w >= 0) & (v + w <= 1)

    def to_segment(x, y):
        t = np.clip(safe_div(((p - x) * (y - x)).sum(1), ((y - x) ** 2).sum(1)), 0, 1)
        return np.linalg.norm(x + (y - x) * t[:, None] - p, axis=1)

    edge = np.minimum(np.minimum(to_segment(a, b), to_segment(b, c)), to_segment(c, a))
    return np.where(inside, np.abs(h) * np.sqrt(nn), edge)


def lamp_clearance(scene, lamp):
    """Distance (m) from lamp ``lamp`` (its patches' corners and centres, or its light's
    centre, minus the light's radius) to the nearest occluding surface other than its own (an
    emissive mesh's faces block light too)."""
    c = scene.corners[scene.occluder & (scene.lamp != lamp)]
    tris = np.concatenate([c[:, [0, 1, 2]], c[:, [0, 2, 3]]])
    # a triangle is a quad with two corners at one point: its second half has no area, and
    # every point would be 0 away from it
    area = np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1)
    tris = tris[area > 1e-12 * max(float(area.max(initial=0.0)), 1e-300)]
    if len(tris) == 0:
        return np.inf
    pts = []
    sel = scene.lamp == lamp
    if sel.any():
        c = scene.corners[sel]
        pts += list(c.reshape(-1, 3)) + list(c.mean(axis=1))
    radius = 0.0
    lights = scene.lights
    for i in np.flatnonzero(lights.lamp == lamp):
        if lights.kind[i] == 2:                                  # a sun is outside
            continue
        pts.append(lights.position[i])
        radius = max(radius, float(lights.radius[i]))
    if not pts:
        return np.inf
    return min(float(_point_triangle_distance(np.asarray(p, float), tris).min()) for p in pts) \
        - radius


def diagnose(result, use_patch, group_names=str) -> list:
    """Sentences for the user (see the module docstring); ``group_names(g)`` names a patch
    group (an object / material)."""
    sol = result.solution
    scene = sol.scene
    names = scene.lamp_names
    out = []
    for name, share in clipped_surfaces(sol, use_patch, group_names):
        out.append(f"'{name}' is brighter in the photo than its lamps can explain on "
                   f"{100 * share:.0f} % of it (a lamp missing from the scene or set too weak, "
                   "or an overexposed photo): its relit light there is too dark")
    est = result.lamps
    gap = [lamp_clearance(scene, k) for k in range(len(names))]
    peak = [max((float(luminance(m[k]).max()) for m in result.maps.values()), default=0.0)
            for k in range(len(names))]
    # a lamp touching a surface or lighting nothing is named below; the photo's view of the
    # others is not judged against its estimate (one lamp 1 mm under the ceiling made the
    # other look 'off' at draft)
    sound = np.array([g >= TOUCHING and p > 1e-9 for g, p in zip(gap, peak)], bool)
    seen = np.flatnonzero(np.isfinite(est.photo_ratio) & np.isfinite(est.uncertainty) & sound)
    log_t = np.log(np.maximum(est.photo_ratio[seen], 1e-300))
    for j, k in enumerate(seen):
        others = np.delete(log_t, j)
        if len(others) == 0:
            continue
        r = float(np.exp(log_t[j] - others.mean()))        # against the others' mean
        s = est.uncertainty[k]
        if r > OFF_FACTOR and s < 0.5 * np.log(OFF_FACTOR) or \
                (len(seen) > 2 and r < 1 / OFF_FACTOR and s < 0.5 * np.log(OFF_FACTOR)):
            versus = f"'{names[seen[1 - j]]}'" if len(seen) == 2 else "the other lamps"
            w = float(est.photo_weight[k])
            used = ("the set power is kept" if w <= 0 else
                    "the photo's estimate is used" if w >= 1.0 else
                    "the photo's estimate is used in part (it is near the edge of its "
                    "uncertainty)")
            out.append(f"The photo suggests lamp '{names[k]}' at {r:.2f} x its set power "
                       f"relative to {versus} (+- {100 * s:.0f} %): check its power; {used}")
    for k in range(len(names)):
        if peak[k] <= 1e-9:
            out.append(f"Lamp '{names[k]}' lights none of the photographed surfaces (is it "
                       "inside or behind something?): switching it on will change nothing")
    info = getattr(sol, "info", None)
    if info is not None and not info.converged:
        out.append(f"The light solve stopped without converging ({info.iterations} iterations, "
                   f"residual {info.residual:.1e}): the interreflections may be wrong (look for "
                   "surfaces that overlap or reflect almost all light)")
    from ..geometry.extent import bounding_diagonal
    touching = TOUCHING * bounding_diagonal(scene.corners)
    inside = enclosed_lamps(result.scene if result.scene is not None else scene,
                            result.occluder) if result.occluder is not None else {}
    for k, g in inside.items():
        out.append(f"Lamp '{names[k]}' is inside the closed object '{group_names(g)}': it "
                   "lights only the object's inside, which the photo does not show (move it "
                   "out, or make the object Ignored)")
    for k in range(len(names)):
        if k in inside:
            continue
        if gap[k] < touching:
            where = ("inside or touching a surface" if gap[k] <= 0
                     else f"{1000 * gap[k]:.2g} mm from a surface")
            out.append(f"Lamp '{names[k]}' is {where}: the light right next to it is not "
                       "resolved (move it away a little, or make it smaller)")
    return out
