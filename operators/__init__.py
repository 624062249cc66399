# SPDX-License-Identifier: GPL-3.0-or-later
"""Operators of the Relight extension: thin wrappers that call ``relight_addon``."""

import bpy

from . import dependencies, eevee, lamps, precompute, settings, unwrap

_modules = (settings, dependencies, precompute, unwrap, lamps, eevee)

classes = tuple(cls for module in _modules for cls in module.classes)

_register, _unregister = bpy.utils.register_classes_factory(classes)


def register():
    _register()
    settings.attach()


def unregister():
    settings.detach()
    _unregister()
