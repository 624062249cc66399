# SPDX-License-Identifier: GPL-3.0-or-later
"""Per-scene Relight settings (``scene.relight``) and the status of the last precompute.

The status lives in the scene's ID property ``relight_status`` (a dict), so it is saved with the
.blend and follows undo like the relit materials it describes.
"""

import bpy
from bpy.props import EnumProperty

STATUS = "relight_status"

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


class RelightSceneSettings(bpy.types.PropertyGroup):
    preset: EnumProperty(name="Quality", items=PRESET_ITEMS, default="medium",
                         description="Quality preset (speed <-> accuracy)")
    correction: EnumProperty(name="Shadow Removal", items=CORRECTION_ITEMS, default="TEXEL",
                             description="How the photographed shadows of the real lamps are "
                                         "removed from the textures")


def status(scene):
    """The last precompute's status dict, or None."""
    st = scene.get(STATUS)
    return st.to_dict() if hasattr(st, "to_dict") else st


def store_status(scene, result, seconds, correction, fingerprint=""):
    """Write what the panel shows: counts, time, model misfit, lamps and their exitances (and
    the scene fingerprint that Update compares)."""
    stats = result.stats
    scale = [float(x) for x in result.exitance_scale]
    mean = sum(scale) / len(scale) if scale and sum(scale) > 0 else 1.0
    scene[STATUS] = {
        "preset": result.options.preset, "correction": correction,
        "elements": int(stats.get("elements", 0)), "links": int(stats.get("links", 0)),
        "seconds": float(seconds), "misfit": float(stats.get("photo_misfit", float("nan"))),
        "lamps": list(result.solution.scene.lamp_names),
        "exitance_scale": scale, "relative_exitance": [s / mean for s in scale],
        "fingerprint": fingerprint,
    }


classes = (RelightSceneSettings,)


def attach():
    bpy.types.Scene.relight = bpy.props.PointerProperty(type=RelightSceneSettings)


def detach():
    if hasattr(bpy.types.Scene, "relight"):
        del bpy.types.Scene.relight
