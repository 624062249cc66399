# SPDX-License-Identifier: GPL-3.0-or-later
"""Panels of the Relight extension: the sidebar "Relight" tab of the 3D viewport."""

import bpy

from . import ar, capture, main

# the main panel first: the AR and Capture sub-panels name it as their parent
_modules = (main, ar, capture)

classes = tuple(cls for module in _modules for cls in module.classes)


register, unregister = bpy.utils.register_classes_factory(classes)
