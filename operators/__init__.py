# SPDX-License-Identifier: GPL-3.0-or-later
"""Operators of the Relight extension: thin wrappers that call ``relight_addon``."""

import bpy

from . import dependencies, eevee, lamps, precompute, settings, settle, unwrap

_modules = (settings, dependencies, precompute, unwrap, lamps, eevee, settle)

classes = tuple(cls for module in _modules for cls in module.classes)

_register, _unregister = bpy.utils.register_classes_factory(classes)


def _one_line_tooltips():
    """Blender shows a class docstring's line breaks in its tooltip: one paragraph instead."""
    for cls in classes:
        if cls.__doc__ and "bl_description" not in cls.__dict__:
            cls.bl_description = " ".join(cls.__doc__.split())


def register():
    _one_line_tooltips()
    _register()
    settings.attach()
    settle.attach()


def unregister():
    settle.detach()
    settings.detach()
    _unregister()
