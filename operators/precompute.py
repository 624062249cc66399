# SPDX-License-Identifier: GPL-3.0-or-later
"""Precompute / Update / Restore / Clear operators.

``relight.precompute``: read the scene (main thread), solve the radiosity (bpy-free core),
write the display maps and relit materials (main thread).  ``relight.update`` does the same
only when the scene changed since the last precompute, and keeps the radiosity mesh and links
when only the photos changed.  Both share :class:`_PrecomputeRunner` (no operator calls
another through ``bpy.ops``):

* From a script (EXEC context) or in background mode they run synchronously in ``execute()``.
* Interactively (``invoke``) the solve runs in a worker thread; a modal timer polls it, shows
  the progress in the status bar and the window's progress indicator, and writes the results
  on the main thread when it is done.  Esc (or right click) sets a flag that the worker's
  progress callback turns into ``Cancelled``; nothing is written, so the scene is unchanged.
  While a solve runs, neither operator can start another (their poll says why).
"""

import dataclasses
import threading
import time

import bpy
from bpy.props import EnumProperty

from .base import RelightOperator
from .settings import (CORRECTION_ITEMS, PRESET_ITEMS, forget, last_result, remember, status,
                       store_status, update_overlay)

# The solve running in a worker thread (one at a time).
_ACTIVE = {"job": None}


def _modules():
    # Imported lazily so that registering the add-on stays fast and never fails on numpy.
    from ..relight_addon.blender import read, write
    from ..relight_addon.core.radiosity import precompute
    return read, write, precompute


def run_precompute(data, preset, correction="TEXEL", progress=None, reuse=None, proxy_faces=0):
    """The bpy-free precompute: shadow-free textures and per-lamp display maps."""
    from ..relight_addon.core.relight.shadowfree import ShadowFreeOptions, shadow_free
    options = ShadowFreeOptions(mode=correction.lower(), preset=preset,
                                proxy_faces=int(proxy_faces))
    return shadow_free(data, options, progress=progress, reuse=reuse)


def user_message(ex) -> str:
    """One sentence for an exception of the precompute: bad input (SceneError, ValueError)
    says what is wrong; anything else is a bug and says so."""
    if isinstance(ex, ValueError):          # SceneError is a ValueError
        return str(ex)
    return f"{type(ex).__name__}: {ex} (unexpected: please report it)"


def reusable_solution(scene, preset, correction):
    """The last run's radiosity solution when Update may keep its mesh and links."""
    result = last_result(scene)
    if result is None or correction == "ELEMENT" or result.options.preset != preset \
            or result.options.mode == "element" \
            or result.options.proxy_faces != proxy_faces_of(scene):
        return None
    return result.solution


def proxy_faces_of(scene):
    """The scene's setting for a dense mesh's radiosity proxy (0: the preset's)."""
    return int(getattr(getattr(scene, "relight", None), "proxy_faces", 0))


def virtual_lights(scene):
    """Names of the scene's lights that are not real lamps of its last precompute: lights added
    since are virtual (not in the photo), and stay so until Clear."""
    st = status(scene)
    if not st:
        return set()
    real = set(st.get("lamps", ())) - set(st.get("virtual", ()))
    return {o.name for o in scene.objects if o.type == "LIGHT"} - real


def read_for_precompute(context, virtual=None):
    """Read the scene (relit materials are read through to the user's originals; ``virtual``
    lights, by default those added since the last precompute, are read off in the photo).
    Returns (scene_data, report, error message or None)."""
    read, write, _ = _modules()
    from ..relight_addon.core.scene import SceneError
    if virtual is None:
        virtual = virtual_lights(context.scene)
    try:
        data, report = read.read_scene(context, virtual=virtual)
    except SceneError as ex:
        return None, None, str(ex)
    if report.errors:
        return data, report, "; ".join(report.errors)
    if data.image is None or not (data.image >= 0).any():
        return data, report, "No face uses an image texture: nothing to relight"
    textured = {report.sources.get(report.groups[int(g)][0], report.groups[int(g)][0])
                for g in set(data.group[data.image >= 0].tolist())}
    objs = [bpy.data.objects.get(n) for n in textured]
    if objs and all(o is not None and not write.slots_editable(o) for o in objs):
        return data, report, ("Every textured object is linked from a library (read-only): make "
                              "them local or add library overrides first")
    return data, report, None


