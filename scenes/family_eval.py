"""Relighting a family room and scoring it against its Cycles truth (the benchmark and the tests).

* ``photographed_room(index, powers)`` (bpy): builds the room as a user would hand it to the
  add-on (``build_room(spec, "file")``: room 18's faces are flipped as another program exported
  them), puts the photo bakes into its textures, sets the lights' powers (``"exact"``: the
  true ones; ``"off30"``: alternately 30 % too high and too low; ``"unknown"``: every lamp at
  its type's base power, i.e. no ratio information) and reads it with the add-on's reader.
* ``score(room, result, ...)`` (bpy-free): CIEDE2000 of the relit textures against the truth
  for every target lighting (the original, each lamp off, each doubled, all but one off),
  overall and in each switched-off lamp's former shadow, with the baselines beside them: the photo unchanged, the
  photo scaled by the best single factor (the global exposure scale, given the truth's total),
  and DRB97 when its result is passed; the noise floor (photo vs truth at the photo's lighting);
  the error of the lamp exitance ratios.

Colour differences as the shadow-free tests: linear values divided by the 99th percentile of
the truth's luminance at the original lighting, clipped at 0, CIE LAB, CIEDE2000; over the
texels the texture map covers.  A lamp's former shadow: texels where it gives at least 10 % of
the unoccluded direct light and at least half of its light is blocked (ray casting, 64 rays).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from relight_addon.core.texture.colour import LUMINANCE, delta_e_2000, linear_rgb_to_lab
from scenes import family as fam

POWER_MODES = ("exact", "off30", "unknown")
SHADOW_SHARE = 0.1
SHADOW_BLOCKED = 0.5


@dataclass
class Room:
    index: int
    spec: object                 # RoomSpec
    bakes: object                # family.Bakes
    data: object                 # SceneData as read
    report: object               # ReadReport
    lamp_of: dict                # family lamp name -> lamp index in data
    image_object: list           # image index in data -> surface name
    user_power: dict             # family lamp name -> the power the lights were set to
    cache: dict = field(default_factory=dict)


def _set_power(bpy, spec, lamp, power):
    obj = bpy.data.objects[lamp.name]
    if lamp.type == "MESH":
        for slot in obj.material_slots:
            node = slot.material.node_tree.nodes.get("Lamp Emission")
            node.inputs["Strength"].default_value = float(power)
    else:
        obj.data.energy = float(power)


def user_powers(spec, mode):
    """The power each lamp is set to for ``mode`` (see the module docstring)."""
    out = {}
    for j, lp in enumerate(spec.lamps):
        if mode == "exact":
            out[lp.name] = lp.power
        elif mode == "off30":
            out[lp.name] = lp.power * (1.3 if j % 2 == 0 else 0.7)
        elif mode == "unknown":
            out[lp.name] = fam.BASE_POWER[lp.type]
        else:
            raise ValueError(mode)
    return out


def photographed_room(index, powers="exact", scan=None) -> Room:
    """Build room ``index`` in a fresh bpy scene with the photo bakes as its textures and read
    it (bpy).  ``scan``: {"triangles": n, "noise": metres, "seed": s} re-meshes every surface
    as a scanned room (scenes.scan); the bakes stay valid texel for texel."""
    import bpy  # noqa: PLC0415

    from relight_addon.blender.read import read_scene  # noqa: PLC0415
    spec = fam.room_spec(index)
    bakes = fam.load_bakes(index)
    if scan is not None:
        from scenes.scan import scan_spec  # noqa: PLC0415
        spec = scan_spec(spec, **scan)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    info = fam.build_room(spec, "file")
    for obj, img_name in info["albedo_images"].items():
        img = bpy.data.images[img_name]
        rgb = np.asarray(bakes.photo[obj], np.float32)
        rgba = np.ones(rgb.shape[:2] + (4,), np.float32)
        rgba[..., :3] = rgb
        img.pixels.foreach_set(rgba.ravel())
        img.update()
    set_to = user_powers(spec, powers)
    for lp in spec.lamps:
        _set_power(bpy, spec, lp, set_to[lp.name])
    bpy.context.view_layer.update()
    data, report = read_scene(bpy.context)
    if report.errors:
        raise RuntimeError(f"room {index}: {report.errors}")
    lamp_of = {}
    for k, src in enumerate(report.lamp_sources):
        lamp_of[src["object"]] = k
    missing = [lp.name for lp in spec.lamps if lp.name not in lamp_of]
    if missing:
        raise RuntimeError(f"room {index}: lamps not read: {missing} ({report.warnings})")
    image_object = [next(o for o, n in info["albedo_images"].items() if n == im.name)
                    for im in data.images]
    return Room(index, spec, bakes, data, report, lamp_of, image_object, set_to)


# -- scoring (bpy-free) ---------------------------------------------------------------------------

def _texels(room, result, images):
    """(T, 3) float64 of per-object images in the texel map's order."""
    tm = result.texel_map
    return tm.gather([np.asarray(images[o], np.float32)[..., :3] for o in room.image_object]) \
        .astype(np.float64)


