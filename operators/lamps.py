# SPDX-License-Identifier: GPL-3.0-or-later
"""``relight.match_lamp_powers``: set each real lamp's power from its estimated exitance.

The precompute estimates, per lamp, the factor s_k between the exitance Blender's light gives
and the exitance that explains the photo (in photo units, a texel value being a radiosity).
Blender renders a diffuse surface as radiance = radiosity / pi, so the power that lights a
virtual object consistently with the photographed surfaces is P0 * pi * s_k.  The relit
materials must not change: each driver's ``p / P0`` and the light's ``relight_power0`` follow
the new power, so every I_k stays 1 until the user changes a lamp.
"""

import math

import bpy

from .base import RelightOperator
from .settings import STATUS, status

POWER0 = "relight_power0"


def _power_drivers(light_data):
    """(driver, its variable's name) of generated materials' drivers that read
    ``light_data.energy`` (not its colour: those keep their own expression)."""
    for mat in bpy.data.materials:
        if not mat.get("relight_generated") or mat.node_tree is None:
            continue
        ad = mat.node_tree.animation_data
        for fc in (ad.drivers if ad else []):
            for var in fc.driver.variables:
                t = var.targets[0]
                if t.id == light_data and t.data_path == "energy":
                    yield fc, var.name


def match_lamp_powers(scene):
    """Returns (changed names, warnings)."""
    st = status(scene)
    if not st or not st.get("exitance_scale"):
        return [], ["Run Precompute first: there is no exitance estimate"]
    changed, warnings = [], []
    for name, s in zip(st["lamps"], st["exitance_scale"]):
        obj = bpy.data.objects.get(name)
        if obj is None or obj.type != "LIGHT":
            warnings.append(f"'{name}' is not a light object: left alone")
            continue
        light = obj.data
        if light.library is not None or getattr(light, "override_library", None) is not None:
            warnings.append(f"Light '{name}' is linked from a library: left alone")
            continue
        p0 = float(light.get(POWER0, light.energy))
        new = p0 * math.pi * float(s)
        if not math.isfinite(new) or new <= 0:
            warnings.append(f"Lamp '{name}': no usable estimate ({s!r}); left alone")
            continue
        light.energy = new
        light[POWER0] = new
        for fc, var in _power_drivers(light):
            fc.driver.expression = f"{var} / {new!r}"
        changed.append(name)
    if changed:
        from ..relight_addon.blender import eevee_probe
        probe = eevee_probe.find_volume(scene)
        if probe is not None:      # its driver divides by the old powers
            eevee_probe.drive_intensity(scene, probe.data)
    st = dict(st)
    st["exitance_scale"] = [1.0 / math.pi if n in changed else s
                            for n, s in zip(st["lamps"], st["exitance_scale"])]
    scene[STATUS] = st
    return changed, warnings


class RELIGHT_OT_match_lamp_powers(RelightOperator, bpy.types.Operator):
    """Set each real lamp's power from the exitance estimated from the photo, so that virtual
    objects are lit like the photographed surfaces (the relit textures do not change)"""

    bl_idname = "relight.match_lamp_powers"
    bl_label = "Match Lamp Powers to Photo"
    bl_options = {'REGISTER', 'UNDO'}

    @classmethod
    def disabled_reason(cls, context):
        reason = super().disabled_reason(context)
        if reason:
            return reason
        from ..relight_addon.blender import write
        st = status(context.scene)
        if not st or not st.get("exitance_scale") or not write.has_relight_data(context.scene):
            return "Run Precompute first: there is no estimate of the lamps to match"
        return None

    def execute(self, context):
        changed, warnings = match_lamp_powers(context.scene)
        for w in warnings:
            self.report({'WARNING'}, w)
        if not changed:
            return {'CANCELLED'}
        self.report({'INFO'}, f"Relight: power of {len(changed)} lamp(s) set from the photo")
        return {'FINISHED'}


classes = (RELIGHT_OT_match_lamp_powers,)
