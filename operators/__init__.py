# SPDX-License-Identifier: GPL-3.0-or-later
"""Operators of the Relight extension: thin wrappers that call ``relight_addon``."""

import bpy

from . import dependencies, precompute, unwrap

_modules = (dependencies, precompute, unwrap)

classes = tuple(cls for module in _modules for cls in module.classes)


def register():
    for cls in classes:
        bpy.utils.register_class(cls)


def unregister():
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
