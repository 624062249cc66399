# SPDX-License-Identifier: GPL-3.0-or-later
"""Per-scene Relight settings (``scene.relight``) and the object properties (role, shadows,
spheres).  What a scene remembers of its last precompute is the bridge's (blender/state.py).
"""

import bpy
from bpy.app.handlers import persistent
from bpy.props import BoolProperty, EnumProperty, IntProperty

from ..relight_addon.blender.roles import DEFAULT_SPHERES, MAX_SPHERES, ROLE_ITEMS, SHADOW_ITEMS
from ..relight_addon.core.radiosity.presets import PROXY_FACTOR

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

@persistent
def _forget_all(*_args):
    from ..relight_addon.blender import ar_draw, relit_draw
    ar_draw.retry()         # another file: what failed to draw in the last one may draw here
    relit_draw.retry()
    if not bpy.app.background:
        from ..relight_addon.blender import overlay
        overlay.unregister_overlay()


def _relit_preview_toggled(settings, context):
    """Toggling the preview draws it again after a failure (a failure stops the drawing, so
    that the console is not flooded at every redraw)."""
    from ..relight_addon.blender import relit_draw
    relit_draw.retry()


def update_overlay(settings, context):
    """Show the chosen overlay of the last precompute (no-op in background mode)."""
    if bpy.app.background:
        return
    from ..relight_addon.blender import overlay
    from ..relight_addon.core.display.colormap import MODE_RATIO, MODE_VISIBILITY
    from ..relight_addon.core.display.elements import element_values, strongest_links
    from ..relight_addon.blender.state import last_result
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
    relit_preview: BoolProperty(
        name="Relit Preview in Solid", default=False, update=_relit_preview_toggled,
        description="In Solid viewport shading, draw the relit surfaces as the relit materials "
                    "show them, with the moving objects' sphere shadows, live while they move "
                    "(nothing to compile; Material Preview and Rendered show the materials "
                    "themselves)")
    ar_eevee_ground: BoolProperty(
        name="EEVEE Sees the Photo Below", default=True,
        description="AR mode: EEVEE lights the objects by the World alone, whose map shows its "
                    "own ground below the horizon; with this, Set Up AR and Update give EEVEE a "
                    "World output that shows the photo there, projected onto the receivers' "
                    "ground, as Cycles sees it (the World's own output stays Cycles'). Costs "
                    "EEVEE a heavier World shader")
    cycles_shadows: EnumProperty(
        name="Cycles Moving Shadows", default="RAYS",
        items=(("RAYS", "Rays", "Cycles casts rays towards the lamps against the moving objects' "
                                "real meshes: their shadows, soft as samples add up. Before "
                                "Blender 5.1 each ray reads a table of the object's lines traced "
                                "on Update: a mesh deformed since (armature, modifier) keeps its "
                                "shadow until the next Update"),
               ("SPHERES", "Spheres", "Cycles shows the spheres' shadows (what EEVEE shows with "
                                      "EEVEE Moving Shadows: Spheres)")),
        description="How Cycles renders the moving virtual objects' shadows on the relit "
                    "surfaces (takes effect on Update)")
    eevee_shadows: EnumProperty(
        name="EEVEE Moving Shadows", default="MAPS",
        items=(("MAPS", "Shadow Maps", "EEVEE draws the moving virtual objects' real meshes "
                                       "into its soft shadow maps (two lamps; others use "
                                       "spheres): compiles as fast with any sphere count"),
               ("SPHERES", "Spheres", "EEVEE shows the spheres' shadows, as Cycles does "
                                      "without rays; compiling grows with the count")),
        description="How EEVEE renders the moving virtual objects' shadows on the relit "
                    "surfaces (takes effect on Update)")
    overlay: EnumProperty(name="Overlay", items=OVERLAY_ITEMS, default="NONE",
                          update=update_overlay,
                          description="Draw the last precompute's radiosity elements or links "
                                      "in the viewport")


classes = (RelightSceneSettings,)


def attach():
    bpy.types.Scene.relight = bpy.props.PointerProperty(type=RelightSceneSettings)
    bpy.types.Object.relight_role = EnumProperty(
        name="Relight Role", items=ROLE_ITEMS, default="relit",
        description="How Relight treats this object: relit (a photographed surface), occluder "
                    "(only blocks light), ignored, virtual (an object added to the photo), or "
                    "receiver (AR: a stand-in for a photographed surface)")
    bpy.types.Object.relight_shadows = EnumProperty(
        name="Shadows", items=SHADOW_ITEMS, default="EXACT",
        description="How a virtual object's shadows are computed")
    bpy.types.Object.relight_spheres = bpy.props.IntProperty(
        name="Spheres", default=DEFAULT_SPHERES, min=1, max=MAX_SPHERES,
        description="Spheres approximating a moving virtual object: more give closer shadows "
                    "under small lamps and slower renders (each sphere is evaluated per lamp at "
                    "every shading point; EEVEE's shader compiler fails at about 128). Update "
                    "after changing it")
    if _forget_all not in bpy.app.handlers.load_post:
        bpy.app.handlers.load_post.append(_forget_all)
    from .. import preferences
    from ..relight_addon.blender import pipeline, state
    state.attach(preferences.keep_limit_bytes)
    pipeline.configure(memory_limit=preferences.memory_limit_bytes)


def detach():
    if _forget_all in bpy.app.handlers.load_post:
        bpy.app.handlers.load_post.remove(_forget_all)
    if hasattr(bpy.types.Scene, "relight"):
        del bpy.types.Scene.relight
    for prop in ("relight_role", "relight_shadows", "relight_spheres"):
        if hasattr(bpy.types.Object, prop):
            delattr(bpy.types.Object, prop)
    from ..relight_addon.blender import state
    state.detach()
    if not bpy.app.background:
        from ..relight_addon.blender import overlay
        overlay.unregister_overlay()
