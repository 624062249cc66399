# SPDX-License-Identifier: GPL-3.0-or-later
"""RELIGHT_OT_check_dependencies: report which bundled libraries import in this Blender."""

import importlib

import bpy

from .base import RelightOperator

# (import name, label shown to the user). numpy is Blender's own and always present.
DEPENDENCIES = (
    ("numpy", "numpy"),
    ("scipy", "scipy"),
    ("colour", "colour-science"),
    ("cv2", "opencv"),
    ("xatlas", "xatlas"),
    ("embreex", "embreex"),
)


def probe_dependencies():
    """Return ``{label: version or None}``; None when the import fails.

    Imports happen here, never at module import time, so enabling the add-on stays fast and
    a missing wheel cannot stop the add-on from registering.
    """
    found = {}
    for module_name, label in DEPENDENCIES:
        try:
            module = importlib.import_module(module_name)
        except Exception:  # ImportError, or a broken binary wheel (OSError, ...)
            found[label] = None
        else:
            found[label] = str(getattr(module, "__version__", "?"))
    return found


def ray_backend(found):
    """Name of the ray-casting backend the core will use (``raycast.active_backend_name``).

    Falls back to a guess from the probed imports if the core module cannot be imported.
    """
    try:
        from ..relight_addon import blender  # noqa: F401  (registers the mathutils fallback)
        from ..relight_addon.core.geometry import raycast

        name = raycast.active_backend_name()
    except Exception as ex:  # the core needs numpy; never let the check itself fail
        guess = "embree" if found.get("embreex") else "bvhtree"
        return f"{guess} (core not importable: {type(ex).__name__})"
    return name or "none"


class RELIGHT_OT_check_dependencies(RelightOperator, bpy.types.Operator):
    """Check which bundled libraries are available and which ray-casting backend is active"""

    bl_idname = "relight.check_dependencies"
    bl_label = "Check Dependencies"
    bl_options = {'REGISTER'}

    def execute(self, context):
        found = probe_dependencies()
        available = [f"{label} {version}" for label, version in found.items() if version is not None]
        missing = [label for label, version in found.items() if version is None]
        message = "Relight: available: {}; missing: {}; ray casting: {}".format(
            ", ".join(available) or "none",
            ", ".join(missing) or "none",
            ray_backend(found),
        )
        self.report({'INFO'}, message)
        return {'FINISHED'}


classes = (RELIGHT_OT_check_dependencies,)
