# SPDX-License-Identifier: GPL-3.0-or-later
"""Per-scene Relight settings (``scene.relight``), the object role, and the state of the last
precompute.

* The status lives in the scene's ID property ``relight_status`` (a dict), so it is saved with
  the .blend and follows undo like the relit materials it describes.
* The last result (the radiosity solution, for Update and the overlays) is kept in memory per
  scene, tied to the status by a run id: after undo, a reload or another file it is simply not
  there (``load_post`` forgets every result), never another scene's or file's.
"""

import uuid

import bpy
from bpy.app.handlers import persistent
from bpy.props import BoolProperty, EnumProperty, IntProperty

from ..relight_addon.core.radiosity.presets import PROXY_FACTOR

STATUS = "relight_status"
ROLE_PROPERTY = "relight_role"

CORRECTION_ITEMS = (
    ("TEXEL", "Per Texel", "Remove the real lamps' shadows from the textures texel by texel "
                           "(ray-cast visibility per texel; most accurate)"),
    ("ELEMENT", "Per Element", "Remove the shadows per radiosity element with frontier and "
                               "reference elements (the original method)"),
    ("NONE", "Off", "Keep the photographed shadows in the textures (they stay when a lamp "
                    "is switched off)"),
)

PRESET_ITEMS = (
    ("draft", "Draft", "Fastest, coarse shadows"),
    ("medium", "Medium", "Balanced"),
    ("high", "High", "Accurate"),
    ("ultra", "Ultra", "Slowest, most accurate"),
)

ROLE_ITEMS = (
    ("relit", "Relit", "A photographed surface: its textures are relit"),
    ("occluder", "Occluder", "Only casts shadows and blocks light (not relit, reflects nothing)"),
    ("ignored", "Ignored", "Not read at all"),
    ("virtual", "Virtual", "A virtual object, not in the photo: it casts shadows on and "
                           "reflects light onto the relit surfaces (Update after moving it)"),
)

SHADOW_ITEMS = (
    ("EXACT", "Exact", "Ray-traced into the maps on Update, with the light the object blocks and "
                       "reflects; Update after moving it"),
    ("SPHERES", "Moving", "Soft shadows of a set of spheres, evaluated by the relit materials: "
                          "they follow the object's animation and drags at once, and render on "
                          "a farm without the extension (direct light only)"),
)

OVERLAY_ITEMS = (
    ("NONE", "None", "No overlay"),
    ("RATIO", "B / D", "Radiosity elements coloured by B / D: white where nothing blocks the "
                       "light, blue in shadow"),
    ("VISIBILITY", "Visibility", "Elements coloured by how they see the lamps: green visible, "
                                 "yellow partial, grey hidden"),
    ("FRONTIER", "Frontier / Reference", "Per-element shadow removal with reference elements: "
                                         "frontier green, shadowed with a reference yellow, "
                                         "without grey"),
    ("LINKS", "Links", "The links that carry the most light"),
)

# scene.session_uid -> [(run id, ShadowFreeResult)], newest last: the last result of each
# scene in memory, and the one before it while its maps are small enough (an undo of the last
# Update brings back the status that names it, and the next Update starts from it, not from a
# new solve).
_RESULTS = {}
KEEP_PREVIOUS_BYTES = 256 << 20


def _map_bytes(result):
    return sum(int(getattr(a, "nbytes", 0)) for part in (result.maps, result.texture)
               for a in (part or {}).values())


def last_result(scene):
    """The result of ``scene``'s last precompute in this session that its status names (Undo
    of the last Update brings back the one before; reload or Clear make it unavailable)."""
    st = status(scene)
    if not st:
        return None
    for run, result in reversed(_RESULTS.get(scene.session_uid, ())):
        if st.get("run") == run:
            return result
    return None


def remember(scene, result):
    """Keep ``result`` as ``scene``'s last result; returns the run id stored in its status."""
    run = uuid.uuid4().hex
    kept = _RESULTS.get(scene.session_uid, [])[-1:]
    if kept and _map_bytes(kept[0][1]) > KEEP_PREVIOUS_BYTES:
        kept = []
    _RESULTS[scene.session_uid] = kept + [(run, result)]
    return run


def forget(scene):
    """Drop ``scene``'s status and last result (Clear)."""
    _RESULTS.pop(scene.session_uid, None)
    if STATUS in scene:
        del scene[STATUS]


@persistent
def _forget_all(*_args):
    _RESULTS.clear()
    if not bpy.app.background:
        from ..relight_addon.blender import overlay
        overlay.unregister_overlay()


def update_overlay(settings, context):
    """Show the chosen overlay of the last precompute (no-op in background mode)."""
    if bpy.app.background:
        return
    from ..relight_addon.blender import overlay
    from ..relight_addon.core.display.colormap import MODE_RATIO, MODE_VISIBILITY
    from ..relight_addon.core.display.elements import element_values, strongest_links
    overlay.clear_overlay_data()
    result = last_result(context.scene)
    mode = settings.overlay
    if mode == "NONE" or result is None:
        overlay.unregister_overlay()
        return
    if mode == "LINKS":
        overlay.set_link_data(*strongest_links(result))
    else:
        corners, values = element_values(result, mode)
        overlay.set_overlay_data(corners, values,
                                 MODE_RATIO if mode == "RATIO" else MODE_VISIBILITY)
    overlay.register_overlay()


