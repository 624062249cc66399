# SPDX-License-Identifier: GPL-3.0-or-later
"""Precompute / Update / Restore / Show Relit / Clear operators: thin wrappers of the bridge's
pipeline (relight_addon/blender/pipeline.py), which reads, decides, computes and writes.

* From a script (EXEC context) or in background mode they run synchronously in ``execute()``.
* Interactively (``invoke``) the computation runs in a worker thread; a modal timer polls it,
  shows the progress in the status bar and the window's progress indicator, and writes the
  results on the main thread when it is done.  Esc cancels at once: nothing is written, so the
  scene is unchanged; the worker stops at its next progress report, and no other run can start
  before it has (the buttons say so).
"""

import threading

import bpy
from bpy.props import EnumProperty

from .base import RelightOperator
from .settings import CORRECTION_ITEMS, PRESET_ITEMS, update_overlay

# The computation running in a worker thread (one at a time), until its thread has ended.
_ACTIVE = {"job": None}


def _pipeline():
    # Imported lazily so that registering the add-on stays fast and never fails on numpy.
    from ..relight_addon.blender import pipeline
    return pipeline


class SolveJob:
    """A pipeline Job's computation in a worker thread. ``state``: running / done / cancelled /
    failed."""

    def __init__(self, job):
        self.job = job
        self.label = getattr(job, "label", "precompute")      # what busy_reason names
        self.fraction = 0.0
        self.message = "Starting"
        self.result = None
        self.error = None
        self.state = "running"
        self._cancel = threading.Event()
        self._thread = threading.Thread(target=self._run, name="relight-solve", daemon=True)

    def start(self):
        self._thread.start()
        return self

    def cancel(self):
        self._cancel.set()

    @property
    def cancelled(self) -> bool:
        return self._cancel.is_set()

    @property
    def alive(self) -> bool:
        return self._thread.is_alive()

    def join(self, timeout=None):
        self._thread.join(timeout)
        return not self._thread.is_alive()

    def progress(self, fraction, message):
        from ..relight_addon.core.progress import Cancelled
        if self._cancel.is_set():
            raise Cancelled("cancelled by the user")
        self.fraction = max(self.fraction, float(fraction))
        self.message = str(message)

    def _run(self):
        from ..relight_addon.core.progress import Cancelled
        try:
            self.result = self.job.compute(progress=self.progress)
            self.state = "cancelled" if self._cancel.is_set() else "done"
        except Cancelled:
            self.state = "cancelled"
        except Exception as ex:  # reported on the main thread
            self.error = _pipeline().user_message(ex)
            self.state = "failed"


def solve_running() -> bool:
    """A computation's thread is alive (running, or stopping after a cancel)."""
    job = _ACTIVE["job"]
    return job is not None and job.alive


def _release_when_stopped():
    """Timer: forget a cancelled job once its thread has ended, then redraw the buttons."""
    job = _ACTIVE["job"]
    if job is not None and job.alive:
        return 0.1
    _ACTIVE["job"] = None
    for window in getattr(bpy.context.window_manager, "windows", ()):
        for area in window.screen.areas:
            area.tag_redraw()
    return None


def busy_reason():
    job = _ACTIVE["job"]
    if job is None or not job.alive:
        return None
    label = getattr(job, "label", "precompute")
    if job.state == "running" and not job.cancelled:
        return f"A {label} is running: wait for it, or press Esc to cancel it"
    return f"The cancelled {label} is stopping: a moment"


def _report_outcome(op, outcome):
    for w in outcome.warnings:
        op.report({'WARNING'}, w)
    if outcome.warnings and outcome.action not in ("none", "reapply"):
        op.report({'WARNING'}, f"{outcome.message}, {len(outcome.warnings)} warning(s): see "
                               "the Relight panel")
    else:
        op.report({'INFO'}, outcome.message)


