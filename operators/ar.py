# SPDX-License-Identifier: GPL-3.0-or-later
"""AR mode's operators: Set Up AR and Clear AR, thin wrappers of relight_addon/blender/ar.py
(Update, ``relight.update``, refreshes a scene set up for AR through the pipeline's hook).

Set Up AR runs as Precompute does: synchronously from scripts and in background mode, in a
worker thread with progress and Esc to cancel from the sidebar (precompute.JobRunner).
"""

import bpy

from .base import RelightOperator
from .precompute import JobRunner, busy_reason


def _ar():
    from ..relight_addon.blender import ar
    return ar


class RELIGHT_OT_ar_setup(JobRunner, bpy.types.Operator):
    """Make the scene's render the composite over the photo: the camera's background image is
    the photo, the World's Environment Texture lights the virtual objects, the receivers show
    the photo with the objects' soft shadows. Moving the objects needs nothing afterwards;
    Update after adding objects or changing the environment"""

    bl_idname = "relight.ar_setup"
    bl_label = "Set Up AR"
    # no REGISTER: "Adjust Last Operation" would run the set-up again without progress
    bl_options = {'UNDO'}
    _kind = "AR set up"

    @classmethod
    def disabled_reason(cls, context):
        return _ar().unsupported_reason() or super().disabled_reason(context)

    def _prepare(self, context, preset=None, correction=None):
        from ..relight_addon.blender import pipeline
        try:
            return _ar().prepare(context, "setup")
        except pipeline.PipelineError as ex:
            self.report({'ERROR'}, str(ex))
            return None


class RELIGHT_OT_ar_clear(RelightOperator, bpy.types.Operator):
    """Undo Set Up AR: the receivers' own materials, the compositor, the view layer's passes
    and the render settings as they were; the images and node groups AR made are deleted"""

    bl_idname = "relight.ar_clear"
    bl_label = "Clear AR"
    bl_options = {'REGISTER', 'UNDO'}

    @classmethod
    def disabled_reason(cls, context):
        reason = busy_reason()
        if reason:
            return reason
        if not _ar().is_set_up(context.scene):
            return "This scene is not set up for AR"
        return None

    def execute(self, context):
        _ar().clear(context.scene)
        self.report({'INFO'}, "AR cleared: the scene is as it was before Set Up AR")
        return {'FINISHED'}


classes = (RELIGHT_OT_ar_setup, RELIGHT_OT_ar_clear)