class RelightSceneSettings(bpy.types.PropertyGroup):
    preset: EnumProperty(name="Quality", items=PRESET_ITEMS, default="medium",
                         description="Quality preset (speed <-> accuracy)")
    correction: EnumProperty(name="Shadow Removal", items=CORRECTION_ITEMS, default="TEXEL",
                             description="How the photographed shadows of the real lamps are "
                                         "removed from the textures")
    proxy_faces: IntProperty(name="Proxy Faces", default=0, min=0, soft_max=20000,
                             description=f"A mesh of more than {PROXY_FACTOR}x this many "
                                         "faces (a scan) is solved on a decimated proxy of "
                                         "about this many triangles; the direct light and the "
                                         "textures stay on the full mesh. 0: the quality "
                                         "preset's")
    settle: BoolProperty(name="Settle Moving Shadows", default=True,
                         description="On Update, ray-trace the moving objects' real shadows "
                                     "where they stand; the materials use them until an "
                                     "object moves (then its spheres' shadow)")
    overlay: EnumProperty(name="Overlay", items=OVERLAY_ITEMS, default="NONE",
                          update=update_overlay,
                          description="Draw the last precompute's radiosity elements or links "
                                      "in the viewport")


def status(scene):
    """The last precompute's status dict, or None (also for a copy of a scene, which carries
    its original's status: it describes the original's lamps and result)."""
    st = scene.get(STATUS)
    if st is None:
        return None
    from ..relight_addon.blender.write import scene_key
    if scene_key(scene) is None:
        return None
    return st.to_dict() if hasattr(st, "to_dict") else st


def store_status(scene, result, seconds, correction, run, warnings, fingerprint="",
                 geometry="", real="", virtual=(), room="", objects=False):
    """Write what the panel shows: counts, time, model misfit, lamps and their exitances, the
    read and write warnings, and the scene fingerprint that Update compares."""
    import math
    stats = result.stats
    scale = [float(x) for x in result.exitance_scale]
    mean = sum(scale) / len(scale) if scale and sum(scale) > 0 else 1.0
    est = result.lamps

    def finite(x, default):
        return float(x) if math.isfinite(x) else default
    scene[STATUS] = {
        "preset": result.options.preset, "correction": correction, "run": run,
        "elements": int(stats.get("elements", 0)), "links": int(stats.get("links", 0)),
        "seconds": float(seconds), "misfit": float(stats.get("photo_misfit", float("nan"))),
        "lamps": list(result.solution.scene.lamp_names),
        "exitance_scale": scale, "relative_exitance": [s / mean for s in scale],
        # the photo's view of each lamp against its set power (geometric mean 1 over the lamps
        # on in the photo; -1 where the photo cannot tell), its uncertainty, whether it is used
        "photo_ratio": [finite(x, -1.0) for x in est.photo_ratio],
        "photo_sigma": [finite(x, -1.0) for x in est.uncertainty],
        "photo_used": [bool(x) for x in est.applied],
        "photo_weight": [float(x) for x in est.photo_weight],
        "rho_mean": finite(est.rho_mean, -1.0),
        "rho_sigma": finite(getattr(est, "rho_sigma", float("inf")), -1.0),
        # a dense mesh solved on a decimated proxy: its faces and how far the mesh is from it
        "proxy_faces": int(stats.get("proxy_faces", 0)),
        "input_faces": int(stats.get("input_faces", 0)),
        "proxy_deviation": finite(float(stats.get("proxy_deviation", 0.0)), 0.0),
        "warnings": [str(w) for w in warnings],
        "fingerprint": fingerprint, "geometry": geometry,
        # the room (the scene without its virtual objects) without its virtual lamps (what the
        # real lamps' maps depend on), and the virtual lamps (lights added after the first
        # precompute: not in the photo)
        "real": real, "virtual": list(virtual),
        # the room with its virtual lamps, whose result an Update that only changes virtual
        # objects starts from ("" when it is not kept), and whether there are such objects
        "room": room, "objects": bool(objects),
    }


classes = (RelightSceneSettings,)


def attach():
    bpy.types.Scene.relight = bpy.props.PointerProperty(type=RelightSceneSettings)
    bpy.types.Object.relight_role = EnumProperty(
        name="Relight Role", items=ROLE_ITEMS, default="relit",
        description="How Relight treats this object: relit photographed surface, occluder only, "
                    "or ignored")
    bpy.types.Object.relight_shadows = EnumProperty(
        name="Shadows", items=SHADOW_ITEMS, default="EXACT",
        description="How a virtual object's shadows are computed")
    bpy.types.Object.relight_spheres = bpy.props.IntProperty(
        name="Spheres", default=32, min=1, max=512,
        description="Spheres approximating a moving virtual object: more give closer shadows "
                    "under small lamps and slower renders (each sphere is evaluated per lamp at "
                    "every shading point; EEVEE's shader compiler fails at about 128). Update "
                    "after changing it")
    if _forget_all not in bpy.app.handlers.load_post:
        bpy.app.handlers.load_post.append(_forget_all)


def detach():
    if _forget_all in bpy.app.handlers.load_post:
        bpy.app.handlers.load_post.remove(_forget_all)
    if hasattr(bpy.types.Scene, "relight"):
        del bpy.types.Scene.relight
    for prop in ("relight_role", "relight_shadows", "relight_spheres"):
        if hasattr(bpy.types.Object, prop):
            delattr(bpy.types.Object, prop)
    _RESULTS.clear()
    if not bpy.app.background:
        from ..relight_addon.blender import overlay
        overlay.unregister_overlay()
