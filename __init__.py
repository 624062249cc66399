# SPDX-License-Identifier: GPL-3.0-or-later
"""Relight: relight photographed scenes with hierarchical radiosity.

Extension entry point. Blender installs this package as ``bl_ext.<repo>.relight``, so every
import inside the extension is relative. The maths lives in ``relight_addon`` (``core`` never
imports bpy); ``operators`` and ``panels`` hold the thin UI layer.
"""

from . import operators, panels, preferences

# Registration order: preferences, operators, then the panels that reference them.
_modules = (preferences, operators, panels)


def register():
    for module in _modules:
        module.register()


def unregister():
    for module in reversed(_modules):
        module.unregister()