def memory_error(context, data, preset):
    """Bad input check: an error message when the estimated peak memory of the solve exceeds
    the add-on preference ``memory_limit_gb`` (checked before solving; nothing is changed)."""
    from .. import preferences
    from ..relight_addon.core.radiosity.memory import estimate_precompute_memory, proxy_need
    from ..relight_addon.core.radiosity.presets import PROXY_FACTOR, get_preset
    faces = proxy_faces_of(context.scene)
    estimate = estimate_precompute_memory(data, preset, proxy_faces=faces)
    limit = preferences.memory_limit_bytes(context)
    if estimate <= limit:
        return None
    proxy = faces or get_preset(preset).proxy_faces
    if data.n_patches > PROXY_FACTOR * proxy:
        # name what makes the peak: the mesh itself, the proxy's solve or the photos
        need = proxy_need(data, preset, proxy)
        if need == "faces":
            hint = (f"decimate the mesh first (its {data.n_patches} faces alone need that much: "
                    f"Blender's Decimate modifier)")
        elif need == "photos":
            hint = "use smaller photos"
        else:
            hint = (f"lower Proxy Faces (now {proxy}: the {data.n_patches} faces are solved on "
                    f"a decimated proxy of that many), use smaller photos")
    else:
        hint = "choose a lower preset, use fewer faces or smaller photos"
    return (f"Relight precompute ({preset}) needs about {estimate / 2**30:.2f} GB, more than the "
            f"{limit / 2**30:.2f} GB memory limit (add-on preferences): {hint}, or raise the "
            f"limit")


class SolveJob:
    """The radiosity solve in a worker thread. ``state``: running / done / cancelled / failed."""

    def __init__(self, scene_data, preset, correction="TEXEL", reuse=None, proxy_faces=0):
        self.scene_data = scene_data
        self.proxy_faces = proxy_faces
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
                                         progress=self._progress, reuse=self.reuse,
                                         proxy_faces=self.proxy_faces)
            self.state = "cancelled" if self._cancel.is_set() else "done"
        except precompute.Cancelled:
            self.state = "cancelled"
        except Exception as ex:  # reported on the main thread
            self.error = user_message(ex)
            self.state = "failed"


def _group_names(data, report, result):
    """Names of the groups of ``result``'s patches.  A result kept from an earlier read (Update
    without a new solve) numbers its groups as that read did; its patches are the room's, in
    order, so each of its groups is named by the current read's group of the same patches."""
    import numpy as np
    kept = np.asarray(result.solution.scene.group)
    now = np.asarray(data.without_virtual().group)
    names = {}
    if len(kept) == len(now):
        for old, new in zip(*np.unique(np.stack([kept, now]), axis=1)):
            names[int(old)] = report.groups[int(new)][0]
    return lambda g: names.get(g, report.groups[g][0])


def virtual_indices(report):
    """Lamp indices of the virtual lamps of a read (lights that are not in the photo)."""
    return [k for k, src in enumerate(report.lamp_sources) if src.get("virtual")]


def solve_running() -> bool:
    job = _ACTIVE["job"]
    return job is not None and job.state == "running"


