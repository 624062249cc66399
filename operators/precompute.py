# SPDX-License-Identifier: GPL-3.0-or-later
"""Precompute / Restore / Clear operators.

``relight.precompute``: read the scene (main thread), solve the radiosity (bpy-free core),
write the display maps and relit materials (main thread).

* From a script (EXEC context) or in background mode it runs synchronously in ``execute()``.
* Interactively (``invoke``) the solve runs in a worker thread; a modal timer polls it, shows
  the progress in the status bar and the window's progress indicator, and writes the results
  on the main thread when it is done.  Esc (or right click) sets a flag that the worker's
  progress callback turns into ``Cancelled``; nothing is written, so the scene is unchanged.
"""

import threading
import time

import bpy
from bpy.props import BoolProperty, EnumProperty

from .settings import CORRECTION_ITEMS, LAST_RESULT, PRESET_ITEMS, store_status, update_overlay


def _modules():
    # Imported lazily so that registering the add-on stays fast and never fails on numpy.
    from ..relight_addon.blender import read, write
    from ..relight_addon.core.radiosity import precompute
    return read, write, precompute


def run_precompute(data, preset, correction="TEXEL", progress=None, reuse=None):
    """The bpy-free precompute: shadow-free textures and per-lamp display maps."""
    from ..relight_addon.core.relight.shadowfree import ShadowFreeOptions, shadow_free
    options = ShadowFreeOptions(mode=correction.lower(), preset=preset)
    return shadow_free(data, options, progress=progress, reuse=reuse)


def reusable_solution(preset, correction):
    """The last run's radiosity solution when Update may keep its mesh and links."""
    result = LAST_RESULT.get("result")
    if result is None or correction == "ELEMENT" or result.options.preset != preset \
            or result.options.mode == "element":
        return None
    return result.solution


def read_for_precompute(context):
    """Read the scene as it is without our relit materials (they are emissive copies).
    Returns (scene_data, report, error message or None)."""
    read, write, _ = _modules()
    with write.originals_swapped(context):
        data, report = read.read_scene(context)
    if report.errors:
        return data, report, "; ".join(report.errors)
    if data.image is None or not (data.image >= 0).any():
        return data, report, "No face uses an image texture: nothing to relight"
    textured = {report.groups[int(g)][0] for g in set(data.group[data.image >= 0].tolist())}
    objs = [bpy.data.objects.get(n) for n in textured]
    if objs and all(o is not None and not write.slots_editable(o) for o in objs):
        return data, report, ("Every textured object is linked from a library (read-only): make "
                              "them local or add library overrides first")
    return data, report, None


def memory_error(context, data, preset):
    """Bad input check: an error message when the estimated peak memory of the solve exceeds
    the add-on preference ``memory_limit_gb`` (checked before solving; nothing is changed)."""
    from .. import preferences
    from ..relight_addon.core.radiosity.memory import estimate_precompute_memory
    estimate, limit = estimate_precompute_memory(data, preset), preferences.memory_limit_bytes(context)
    if estimate <= limit:
        return None
    return (f"Relight precompute ({preset}) needs about {estimate / 2**30:.2f} GB, more than the "
            f"{limit / 2**30:.2f} GB memory limit (add-on preferences): choose a lower preset, "
            f"fewer faces, or raise the limit")


class SolveJob:
    """The radiosity solve in a worker thread. ``state``: running / done / cancelled / failed."""

    def __init__(self, scene_data, preset, correction="TEXEL", reuse=None):
        self.scene_data = scene_data
        self.preset = preset
        self.correction = correction
        self.reuse = reuse
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

    def join(self, timeout=None):
        self._thread.join(timeout)
        return not self._thread.is_alive()

    def _progress(self, fraction, message):
        _, _, precompute = _modules()
        if self._cancel.is_set():
            raise precompute.Cancelled("cancelled by the user")
        self.fraction = float(fraction)
        self.message = str(message)

    def _run(self):
        _, _, precompute = _modules()
        try:
            self.result = run_precompute(self.scene_data, self.preset, self.correction,
                                         progress=self._progress, reuse=self.reuse)
            self.state = "cancelled" if self._cancel.is_set() else "done"
        except precompute.Cancelled:
            self.state = "cancelled"
        except Exception as ex:  # reported on the main thread
            self.error = f"{type(ex).__name__}: {ex}"
            self.state = "failed"


