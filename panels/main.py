# SPDX-License-Identifier: GPL-3.0-or-later
"""RELIGHT_PT_main: the sidebar "Relight" tab of the 3D viewport."""

import math

import bpy

from ..relight_addon.version import addon_version

# Warnings listed in the panel (all of them are in the Info editor and the status dict).
PANEL_WARNINGS = 8


def status_lines(scene):
    """(text, icon) lines describing the last precompute (empty before the first)."""
    from ..relight_addon.blender import state
    st = state.status(scene)
    if not st:
        return []
    records = state.lamp_records(scene)
    lines = [(f"{st['elements']:,} elements, {st['links']:,} links", 'MESH_GRID'),
             (f"{st['seconds']:.1f} s ({st['preset']}, shadow removal {st['correction'].lower()})",
              'TIME')]
    if st.get("proxy_faces", 0):
        lines.append((f"{st['input_faces']:,} faces solved on a proxy of {st['proxy_faces']:,} "
                      f"(mean distance {1000 * st['proxy_deviation']:.1f} mm)", 'MOD_DECIM'))
    if math.isfinite(st.get("misfit", float("nan"))):
        lines.append((f"Model vs photo: {100 * st['misfit']:.1f} % RMS", 'INFO'))
    if st.get("rho_mean", -1) > 0:
        rho, sigma = st["rho_mean"], st.get("rho_sigma", -1)
        lines.append((f"Mean reflectance (from the shadows' depth): {rho:.2f} "
                      f"\u00b1 {rho * sigma:.2f}" if sigma >= 0 else
                      f"Mean reflectance: {rho:.2f} (the photo's shadows do not tell it)", 'INFO'))
    n = len(st["lamps"])
    for j, name in enumerate(st["lamps"]):
        record = records[j] if j < len(records) else {}
        obj = state.find_light(scene, record) if record.get("uid") else None
        now = ""
        if record.get("kind", "light") == "light" and obj is None and record:
            now = "; deleted: off"
        elif obj is not None and float(record.get("p0", 0.0)) > 0:
            now = f"; now at {obj.data.energy / float(record['p0']):.2f}x"
            if obj.name != name:
                now += f" (light '{obj.name}')"
        ratio = st.get("photo_ratio", [-1] * n)[j]
        sigma = st.get("photo_sigma", [-1] * n)[j]
        used = st.get("photo_used", [False] * n)[j]
        weight = st.get("photo_weight", [1.0] * n)[j] if used else 0.0
        if n == 1:
            view = "set power used (one lamp: the photo fixes only the overall level)"
        elif ratio <= 0 or sigma < 0 or not math.isfinite(sigma):
            view = "set power used (the photo cannot tell)"
        else:
            taken = ("set power used" if not used else "photo used" if weight >= 1.0 else
                     "photo used in part")
            view = (f"photo says {ratio:.2f}x +- {100 * sigma:.0f} % of its set power, relative "
                    f"to the other lamps; {taken}")
        lines.append((f"{name}: {view}{now}", 'LIGHT_AREA'))
    return lines


def warning_lines(scene, limit=PANEL_WARNINGS):
    from ..relight_addon.blender import state
    st = state.status(scene) or {}
    warnings = list(st.get("warnings", ()))
    lines = warnings[:limit]
    if len(warnings) > limit:
        lines.append(f"... and {len(warnings) - limit} more (Info editor)")
    return lines


class RELIGHT_PT_main(bpy.types.Panel):
    bl_idname = "RELIGHT_PT_main"
    bl_label = "Relight"
    bl_space_type = 'VIEW_3D'
    bl_region_type = 'UI'
    bl_category = "Relight"

    def draw(self, context):
        layout = self.layout
        layout.label(text=f"Relight {addon_version()}", icon='LIGHT')
        layout.operator("relight.check_dependencies", icon='CHECKMARK')

        box = layout.box()
        box.label(text="Scene", icon='SCENE_DATA')
        box.operator("relight.unwrap_missing", icon='UV')
        obj = context.active_object
        if obj is not None and obj.type in {'MESH', 'CURVE', 'SURFACE', 'FONT', 'META'} \
                and hasattr(obj, "relight_role"):
            raw = obj.get("relight_role")
            if isinstance(raw, str):          # set as a plain custom property by a script
                box.label(text=f"{obj.name}: role '{raw}' (custom property)", icon='OBJECT_DATA')
            else:
                box.prop(obj, "relight_role", text=f"{obj.name} Role")
            if getattr(obj, "relight_role", None) == "virtual" and \
                    hasattr(obj, "relight_shadows"):
                row = box.row(align=True)
                row.prop(obj, "relight_shadows")
                if obj.relight_shadows == "SPHERES":
                    row.prop(obj, "relight_spheres")

        settings = getattr(context.scene, "relight", None)
        if settings is not None:
            col = layout.column(align=True)
            col.prop(settings, "preset")
            col.prop(settings, "correction")
            col.prop(settings, "proxy_faces")
            row = layout.row(align=True)
            op = row.operator("relight.precompute", text="Precompute", icon='LIGHT_AREA')
            op.preset = settings.preset
            op.correction = settings.correction
            row.operator("relight.update", icon='FILE_REFRESH')
            layout.prop(settings, "overlay")
            layout.prop(settings, "settle")
        lines = status_lines(context.scene)
        if lines:
            box = layout.box()
            for text, icon in lines:
                box.label(text=text, icon=icon)
            box.operator("relight.match_lamp_powers", icon='LIGHT_SUN')
            box.operator("relight.eevee_light", icon='LIGHTPROBE_VOLUME')
        warnings = warning_lines(context.scene)
        if warnings:
            box = layout.box()
            box.label(text="Warnings", icon='ERROR')
            col = box.column(align=True)
            for text in warnings:
                col.label(text=text)
        row = layout.row(align=True)
        row.operator("relight.restore_originals", icon='LOOP_BACK')
        row.operator("relight.show_relit", icon='LOOP_FORWARDS')
        row.operator("relight.clear", icon='TRASH')


classes = (RELIGHT_PT_main,)