class _PrecomputeRunner(RelightOperator):
    """Read, solve (synchronously or in a worker thread with a modal timer), write."""

    _timer = None
    _job = None
    _data = None
    _read_report = None
    _run_correction = "TEXEL"
    _t0 = 0.0

    @classmethod
    def disabled_reason(cls, context):
        if solve_running():
            return "A precompute is running: wait for it, or press Esc to cancel it"
        return super().disabled_reason(context)

    def _read(self, context, preset):
        """(data, report) or None after reporting the error (nothing is changed)."""
        self._t0 = time.perf_counter()
        data, read_report, error = read_for_precompute(context)
        error = error or memory_error(context, data, preset)
        if error:
            self.report({'ERROR'}, error)
            return None
        return data, read_report

    def _solve_now(self, context, data, read_report, preset, correction, reuse=None):
        try:
            solution = run_precompute(data, preset, correction, reuse=reuse,
                                      proxy_faces=proxy_faces_of(context.scene))
        except Exception as ex:
            self.report({'ERROR'}, f"Relight precompute failed: {user_message(ex)}")
            return {'CANCELLED'}
        return self._finish(context, data, read_report, solution, correction)

    def _solve_modal(self, context, data, read_report, preset, correction, reuse=None):
        if bpy.app.background or context.window is None:
            return self._solve_now(context, data, read_report, preset, correction, reuse)
        self._data, self._read_report, self._run_correction = data, read_report, correction
        self._job = _ACTIVE["job"] = SolveJob(data, preset, correction, reuse,
                                              proxy_faces_of(context.scene)).start()
        wm = context.window_manager
        self._timer = wm.event_timer_add(0.1, window=context.window)
        wm.progress_begin(0, 100)
        wm.modal_handler_add(self)
        self._status(context, "Relight: starting (Esc to cancel)")
        return {'RUNNING_MODAL'}

    def _finish(self, context, data, read_report, solution, correction):
        _, write, _ = _modules()
        from ..relight_addon.core.scene import scene_fingerprint
        scene = context.scene
        from ..relight_addon.core.relight.diagnose import diagnose
        summary = write.write_results(context, data, read_report, solution)
        moving = self._sync_spheres(context, read_report, solution)
        for sentence in diagnose(solution, solution.photographed,
                                 _group_names(data, read_report, solution)):
            read_report.warn(sentence)
        warnings = list(read_report.warnings)          # write_results appended its own
        virtual = virtual_indices(read_report)
        room = data.without_virtual()
        real = data.without_lamps(virtual)
        objects = bool(data.virtual.any())
        kept = getattr(solution, "room", None) is not None or not objects
        store_status(scene, solution, time.perf_counter() - self._t0, correction,
                     remember(scene, solution), warnings, scene_fingerprint(data),
                     scene_fingerprint(real, textures=False),
                     scene_fingerprint(room.without_lamps(virtual)),
                     [data.lamp_names[k] for k in virtual],
                     scene_fingerprint(room) if kept else "", objects)
        settings = getattr(scene, "relight", None)
        if settings is not None:
            update_overlay(settings, context)
        for w in warnings:
            self.report({'WARNING'}, w)
        done = (f"Relight: {summary['materials']} material(s), {summary['images']} image(s), "
                f"{summary['lamps']} lamp(s)")
        if moving["objects"]:
            done += f", {moving['objects']} moving object(s)"
        if warnings:
            self.report({'WARNING'}, f"{done}, {len(warnings)} warning(s): see the Relight panel")
        else:
            self.report({'INFO'}, done)
        return {'FINISHED'}

    def _sync_spheres(self, context, read_report, result=None):
        """The moving virtual objects' sphere shadows (fitted again only if their mesh or
        sphere count changed; their transforms are followed by drivers), settled where they
        stand (ray-traced with ``result``, the scene's last result) unless the scene's
        setting says not to."""
        from ..relight_addon.blender import sphere_nodes
        settings = getattr(context.scene, "relight", None)
        try:
            summary = sphere_nodes.sync(context.scene, context.evaluated_depsgraph_get(),
                                        result=result,
                                        settle_shadows=bool(getattr(settings, "settle", True)))
            for w in summary.get("warnings", ()):
                read_report.warn(w)
            return summary
        except Exception as ex:
            read_report.warn(f"Moving objects' shadows could not be made: {user_message(ex)}")
            return {"objects": 0, "fitted": 0, "materials": 0}

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
        if _ACTIVE["job"] is self._job:
            _ACTIVE["job"] = None

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
            return self._finish(context, self._data, self._read_report, job.result,
                                self._run_correction)
        if job.state == "failed":
            self.report({'ERROR'}, f"Relight precompute failed: {job.error}")
        return {'CANCELLED'}