class RELIGHT_OT_precompute(bpy.types.Operator):
    """Solve the radiosity of the scene and write relightable materials (Esc cancels)"""

    bl_idname = "relight.precompute"
    bl_label = "Precompute"
    bl_options = {'REGISTER', 'UNDO'}

    preset: EnumProperty(name="Preset", items=PRESET_ITEMS, default="medium",
                         description="Quality preset (speed <-> accuracy)")
    correction: EnumProperty(name="Shadow Removal", items=CORRECTION_ITEMS, default="TEXEL",
                             description="How the photographed shadows of the real lamps are "
                                         "removed from the textures")
    reuse_solution: BoolProperty(default=False, options={'HIDDEN', 'SKIP_SAVE'},
                                 description="Keep the last run's radiosity mesh and links (set "
                                             "by Update when only the photos changed)")

    _timer = None
    _job = None
    _data = None
    _read_report = None

    _t0 = 0.0

    def _finish(self, context, data, read_report, solution):
        _, write, _ = _modules()
        summary = write.write_results(context, data, read_report, solution)
        if hasattr(solution, "stats"):
            from ..relight_addon.core.scene import scene_fingerprint
            store_status(context.scene, solution, time.perf_counter() - self._t0, self.correction,
                         scene_fingerprint(data), scene_fingerprint(data, textures=False))
            LAST_RESULT["result"] = solution
            settings = getattr(context.scene, "relight", None)
            if settings is not None:
                update_overlay(settings, context)
        for w in summary["warnings"]:
            self.report({'WARNING'}, w)
        self.report({'INFO'}, f"Relight: {summary['materials']} material(s), "
                              f"{summary['images']} image(s), {summary['lamps']} lamp(s)")
        return {'FINISHED'}

    def execute(self, context):
        self._t0 = time.perf_counter()
        data, read_report, error = read_for_precompute(context)
        error = error or memory_error(context, data, self.preset)
        if error:
            self.report({'ERROR'}, error)
            return {'CANCELLED'}
        reuse = reusable_solution(self.preset, self.correction) if self.reuse_solution else None
        try:
            solution = run_precompute(data, self.preset, self.correction, reuse=reuse)
        except Exception as ex:
            self.report({'ERROR'}, f"Relight precompute failed: {type(ex).__name__}: {ex}")
            return {'CANCELLED'}
        return self._finish(context, data, read_report, solution)

    def invoke(self, context, event):
        if bpy.app.background or context.window is None:
            return self.execute(context)
        self._t0 = time.perf_counter()
        data, read_report, error = read_for_precompute(context)
        error = error or memory_error(context, data, self.preset)
        if error:
            self.report({'ERROR'}, error)
            return {'CANCELLED'}
        self._data, self._read_report = data, read_report
        reuse = reusable_solution(self.preset, self.correction) if self.reuse_solution else None
        self._job = SolveJob(data, self.preset, self.correction, reuse).start()
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

    def modal(self, context, event):
        job = self._job
        if event.type in {'ESC', 'RIGHTMOUSE'} and event.value == 'PRESS':
            job.cancel()
            self._cleanup(context)
            self.report({'INFO'}, "Relight precompute cancelled: nothing changed")
            return {'CANCELLED'}
        if event.type != 'TIMER':
            return {'PASS_THROUGH'}
        if job.state == "running":
            context.window_manager.progress_update(int(100 * job.fraction))
            self._status(context, f"Relight: {job.message} ({100 * job.fraction:.0f} %) - Esc to cancel")
            return {'RUNNING_MODAL'}
        self._cleanup(context)
        if job.state == "done":
            return self._finish(context, self._data, self._read_report, job.result)
        if job.state == "failed":
            self.report({'ERROR'}, f"Relight precompute failed: {job.error}")
        return {'CANCELLED'}


class RELIGHT_OT_restore(bpy.types.Operator):
    """Put the original materials back on the relit objects (the relit data is kept until Clear)"""

    bl_idname = "relight.restore_originals"
    bl_label = "Restore Originals"
    bl_options = {'REGISTER', 'UNDO'}

    def execute(self, context):
        _, write, _ = _modules()
        n = write.restore_originals(context)
        self.report({'INFO'}, f"Relight: {n} material slot(s) restored")
        return {'FINISHED'}


class RELIGHT_OT_clear(bpy.types.Operator):
    """Restore the original materials and remove every image and material Relight generated"""

    bl_idname = "relight.clear"
    bl_label = "Clear Relight Data"
    bl_options = {'REGISTER', 'UNDO'}

    def execute(self, context):
        _, write, _ = _modules()
        s = write.clear_relight_data(context)
        self.report({'INFO'}, f"Relight: removed {s['materials']} material(s) and "
                              f"{s['images']} image(s)")
        return {'FINISHED'}


class RELIGHT_OT_update(bpy.types.Operator):
    """Re-run the precompute if the scene changed since the last one: nothing to do when only
    lamp powers changed; the radiosity mesh and links are kept when only the photos changed;
    everything is recomputed after geometry, lamp or quality changes"""

    bl_idname = "relight.update"
    bl_label = "Update"
    bl_options = {'REGISTER', 'UNDO'}

    def execute(self, context):
        return self._run(context, "EXEC_DEFAULT")

    def invoke(self, context, event):
        return self._run(context, "INVOKE_DEFAULT")

    def _run(self, context, how):
        from ..relight_addon.core.scene import scene_fingerprint
        from .settings import status
        _, write, _ = _modules()
        settings = context.scene.relight
        st = status(context.scene)
        reuse = False
        if st and write.has_relight_data() and st.get("preset") == settings.preset \
                and st.get("correction") == settings.correction:
            data, _, error = read_for_precompute(context)
            if error is None and st.get("fingerprint") == scene_fingerprint(data):
                self.report({'INFO'}, "Relight: up to date (nothing changed since the last "
                                      "precompute)")
                return {'FINISHED'}
            reuse = (error is None and st.get("geometry") == scene_fingerprint(data, False)
                     and reusable_solution(settings.preset, settings.correction) is not None)
        return bpy.ops.relight.precompute(how, preset=settings.preset,
                                          correction=settings.correction, reuse_solution=reuse)


classes = (RELIGHT_OT_precompute, RELIGHT_OT_update, RELIGHT_OT_restore, RELIGHT_OT_clear)
