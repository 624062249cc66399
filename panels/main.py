# SPDX-License-Identifier: GPL-3.0-or-later
"""RELIGHT_PT_main: the top panel of the sidebar "Relight" tab."""

import functools
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
        # A menu of the quality presets: picking one starts the (modal) precompute.
        layout.operator_menu_enum("relight.precompute", "preset", text="Precompute", icon='LIGHT_AREA')
        row = layout.row(align=True)
        row.operator("relight.restore_originals", icon='LOOP_BACK')
        row.operator("relight.clear", icon='TRASH')


classes = (RELIGHT_PT_main,)