def targets(spec):
    """{label: {lamp: factor}} of the target lightings: the photo's own ("original"), each lamp
    off, each doubled, and (with several lamps) each alone."""
    names = [lp.name for lp in spec.lamps]
    out = {"original": {}}
    for n in names:
        out[f"{n} off"] = {n: 0.0}
        out[f"{n} x2"] = {n: 2.0}
        if len(names) > 1:
            out[f"only {n}"] = {m: 0.0 for m in names if m != n}
    return out


def switched_off(intensities):
    return [n for n, v in intensities.items() if v == 0.0]


def shadow_masks(room, result):
    """{lamp: (T,) bool} former-shadow texels of each lamp (see the module docstring)."""
    if "masks" in room.cache:
        return room.cache["masks"]
    from relight_addon.core.geometry.raycast import make_occluder  # noqa: PLC0415
    from relight_addon.core.relight.direct import lamp_irradiance  # noqa: PLC0415
    from relight_addon.core.scene import bilinear_point  # noqa: PLC0415
    sc, tm = room.data, result.texel_map
    pts = bilinear_point(sc.corners[tm.patch][:, None], tm.u[:, None], tm.v[:, None])[:, 0]
    U, O = lamp_irradiance(sc, pts, sc.area_normal()[1][tm.patch],
                           make_occluder(sc.occluder_triangles()), rays=64, seed=3)
    u, o = U @ LUMINANCE, O @ LUMINANCE
    share = u / np.maximum(u.sum(axis=1, keepdims=True), 1e-300)
    masks = {}
    for name, k in room.lamp_of.items():
        masks[name] = (share[:, k] >= SHADOW_SHARE) & (o[:, k] <= SHADOW_BLOCKED * u[:, k])
    room.cache["masks"] = masks
    return masks


class _DE:
    def __init__(self, white):
        self.white = white

    def __call__(self, x, y):
        return delta_e_2000(linear_rgb_to_lab(np.clip(x / self.white, 0, None)),
                            linear_rgb_to_lab(np.clip(y / self.white, 0, None)))


def _stats(d, mask=None):
    d = d if mask is None else d[mask]
    if len(d) == 0:
        return (float("nan"), float("nan"))
    return (float(d.mean()), float(np.percentile(d, 95)))


def relit_texels(room, result, intensities):
    I = np.ones(room.data.n_lamps)
    for name, v in intensities.items():
        I[room.lamp_of[name]] = v
    out = result.relit(I)
    tm = result.texel_map
    return tm.gather([out[i] for i in range(len(room.image_object))]).astype(np.float64)


def score(room, result, drb97=None):
    """Every figure of one precompute (see the module docstring): {"floor": (mean, p95),
    "targets": {label: {"relit", "scale", "photo", "drb97": {"all": (mean, p95), "shadow":
    (mean, p95)}}}, "ratio_error": max relative error of the lamps' exitance ratios}."""
    bakes = room.bakes
    truth_basis = {n: _texels(room, result, bakes.lamps[n]) for n in bakes.lamps}
    photo = _texels(room, result, bakes.photo)
    full = sum(truth_basis.values())
    de = _DE(float(np.percentile(full @ LUMINANCE, 99)))
    masks = shadow_masks(room, result)
    out = {"floor": _stats(de(photo, full)), "targets": {}}
    for label, I in targets(room.spec).items():
        want = sum(I.get(n, 1.0) * t for n, t in truth_basis.items())
        off = switched_off(I)
        shadow = np.zeros(len(want), bool)
        for n in off:
            shadow |= masks[n]
        p_l, w_l = photo @ LUMINANCE, want @ LUMINANCE
        s = float(p_l @ w_l / max(p_l @ p_l, 1e-300))
        cands = {"relit": relit_texels(room, result, I), "scale": photo * s, "photo": photo}
        if drb97 is not None:
            cands["drb97"] = relit_texels(room, drb97, I)
        row = {}
        for k, x in cands.items():
            d = de(x, want)
            row[k] = {"all": _stats(d), "shadow": _stats(d, shadow) if off else (np.nan, np.nan),
                      "shadow_texels": int(shadow.sum())}
        out["targets"][label] = row
    out["ratio_error"] = ratio_error(room, result)
    return out


def ratio_error(room, result):
    """Largest relative error of the lamps' exitance ratios: each lamp's factor x the power it
    was set to, against its true power (geometric means matched); 0 for a single lamp."""
    est = []
    true = []
    for lp in room.spec.lamps:
        k = room.lamp_of[lp.name]
        est.append(result.exitance_scale[k] * room.user_power[lp.name])
        true.append(lp.power)
    est, true = np.log(np.asarray(est)), np.log(np.asarray(true))
    err = (est - est.mean()) - (true - true.mean())
    return float(np.max(np.abs(np.expm1(err))))
