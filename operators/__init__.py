# SPDX-License-Identifier: GPL-3.0-or-later
"""Operators of the Relight extension: thin wrappers that call ``relight_addon``."""

import bpy

from . import ar, capture, dependencies, eevee, lamps, precompute, settings, settle, unwrap

_modules = (settings, dependencies, precompute, unwrap, lamps, eevee, settle, ar, capture)

classes = tuple(cls for module in _modules for cls in module.classes)

_register, _unregister = bpy.utils.register_classes_factory(classes)


def _one_line_tooltips():
    """Blender shows a class docstring's line breaks in its tooltip: one paragraph instead."""
    for cls in classes:
        if cls.__doc__ and "bl_description" not in cls.__dict__:
            cls.bl_description = " ".join(cls.__doc__.split())


def _ar_draw():
    from ..relight_addon.blender import ar_draw
    return ar_draw


def _relit_draw():
    from ..relight_addon.blender import relit_draw
    return relit_draw


def register():
    _one_line_tooltips()
    _register()
    settings.attach()
    settle.attach()
    capture.attach()
    _ar_draw().register_draw()          # AR mode's live viewport (nothing in background mode)
    _relit_draw().register_draw()       # the relit preview in Solid shading (likewise)


def unregister():
    _relit_draw().unregister_draw()
    _ar_draw().unregister_draw()
    capture.detach()
    settle.detach()
    settings.detach()
    _unregister()