class JobRunner(RelightOperator):
    """Prepare, compute (synchronously or in a worker thread with a modal timer), finish: the
    pipeline's jobs by default; an operator with a job of its own (a ``compute(progress)``,
    an ``action``, a ``label``) overrides ``_prepare``, ``_finish`` and ``_abandon``."""

    _timer = None
    _solve = None
    _kind = "update"

    @classmethod
    def disabled_reason(cls, context):
        return busy_reason()

    def _arguments(self):
        """What ``_prepare`` takes beside the context (Precompute: its preset and removal)."""
        return ()

    def _abandon(self, context, job):
        """The job was cancelled or failed: undo what ``_prepare`` wrote (the pipeline's
        prepare writes nothing)."""

    def execute(self, context):
        job = self._prepare(context, *self._arguments())
        return {'CANCELLED'} if job is None else self._now(context, job)

    def invoke(self, context, event):
        job = self._prepare(context, *self._arguments())
        return {'CANCELLED'} if job is None else self._start(context, job)

    def _prepare(self, context, preset=None, correction=None):
        pipeline = _pipeline()
        try:
            return pipeline.prepare(context, self._kind, preset, correction)
        except pipeline.PipelineError as ex:
            self.report({'ERROR'}, str(ex))
            return None

    def _finish(self, context, job, result):
        pipeline = _pipeline()
        try:
            outcome = pipeline.finish(context, job, result)
        except Exception as ex:
            self.report({'ERROR'}, f"Relight {self._kind} failed: {pipeline.user_message(ex)}")
            return {'CANCELLED'}
        settings = getattr(context.scene, "relight", None)
        if settings is not None:
            update_overlay(settings, context)
        _report_outcome(self, outcome)
        return {'FINISHED'}

    def _now(self, context, job):
        pipeline = _pipeline()
        try:
            result = job.compute()
        except Exception as ex:
            self._abandon(context, job)
            self.report({'ERROR'}, f"Relight {self._kind} failed: {pipeline.user_message(ex)}")
            return {'CANCELLED'}
        return self._finish(context, job, result)

    def _start(self, context, job):
        if bpy.app.background or context.window is None or job.action in ("none", "reapply",
                                                                           "rewrite"):
            return self._now(context, job)
        self._job = job
        self._solve = _ACTIVE["job"] = SolveJob(job).start()
        wm = context.window_manager
        self._timer = wm.event_timer_add(0.1, window=context.window)
        wm.progress_begin(0, 100)
        wm.modal_handler_add(self)
        self._status(context, "Relight: starting (Esc to cancel)")
        return {'RUNNING_MODAL'}

    def _status(self, context, text):
        ws = getattr(context, "workspace", None)
        if ws is not None:
            ws.status_text_set(text)

    def _cleanup(self, context):
        wm = context.window_manager
        if self._timer is not None:
            wm.event_timer_remove(self._timer)
            self._timer = None
        wm.progress_end()
        self._status(context, None)
        if _ACTIVE["job"] is self._solve and not self._solve.alive:
            _ACTIVE["job"] = None
        elif _ACTIVE["job"] is self._solve and not bpy.app.timers.is_registered(
                _release_when_stopped):
            bpy.app.timers.register(_release_when_stopped, first_interval=0.1)

    def modal(self, context, event):
        solve = self._solve
        if event.type == 'ESC' and event.value == 'PRESS':
            solve.cancel()
            self._cleanup(context)
            self._abandon(context, self._job)
            self.report({'INFO'}, f"Relight {self._kind} cancelled: nothing changed")
            return {'CANCELLED'}
        if event.type != 'TIMER':
            return {'PASS_THROUGH'}
        if solve.state == "running":
            context.window_manager.progress_update(int(100 * solve.fraction))
            self._status(context, f"Relight: {solve.message} ({100 * solve.fraction:.0f} %) - "
                                  "Esc to cancel")
            return {'RUNNING_MODAL'}
        self._cleanup(context)
        if solve.state == "done":
            return self._finish(context, self._job, solve.result)
        self._abandon(context, self._job)
        if solve.state == "failed":
            self.report({'ERROR'}, f"Relight {self._kind} failed: {solve.error}")
        return {'CANCELLED'}


