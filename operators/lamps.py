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


def match_lamp_powers(scene):
    """Returns (changed labels, warnings)."""
    from ..relight_addon.blender import eevee_probe, ids, state
    from ..relight_addon.blender.drivers import drivers_reading, ratio_expression
    st = state.status(scene)
    if not st or not st.get("exitance_scale"):
        return [], ["Run Precompute first: there is no exitance estimate"]
    records = state.lamp_records(scene)
    changed, warnings = [], []
    for r, s in zip(records, st["exitance_scale"]):
        name = r["label"]
        obj = state.find_light(scene, r) if r.get("kind", "light") == "light" else None
        if obj is None:
            warnings.append(f"'{name}' is not a light object: left alone")
            continue
        light = obj.data
        if light.library is not None or getattr(light, "override_library", None) is not None:
            warnings.append(f"Light '{name}' is linked from a library: left alone")
            continue
        # the power its map was computed at: the record's, never the light's present power
        p0 = float(r["p0"])
        new = p0 * math.pi * float(s)
        if not math.isfinite(new) or new <= 0:
            warnings.append(f"Lamp '{name}': no usable estimate ({s!r}); left alone")
            continue
        light.energy = new
        light[ids.POWER0] = new
        for mat in bpy.data.materials:
            if ids.is_generated(mat) and mat.node_tree is not None:
                for fc, var in drivers_reading(mat.node_tree, light, "energy"):
                    fc.driver.expression = ratio_expression(var, new)
        # the maps now stand for the lamp at this power, in the photo too
        r["p0"] = new
        if not r.get("virtual"):
            r["photo"] = new if float(r.get("photo", 0.0)) > 0 else 0.0
        changed.append(name)
    if changed:
        probe = eevee_probe.find_volume(scene)
        if probe is not None:      # its driver divides by the old powers
            eevee_probe.drive_intensity(scene, probe.data)
    state.update_status(scene, lamp_records=records,
                        exitance_scale=[1.0 / math.pi if r["label"] in changed else s
                                        for r, s in zip(records, st["exitance_scale"])])
    return changed, warnings


class RELIGHT_OT_match_lamp_powers(RelightOperator, bpy.types.Operator):
    """Set each real lamp's power from the exitance estimated from the photo, so that virtual
    objects are lit like the photographed surfaces (the relit textures do not change)"""

    bl_idname = "relight.match_lamp_powers"
    bl_label = "Match Lamp Powers to Photo"
    bl_options = {'REGISTER', 'UNDO'}

    @classmethod
    def disabled_reason(cls, context):
        from ..relight_addon.blender import state, write
        st = state.status(context.scene)
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