class RELIGHT_OT_precompute(_PrecomputeRunner, bpy.types.Operator):
    """Estimate the real lamps and reflectances from the photos and write relightable
    materials: the photographed shadows are removed and each lamp gets a map (Esc cancels)"""

    bl_idname = "relight.precompute"
    bl_label = "Precompute"
    bl_options = {'REGISTER', 'UNDO'}

    preset: EnumProperty(name="Quality", items=PRESET_ITEMS, default="medium",
                         description="Quality preset (speed <-> accuracy)")
    correction: EnumProperty(name="Shadow Removal", items=CORRECTION_ITEMS, default="TEXEL",
                             description="How the photographed shadows of the real lamps are "
                                         "removed from the textures")

    def execute(self, context):
        read = self._read(context, self.preset)
        if read is None:
            return {'CANCELLED'}
        return self._solve_now(context, *read, self.preset, self.correction)

    def invoke(self, context, event):
        read = self._read(context, self.preset)
        if read is None:
            return {'CANCELLED'}
        return self._solve_modal(context, *read, self.preset, self.correction)


class RELIGHT_OT_update(_PrecomputeRunner, bpy.types.Operator):
    """Bring the relit materials up to date: nothing to do when only lamp powers changed (the
    drivers follow them); the radiosity mesh and links are kept when only the photos changed;
    everything is recomputed after geometry, lamp or quality changes"""

    bl_idname = "relight.update"
    bl_label = "Update"
    bl_options = {'REGISTER', 'UNDO'}

    def execute(self, context):
        return self._update(context, modal=False)

    def invoke(self, context, event):
        return self._update(context, modal=True)

    def _update(self, context, modal):
        from ..relight_addon.core.scene import scene_fingerprint
        _, write, _ = _modules()
        scene = context.scene
        settings = scene.relight
        preset, correction = settings.preset, settings.correction
        read = self._read(context, preset)
        if read is None:
            return {'CANCELLED'}
        data, report = read
        st = status(scene)
        reuse = None
        if st and write.has_relight_data(scene) and st.get("preset") == preset \
                and st.get("correction") == correction:
            if st.get("fingerprint") == scene_fingerprint(data):
                moving = self._sync_spheres(context, report, last_result(scene))
                for w in report.warnings:
                    self.report({'WARNING'}, w)
                if moving["fitted"] or moving["objects"]:
                    self.report({'INFO'}, f"Relight: {moving['objects']} moving object(s), "
                                          f"{moving['fitted']} fitted again; the maps are up "
                                          "to date")
                else:
                    self.report({'INFO'}, "Relight: up to date (nothing changed since the last "
                                          "precompute)")
                return {'FINISHED'}
            quick = self._room_kept(context, data, report, st, correction)
            if quick is not None:
                return quick
            virtual = virtual_indices(report)
            if st.get("geometry") == scene_fingerprint(data.without_lamps(virtual), False):
                reuse = reusable_solution(scene, preset, correction)
        run = self._solve_modal if modal else self._solve_now
        return run(context, *read, preset, correction, reuse)

    def _room_kept(self, context, data, report, st, correction):
        """Without a new solve of the room when only virtual lamps or virtual objects were
        added, moved, changed or deleted: the last result of the room (without its objects)
        keeps the real lamps' maps, the virtual lamps' maps are made on it again if they
        changed, then the objects' change is added (virtual.py).  None: a new solve is needed."""
        from ..relight_addon.core.relight.virtual import add_lamps, add_objects, keep_lamps
        from ..relight_addon.core.scene import scene_fingerprint
        last = last_result(context.scene)
        if last is None or last.denominator is None:
            return None
        base = last.room if last.room is not None else (None if st.get("objects") else last)
        if base is None:
            return None
        virtual = virtual_indices(report)
        room = data.without_virtual()
        try:
            if st.get("room") and st.get("room") == scene_fingerprint(room):
                result = base
            elif st.get("real") == scene_fingerprint(room.without_lamps(virtual)):
                result = self._virtual_lamps(context, data, base, virtual, add_lamps, keep_lamps)
            else:
                return None
            if data.virtual.any():
                result = add_objects(result, data)
            elif result.room is not None:
                result = dataclasses.replace(result, room=None)
        except Exception as ex:
            self.report({'ERROR'}, f"Relight update failed: {user_message(ex)}")
            return {'CANCELLED'}
        return self._finish(context, data, report, result, correction)

    @staticmethod
    def _virtual_lamps(context, data, base, virtual, add_lamps, keep_lamps):
        """``base`` (the room's result) with its virtual lamps' maps made again for the virtual
        lamps of ``data`` (no new solve of the room)."""
        import numpy as np
        st = status(context.scene)
        names = list(base.solution.scene.lamp_names)
        base = keep_lamps(base, [names.index(n) for n in st.get("virtual", ()) if n in names])
        lights = data.lights
        rows = [np.flatnonzero(lights.lamp == k) for k in virtual]
        rows = np.concatenate(rows) if rows else np.zeros(0, np.int64)
        order = {k: j for j, k in enumerate(virtual)}
        sub = dataclasses.replace(lights, **{f.name: getattr(lights, f.name)[rows]
                                             for f in dataclasses.fields(lights)})
        sub.lamp = np.array([order[int(k)] for k in sub.lamp], np.int32)
        return add_lamps(base, sub, [data.lamp_names[k] for k in virtual])