class RELIGHT_OT_precompute(JobRunner, bpy.types.Operator):
    """Estimate the real lamps and reflectances from the photos and write relightable
    materials: the photographed shadows are removed and each lamp gets a map (Esc cancels).
    Lamps already precomputed keep their power in the photo (Clear forgets it)"""

    bl_idname = "relight.precompute"
    bl_label = "Precompute"
    # no REGISTER: "Adjust Last Operation" would run the whole solve again without progress
    bl_options = {'UNDO'}
    _kind = "precompute"

    preset: EnumProperty(name="Quality", items=PRESET_ITEMS, default="medium",
                         description="Quality preset (speed <-> accuracy)")
    correction: EnumProperty(name="Shadow Removal", items=CORRECTION_ITEMS, default="TEXEL",
                             description="How the photographed shadows of the real lamps are "
                                         "removed from the textures")

    def _arguments(self):
        return self.preset, self.correction


class RELIGHT_OT_update(JobRunner, bpy.types.Operator):
    """Bring the relit materials up to date: virtual lamps and objects are added to the kept
    solution (no new solve), the relit materials are shown again after Restore, and the room is
    solved again only after its surfaces, photos or photographed lamps' places changed (lamp
    powers need no Update: the materials follow them)"""

    bl_idname = "relight.update"
    bl_label = "Update"
    bl_options = {'UNDO'}
    _kind = "update"


class RELIGHT_OT_restore_originals(RelightOperator, bpy.types.Operator):
    """Put your original materials back on the relit objects of this scene. The relit images
    and materials are kept (Show Relit or Update puts them back; Clear deletes them)"""

    bl_idname = "relight.restore_originals"
    bl_label = "Restore Originals"
    bl_options = {'REGISTER', 'UNDO'}

    @classmethod
    def disabled_reason(cls, context):
        from ..relight_addon.blender import materials
        if not materials.relit_slot_count(context.scene):
            return "Nothing to restore: no object shows this scene's relit materials"
        return None

    def execute(self, context):
        n = _pipeline().restore(context.scene)
        self.report({'INFO'}, f"Relight: {n} material slot(s) restored")
        return {'FINISHED'}


class RELIGHT_OT_show_relit(RelightOperator, bpy.types.Operator):
    """Show this scene's relit materials again where Restore Originals put yours back (nothing
    is computed)"""

    bl_idname = "relight.show_relit"
    bl_label = "Show Relit"
    bl_options = {'REGISTER', 'UNDO'}

    @classmethod
    def disabled_reason(cls, context):
        from ..relight_addon.blender import state, write
        st = state.status(context.scene)
        if not st or not write.has_relight_data(context.scene):
            return "Nothing to show: this scene has no relit materials (Precompute first)"
        if not st.get("restored"):
            return "The relit materials are shown"
        return None

    def execute(self, context):
        n = _pipeline().show_relit(context.scene)
        self.report({'INFO'}, f"Relight: {n} material slot(s) show the relit materials")
        return {'FINISHED'}


class RELIGHT_OT_clear(RelightOperator, bpy.types.Operator):
    """Restore your original materials, then delete the images and materials Relight made for
    this scene and its precompute state (your own data is never deleted)"""

    bl_idname = "relight.clear"
    bl_label = "Clear Relight Data"
    bl_options = {'REGISTER', 'UNDO'}

    @classmethod
    def disabled_reason(cls, context):
        reason = busy_reason()
        if reason:
            return reason
        from ..relight_addon.blender import state, write
        if not write.has_relight_data(context.scene) and state.status(context.scene) is None:
            return "Nothing to clear: this scene has no Relight data"
        return None

    def execute(self, context):
        s = _pipeline().clear(context.scene)
        settings = getattr(context.scene, "relight", None)
        if settings is not None:
            update_overlay(settings, context)
        self.report({'INFO'}, f"Relight: removed {s['materials']} material(s) and "
                              f"{s['images']} image(s)")
        return {'FINISHED'}


classes = (RELIGHT_OT_precompute, RELIGHT_OT_update, RELIGHT_OT_restore_originals,
           RELIGHT_OT_show_relit, RELIGHT_OT_clear)
