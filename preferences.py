# SPDX-License-Identifier: GPL-3.0-or-later
"""Add-on preferences (Edit > Preferences > Add-ons > Relight)."""

import bpy
from bpy.props import BoolProperty, FloatProperty

DEFAULT_MEMORY_LIMIT_GB = 8.0
DEFAULT_KEEP_LIMIT_MB = 1024.0


class RELIGHT_AddonPreferences(bpy.types.AddonPreferences):
    bl_idname = __package__

    memory_limit_gb: FloatProperty(
        name="Memory Limit (GB)", default=DEFAULT_MEMORY_LIMIT_GB, min=0.0, soft_min=0.5,
        soft_max=256.0, precision=2,
        description="Precompute refuses to start when its estimated peak memory exceeds this")
    keep_solution: BoolProperty(
        name="Keep the Solution in the File", default=True,
        description="Save the radiosity solution in the .blend, so that Update after reopening "
                    "adds virtual lamps and objects in about a second instead of solving the "
                    "room again (the panel shows what it adds to the file)")
    keep_limit_mb: FloatProperty(
        name="Largest Kept Solution (MB)", default=DEFAULT_KEEP_LIMIT_MB, min=0.0,
        soft_max=8192.0, precision=0,
        description="A solution larger than this is not saved in the file (Update after "
                    "reopening then solves the room again)")

    def draw(self, context):
        col = self.layout.column()
        col.prop(self, "memory_limit_gb")
        col.prop(self, "keep_solution")
        row = col.row()
        row.enabled = self.keep_solution
        row.prop(self, "keep_limit_mb")


def get(context=None):
    """The preferences of this add-on, or None when it is registered without being enabled
    as an add-on (e.g. imported by a script or a test)."""
    context = context or bpy.context
    addon = context.preferences.addons.get(__package__)
    return addon.preferences if addon is not None else None


def memory_limit_bytes(context=None):
    prefs = get(context)
    gb = prefs.memory_limit_gb if prefs is not None else DEFAULT_MEMORY_LIMIT_GB
    return gb * 2**30


def keep_limit_bytes(context=None):
    """The largest solution kept in a saved file (0: none kept)."""
    try:
        prefs = get(context)
    except Exception:                 # no context (a save from a script at exit)
        prefs = None
    if prefs is None:
        return DEFAULT_KEEP_LIMIT_MB * 2**20
    return prefs.keep_limit_mb * 2**20 if prefs.keep_solution else 0


classes = (RELIGHT_AddonPreferences,)


register, unregister = bpy.utils.register_classes_factory(classes)