class RELIGHT_OT_restore_originals(RelightOperator, bpy.types.Operator):
    """Put your original materials back on the relit objects of this scene. The relit images
    and materials are kept (to compare, or to reassign by hand); Clear removes them"""

    bl_idname = "relight.restore_originals"
    bl_label = "Restore Originals"
    bl_options = {'REGISTER', 'UNDO'}

    @classmethod
    def disabled_reason(cls, context):
        reason = super().disabled_reason(context)
        if reason:
            return reason
        _, write, _ = _modules()
        if not write.relit_slot_count(context.scene):
            return "Nothing to restore: no object shows this scene's relit materials"
        return None

    def execute(self, context):
        _, write, _ = _modules()
        n = write.restore_originals(context.scene)
        self.report({'INFO'}, f"Relight: {n} material slot(s) restored")
        return {'FINISHED'}


class RELIGHT_OT_clear(RelightOperator, bpy.types.Operator):
    """Restore your original materials, then delete the images and materials Relight made for
    this scene and its precompute status (your own data is never deleted)"""

    bl_idname = "relight.clear"
    bl_label = "Clear Relight Data"
    bl_options = {'REGISTER', 'UNDO'}

    @classmethod
    def disabled_reason(cls, context):
        reason = super().disabled_reason(context)
        if reason:
            return reason
        _, write, _ = _modules()
        if solve_running():
            return "A precompute is running: wait for it, or press Esc to cancel it"
        if not write.has_relight_data(context.scene) and status(context.scene) is None:
            return "Nothing to clear: this scene has no Relight data"
        return None

    def execute(self, context):
        _, write, _ = _modules()
        s = write.clear_relight_data(context.scene)
        forget(context.scene)
        settings = getattr(context.scene, "relight", None)
        if settings is not None:
            update_overlay(settings, context)
        self.report({'INFO'}, f"Relight: removed {s['materials']} material(s) and "
                              f"{s['images']} image(s)")
        return {'FINISHED'}


classes = (RELIGHT_OT_precompute, RELIGHT_OT_update, RELIGHT_OT_restore_originals,
           RELIGHT_OT_clear)
