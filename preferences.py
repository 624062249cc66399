# SPDX-License-Identifier: GPL-3.0-or-later
"""Add-on preferences (Edit > Preferences > Add-ons > Relight)."""

import bpy
from bpy.props import FloatProperty

DEFAULT_MEMORY_LIMIT_GB = 8.0


class RELIGHT_AddonPreferences(bpy.types.AddonPreferences):
    bl_idname = __package__

    memory_limit_gb: FloatProperty(
        name="Memory Limit (GB)", default=DEFAULT_MEMORY_LIMIT_GB, min=0.0, soft_min=0.5,
        soft_max=256.0, precision=2,
        description="Precompute refuses to start when its estimated peak memory exceeds this")

    def draw(self, context):
        self.layout.prop(self, "memory_limit_gb")


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


classes = (RELIGHT_AddonPreferences,)


register, unregister = bpy.utils.register_classes_factory(classes)
