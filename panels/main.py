# SPDX-License-Identifier: GPL-3.0-or-later
"""RELIGHT_PT_main: the top panel of the sidebar "Relight" tab."""

import functools
import math
import os

import bpy


@functools.lru_cache(maxsize=1)
def addon_version():
    """Version string from blender_manifest.toml, the single source of truth."""
    import tomllib

    path = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "blender_manifest.toml")
    try:
        with open(path, "rb") as fh:
            return str(tomllib.load(fh).get("version", "?"))
    except (OSError, ValueError):
        return "?"


def status_lines(scene):
    """(text, icon) lines describing the last precompute (empty before the first)."""
    from ..operators.settings import status
    st = status(scene)
    if not st:
        return []
    lines = [(f"{st['elements']:,} elements, {st['links']:,} links", 'MESH_GRID'),
             (f"{st['seconds']:.1f} s ({st['preset']}, shadow removal {st['correction'].lower()})",
              'TIME')]
    if math.isfinite(st.get("misfit", float("nan"))):
        lines.append((f"Model vs photo: {100 * st['misfit']:.1f} % RMS", 'INFO'))
    for name, rel in zip(st["lamps"], st["relative_exitance"]):
        obj = bpy.data.objects.get(name)
        now = ""
        if obj is not None and obj.type == "LIGHT" and obj.data.get("relight_power0"):
            now = f"  I = {obj.data.energy / obj.data['relight_power0']:.2f}"
        lines.append((f"{name}: estimated {rel:.2f}x{now}", 'LIGHT_AREA'))
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
        layout.operator("relight.unwrap_missing", icon='UV')
        settings = getattr(context.scene, "relight", None)
        if settings is not None:
            col = layout.column(align=True)
            col.prop(settings, "preset")
            col.prop(settings, "correction")
            row = layout.row(align=True)
            op = row.operator("relight.precompute", text="Precompute", icon='LIGHT_AREA')
            op.preset = settings.preset
            op.correction = settings.correction
            row.operator("relight.update", icon='FILE_REFRESH')
        if settings is not None:
            layout.prop(settings, "overlay")
        lines = status_lines(context.scene)
        if lines:
            box = layout.box()
            for text, icon in lines:
                box.label(text=text, icon=icon)
            box.operator("relight.match_lamp_powers", icon='LIGHT_SUN')
        row = layout.row(align=True)
        row.operator("relight.restore_originals", icon='LOOP_BACK')
        row.operator("relight.clear", icon='TRASH')


classes = (RELIGHT_PT_main,)
