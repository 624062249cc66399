# SPDX-License-Identifier: GPL-3.0-or-later
"""Operators of the Relight extension: thin wrappers that call ``relight_addon``."""

import bpy

from . import dependencies, precompute, unwrap

_modules = (dependencies, precompute, unwrap)

classes = tuple(cls for module in _modules for cls in module.classes)


register, unregister = bpy.utils.register_classes_factory(classes)
