"""Precompute and Update: the few calls that operators, scripts and tests all use.

One run is three hand-offs, and nothing calls back:

1. :func:`prepare` (main thread) reads the scene (read.py), decides what must be done (the
   Update decisions below) and checks the memory it needs: a :class:`Job`, or a
   :class:`PipelineError` whose sentence says what is wrong (nothing is changed);
2. :meth:`Job.compute` (any thread: bpy-free) solves, or adds virtual lamps and objects to the
   kept solution;
3. :func:`finish` (main thread) writes the maps and relit materials (write.py), the moving
   objects' sphere shadows, the diagnosis and the state (state.py).

:func:`precompute` and :func:`update` do all three at once (scripts, background mode).

What Update does, from what changed since the last run (core/fingerprint.py):

* nothing: the moving objects' spheres are brought up to date, and the relit materials are
  shown again if Restore had put the originals back;
* virtual lamps (added, moved, changed, deleted) and virtual objects: the kept solution of the
  room gains their maps and their shadows and reflections, no new solve;
* a photographed lamp deleted: it is off, no new solve (the photo still shows its light);
* the photos or reflectances only: the radiosity mesh and links are kept;
* the surfaces, or a photographed lamp's place or shape: a new solve.

A lamp of the photo is read at its power and colour in the photo, and a virtual lamp at the
power its map was computed at, whatever the light's settings are now (state.py's lamp
records): dimming, lights out and keyframes are the drivers' business and never change what
Update computes.
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field

import bpy
import numpy as np

from . import eevee_shadow, ids, materials, read, relit_draw, state, write


class PipelineError(Exception):
    """Bad input: its text is one sentence for the user; nothing was changed."""


@dataclass
class Outcome:
    """What a run did: the sentence for the status bar, the warnings, the action taken."""
    message: str
    warnings: list = field(default_factory=list)
    action: str = ""
    summary: dict = field(default_factory=dict)


def user_message(ex) -> str:
    """One sentence for an exception of the precompute: bad input (SceneError, ValueError)
    says what is wrong; anything else is a bug and says so."""
    if isinstance(ex, (ValueError, PipelineError)):          # SceneError is a ValueError
        return str(ex)
    return f"{type(ex).__name__}: {ex} (unexpected: please report it)"


def solve(data, preset, correction="TEXEL", progress=None, reuse=None, proxy_faces=0):
    """The bpy-free precompute: shadow-free textures and per-lamp display maps (``progress``:
    a callback, or the reporter of core.progress already running)."""
    from ..core.relight.shadowfree import ShadowFreeOptions, shadow_free
    options = ShadowFreeOptions(mode=correction.lower(), preset=preset,
                                proxy_faces=int(proxy_faces))
    return shadow_free(data, options, progress=progress, reuse=reuse)


def proxy_faces_of(scene):
    """The scene's setting for a dense mesh's radiosity proxy (0: the preset's)."""
    return int(getattr(getattr(scene, "relight", None), "proxy_faces", 0))


# -- the job ----------------------------------------------------------------------------------

@dataclass
class Job:
    """One Precompute or Update, prepared: what to do (``action``: "solve", "reuse" (photos
    changed: keep the mesh and links), "quick" (virtual lamps and objects on the kept room),
    "rewrite" (the kept result written again), "reapply" (show the relit materials again),
    "none"), on what read of the scene."""
    kind: str
    action: str
    preset: str
    correction: str
    data: object
    report: object
    records: list
    parts: dict
    proxy_faces: int = 0
    base: object = None              # the kept result a quick path or a rewrite starts from
    reuse: object = None             # the solution whose mesh and links a "reuse" keeps
    drop: list = field(default_factory=list)    # virtual lamp labels whose maps are made again
    add: list = field(default_factory=list)     # virtual lamp labels whose maps are made
    # the kept result with the objects in its maps, when they did not change: the lamps it
    # keeps keep their maps, and only the new lamps' get the objects' change
    with_objects: object = None
    note: str = ""                   # why the room is solved again when it might not have been
    t0: float = field(default_factory=time.perf_counter)

    @property
    def solves(self) -> bool:
        return self.action in ("solve", "reuse")

    def compute(self, progress=None):
        """The result to write (bpy-free, any thread), or None when nothing is computed.
        ``progress(fraction, message)`` hears from every stage and from inner loops at least
        every core.progress.TICK seconds, and may raise core.progress.Cancelled to stop."""
        from ..core.progress import reporting
        with reporting(progress):
            if self.action == "solve":
                return solve(self.data, self.preset, self.correction,
                             proxy_faces=self.proxy_faces)
            if self.action == "reuse":
                return solve(self.data, self.preset, self.correction, reuse=self.reuse,
                             proxy_faces=self.proxy_faces)
            if self.action == "quick":
                return _quick(self)
            if self.action == "rewrite":
                return self.base
            return None


def _quick(job):
    """The kept room with its virtual lamps' maps made again where they changed, then the
    virtual objects' change added (core/relight/virtual.py): no new solve.  When the objects
    did not change, the lamps kept keep their maps with the objects, and only the new lamps'
    maps get the objects' change."""
    from ..core.progress import report
    from ..core.relight.virtual import (add_lamps, add_lamps_beside_objects, add_objects,
                                        keep_lamps)
    base = job.base
    names = list(base.solution.scene.lamp_names)
    drop = [names.index(n) for n in job.drop if n in names]
    result = keep_lamps(base, drop)
    objects = bool(job.data.virtual.any())
    if job.add:
        report(0.0, "Lighting the room with the virtual lamps", 0.5 if objects else 1.0)
        data = job.data
        lights = data.lights
        ks = [data.lamp_names.index(n) for n in job.add]
        rows = np.concatenate([np.flatnonzero(lights.lamp == k) for k in ks])
        order = {k: j for j, k in enumerate(ks)}
        sub = dataclasses.replace(lights, **{f.name: getattr(lights, f.name)[rows]
                                             for f in dataclasses.fields(lights)})
        sub.lamp = np.array([order[int(k)] for k in sub.lamp], np.int32)
        if objects and job.with_objects is not None:
            report(0.0, "Lighting the room with the virtual lamps, past the objects", 1.0)
            return add_lamps_beside_objects(keep_lamps(job.with_objects, drop), result, sub,
                                            list(job.add), job.data)
        result = add_lamps(result, sub, list(job.add))
    if objects:
        report(0.5 if job.add else 0.0, "Casting the virtual objects' shadows", 1.0)
        result = add_objects(result, job.data)
    elif result.room is not None:
        result = dataclasses.replace(result, room=None)
    return result


# -- 1. prepare -------------------------------------------------------------------------------

def _check_read(data, report):
    if report.errors:
        raise PipelineError("; ".join(report.errors))
    if data.image is None or not (data.image >= 0).any():
        # the specific reasons first (no UV map, a missing image), then what to do
        uv = [w for w in report.warnings if "UV map" in w]
        images = [w for w in report.warnings if "image" in w.lower() and w not in uv]
        why = (uv + images)[:2]
        raise PipelineError("No face uses an image texture: nothing to relight"
                            + (f" ({'; '.join(why)})" if why else "")
                            + (": the photo textures need the UV maps they were made with "
                               "(import the model with its UVs; Unwrap Missing UVs makes new ones, "
                               "for photos projected on the model afterwards)" if uv else ""))
    textured = {report.sources.get(report.groups[int(g)][0], report.groups[int(g)][0])
                for g in set(data.group[data.image >= 0].tolist())}
    objs = [bpy.data.objects.get(n) for n in textured]
    if objs and all(o is not None and not materials.slots_editable(o) for o in objs):
        raise PipelineError("Every textured object is linked from a library (read-only): make "
                            "them local or add library overrides first")


def memory_error(context, data, preset):
    """An error message when the estimated peak memory of the solve exceeds the add-on
    preference ``memory_limit_gb`` (checked before solving; nothing is changed), or None."""
    from ..core.radiosity.memory import estimate_precompute_memory, proxy_need
    from ..core.radiosity.presets import PROXY_FACTOR, get_preset
    faces = proxy_faces_of(context.scene)
    estimate = estimate_precompute_memory(data, preset, proxy_faces=faces)
    limit = _memory_limit(context)
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


# the add-on preferences' memory limit (bytes), set at registration
_settings = {"memory_limit": lambda context: 8 * 2**30}


def configure(memory_limit=None):
    """Where the pipeline reads the user's preferences (set by the add-on's registration)."""
    if memory_limit is not None:
        _settings["memory_limit"] = memory_limit


def _memory_limit(context):
    return _settings["memory_limit"](context)


def prepare(context, kind="update", preset=None, correction=None) -> Job:
    """Read ``context.scene`` and decide what a Precompute (``kind`` "precompute": always a new
    solve) or an Update does.  Raises PipelineError on bad input."""
    from ..core.fingerprint import scene_parts
    from ..core.scene import SceneError
    scene = context.scene
    if kind == "update" and ids.AR_STATE in scene:    # set up for AR: Update refreshes AR
        from . import ar
        if ar.is_set_up(scene):
            return ar.prepare(context, "update")
    settings = getattr(scene, "relight", None)
    preset = preset or (settings.preset if settings is not None else "medium")
    correction = correction or (settings.correction if settings is not None else "TEXEL")
    st = state.status(scene)
    records = state.lamp_records(scene) if st else []
    try:
        data, report = read.read_scene(context, lamps=records if st else None)
    except SceneError as ex:
        raise PipelineError(str(ex))
    _check_read(data, report)
    parts = scene_parts(data)
    job = Job(kind, "solve", preset, correction, data, report, records, parts,
              proxy_faces_of(scene))
    if kind == "update" and st:
        _decide(scene, job, st)
    if job.solves:
        if not np.any(np.asarray(data.lamp_intensity) > 0):
            raise PipelineError("No lamp of the photo is left in the scene (deleted): undo the "
                                "deletion, or Clear and start again from the lamps as they are")
        error = memory_error(context, data, preset)
        if error:
            raise PipelineError(error)
    return job


def _decide(scene, job, st):
    """Set ``job.action`` (and what the quick path keeps and makes) from what changed."""
    old = state.stored_parts(st)
    new = job.parts
    if not old or st.get("preset") != job.preset or st.get("correction") != job.correction:
        return
    # (the kept solution is read only where a path starts from it: after reopening, an Update
    # that changes nothing reads nothing)
    def kept():
        return state.last_result(scene)
    virtual = {r["label"] for r in job.records if r.get("virtual")}
    real = {r["label"] for r in job.records if not r.get("virtual")}
    present = set(new["lamps"])
    old_lamps = old.get("lamps", {})
    moved_real = {n for n in real & present if new["lamps"][n] != old_lamps.get(n)}
    if new["geometry"] != old.get("geometry") or moved_real:
        return                                          # a new solve
    if new["surfaces"] != old.get("surfaces"):
        result = kept()
        if result is not None and result.options.mode != "element" and \
                result.options.proxy_faces == job.proxy_faces and not set(real) - present:
            job.action, job.reuse = "reuse", result.solution
        return
    new_virtual = {n for n in present if n not in real}
    changed = {n for n in new_virtual if new["lamps"][n] != old_lamps.get(n)}
    removed = virtual - present
    objects = new["objects"] != old.get("objects")
    data = job.data
    # a virtual lamp of patches (a large emissive mesh) is part of the radiosity mesh
    if any(np.any(data.lamp == data.lamp_names.index(n)) for n in changed):
        return
    gone = sorted(real - present)
    if changed or removed or objects:
        result = kept()
        room = None if result is None else (result.room if result.room is not None else
                                            (None if st.get("objects") else result))
        if room is None or room.denominator is None:
            # nothing kept to start from: solve, and say why
            job.note = state.kept_problem(scene) or (
                "no solution of the last run is kept (the file was saved without it: add-on "
                "preferences)" if result is None else "")
            return
        job.action, job.base = "quick", room
        job.drop = sorted((changed | removed) & virtual)
        job.add = sorted(changed)
        if not objects and room is not result and data.virtual.any():
            job.with_objects = result
        return
    if gone != sorted(st.get("gone", ())) or not write.has_relight_data(scene):
        result = kept()
        if result is None:
            return
        job.action, job.base = "rewrite", result
        return
    job.action = "reapply" if st.get("restored") or not materials.relit_slot_count(scene) \
        else "none"


# -- 3. finish --------------------------------------------------------------------------------

def _group_names(data, report, result):
    """Names of the groups of ``result``'s patches.  A result kept from an earlier read (Update
    without a new solve) numbers its groups as that read did; its patches are the room's, in
    order, so each of its groups is named by the current read's group of the same patches."""
    kept = np.asarray(result.solution.scene.group)
    now = np.asarray(data.without_virtual().group)
    names = {}
    if len(kept) == len(now):
        for old, new in zip(*np.unique(np.stack([kept, now]), axis=1)):
            names[int(old)] = report.groups[int(new)][0]
    return lambda g: names.get(g, report.groups[g][0] if 0 <= g < len(report.groups) else "?")


def _records(scene, job, result):
    """The lamp records of ``result``'s lamps, in its order: the known ones kept (their light
    found by identity), the new ones made from the read (their lights given an identity)."""
    known = {r["label"]: r for r in job.records}
    sources = {src["name"]: src for src in job.report.lamp_sources}
    out = []
    for label in result.solution.scene.lamp_names:
        record = dict(known[label]) if label in known else None
        src = sources.get(label)
        if record is None:
            src = src or {}
            record = {"label": label, "uid": None, "object": src.get("object", label),
                      "kind": src.get("kind", "light"), "virtual": bool(src.get("virtual")),
                      "p0": float(src.get("power_ref", 1.0)),
                      "photo": float(src.get("power_photo", 0.0)),
                      "color0": list(src.get("color0", (1.0, 1.0, 1.0)))}
            record.update(exposure=float(src.get("exposure", 0.0)),
                          temperature=float(src.get("temperature", 0.0)))
            if src.get("kind") == "emissive":
                # (node, input, strength then): ID properties hold no mixed lists
                node, socket, s0 = (list(src.get("strength", ())) + [None] * 3)[:3]
                record.update(material=src.get("material") or "",
                              strength={"node": node or "", "input": socket or "",
                                        "value": float(s0 or 0.0)})
            obj = bpy.data.objects.get(record["object"])
            if obj is not None and obj.type == "LIGHT" and ids.editable(obj):
                holders = [o for o in scene.objects if o.type == "LIGHT" and o != obj
                           and ids.uid(o) is not None and ids.uid(o) == ids.uid(obj)]
                # a duplicate (Shift D) carries its original's identity: it gets its own
                record["uid"] = ids.give_uid(obj, fresh=bool(holders) or ids.uid(obj) in
                                             {r.get("uid") for r in job.records})
        elif src is not None and job.solves:
            # a new solve reads the light's exposure and temperature as they are now
            record.update(exposure=float(src.get("exposure", 0.0)),
                          temperature=float(src.get("temperature", 0.0)))
        obj = state.find_light(scene, record) if record.get("uid") else None
        if obj is not None:
            record["object"] = obj.name
        record["gone"] = record.get("kind") == "light" and obj is None
        out.append(record)
    return out


def _lamp_terms(scene, records, warnings):
    terms = []
    for r in records:
        if r.get("kind") == "emissive":
            mat = bpy.data.materials.get(r.get("material") or "")
            s = r.get("strength") or {}
            if mat is not None and s.get("node"):
                terms.append(write.LampTerm(r["label"], None, 1.0, strength=(
                    mat, s["node"], s["input"], float(s["value"]))))
                continue
            warnings.append(f"Lamp '{r['label']}' is not a light object: its intensity is "
                            "fixed at 1")
            terms.append(write.LampTerm(r["label"]))
            continue
        obj = state.find_light(scene, r)
        if obj is None:
            what = "of the photo" if not r.get("virtual") else "(virtual)"
            warnings.append(f"Lamp '{r['label']}' {what} was deleted: it is off (undo the "
                            "deletion to have it back; a new light is a virtual lamp)")
        elif obj is not None:
            changed = [what for what, now, then in (
                ("Exposure", float(getattr(obj.data, "exposure", 0.0)), r.get("exposure")),
                ("Temperature", float(getattr(obj.data, "temperature", 0.0))
                 if getattr(obj.data, "use_temperature", False) else 0.0, r.get("temperature")))
                if then is not None and abs(now - float(then)) > 1e-6]
            if changed:
                warnings.append(f"Lamp '{r['label']}': its {' and '.join(changed)} changed since "
                                "its map was made; the relit surfaces follow its Power and Color "
                                "only (Precompute again to take the change)")
        terms.append(write.LampTerm(r["label"], obj, float(r["p0"]),
                                    tuple(r.get("color0") or (1.0, 1.0, 1.0)), gone=obj is None))
    return terms


def finish(context, job, result) -> Outcome:
    """Write what ``job`` computed (``result``, or None for the actions that compute nothing)
    into ``context.scene``; returns what was done."""
    from ..core.relight.diagnose import diagnose
    if getattr(job, "kind", None) == "ar":    # AR mode's job writes itself (ar.py)
        return job.write(context, result)
    relit_draw.retry()      # the preview draws again from what this writes, even after a failure
    scene = context.scene
    report = job.report
    if job.action in ("none", "reapply"):
        shown = materials.reapply(scene) if job.action == "reapply" else 0
        if shown:
            state.update_status(scene, restored=False)
        from .roles import moving_objects
        moving = sync_spheres(context, report, state.last_result(
            scene, load=bool(moving_objects(scene))))       # (settling traces with it)
        warnings = list(report.warnings)
        if shown:
            message = f"Relight: {shown} material slot(s) show the relit materials again"
        elif moving["fitted"] or moving["objects"]:
            message = (f"Relight: {moving['objects']} moving object(s), {moving['fitted']} "
                       "fitted again; the maps are up to date")
        else:
            message = "Relight: up to date (nothing changed since the last precompute)"
        return Outcome(message, warnings, job.action, moving)
    records = _records(scene, job, result)
    warnings_write = []
    lost = [r["label"] for r in job.records if not r.get("virtual") and r["label"] not in
            {x["label"] for x in records}]
    if lost:
        warnings_write.append(f"Lamp(s) {', '.join(repr(n) for n in lost)} of the photo were "
                              "deleted before this solve: the photo is explained without them "
                              "(undo the deletion and Precompute again to keep them)")
    terms = _lamp_terms(scene, records, warnings_write)
    summary = write.write_results(context, job.data, report, result, terms)
    for w in warnings_write:
        report.warn(w)
    moving = sync_spheres(context, report, result)
    if job.action != "rewrite":
        for sentence in diagnose(result, result.photographed,
                                 _group_names(job.data, report, result)):
            report.warn(sentence)
    view = scene.view_settings.view_transform
    if view not in ("Standard", "Raw"):
        report.warn(f"The view transform is '{view}': the relit surfaces show the photo's "
                    "colours with 'Standard' (Render Properties > Color Management)")
    warnings = list(report.warnings)
    objects = bool(job.data.virtual.any())
    run = state.remember(scene, result)
    # a deleted lamp of the photo keeps its fingerprint: put back, it is that lamp again
    old_lamps = state.stored_parts(state.status(scene)).get("lamps", {})
    parts = dict(job.parts, lamps={**{r["label"]: old_lamps[r["label"]] for r in records
                                      if r.get("gone") and r["label"] in old_lamps},
                                   **job.parts["lamps"]})
    state.store_status(scene, result, time.perf_counter() - job.t0, job.correction, run,
                       warnings, parts, records, objects=objects,
                       kept_room=getattr(result, "room", None) is not None, action=job.action)
    state.update_status(scene, gone=[r["label"] for r in records if r.get("gone")])
    done = (f"Relight: {summary['materials']} material(s), {summary['images']} image(s), "
            f"{summary['lamps']} lamp(s)")
    if job.note:
        done += f" (solved again: {job.note})"

    if moving["objects"]:
        done += f", {moving['objects']} moving object(s)"
    return Outcome(done, warnings, job.action, summary)


def sync_spheres(context, report, result=None):
    """The moving virtual objects' sphere shadows (fitted again only if their mesh or sphere
    count changed; their transforms are followed by drivers), settled where they stand
    (ray-traced with ``result``, the scene's last result) unless the scene's setting says
    not to."""
    from . import sphere_nodes
    settings = getattr(context.scene, "relight", None)
    try:
        summary = sphere_nodes.sync(context.scene, context.evaluated_depsgraph_get(),
                                    result=result,
                                    settle_shadows=bool(getattr(settings, "settle", True)))
        for w in summary.get("warnings", ()):
            report.warn(w)
        return summary
    except Exception as ex:
        report.warn(f"Moving objects' shadows could not be made: {user_message(ex)}")
        return {"objects": 0, "fitted": 0, "materials": 0}


# -- the whole run, synchronously -------------------------------------------------------------

def _run(context, kind, preset=None, correction=None, progress=None) -> Outcome:
    job = prepare(context, kind, preset, correction)
    try:
        result = job.compute(progress)
    except Exception as ex:
        raise PipelineError(f"Relight {kind} failed: {user_message(ex)}") from ex
    return finish(context, job, result)


def precompute(context, preset=None, correction=None, progress=None) -> Outcome:
    """Read, solve and write ``context.scene`` (the lamps already precomputed keep their power
    in the photo; Clear forgets them).  Raises PipelineError on bad input."""
    return _run(context, "precompute", preset, correction, progress)


def update(context, progress=None) -> Outcome:
    """Bring ``context.scene``'s relit materials up to date (see the module docstring)."""
    return _run(context, "update", progress=progress)


# -- restore, show, clear ---------------------------------------------------------------------

def restore(scene) -> int:
    """The user's materials back on this scene's relit objects (the relit ones are kept)."""
    n = materials.restore_originals(scene)
    eevee_shadow.show(scene, ids.scene_key(scene), False)   # they would light the user's
    if state.status(scene):
        state.update_status(scene, restored=True)
    return n


def show_relit(scene) -> int:
    """This scene's relit materials shown again where Restore put the originals back."""
    n = materials.reapply(scene)
    eevee_shadow.show(scene, ids.scene_key(scene), True)
    if state.status(scene):
        state.update_status(scene, restored=False)
    return n


def clear(scene) -> dict:
    """Restore, then delete what Relight made for this scene and its state."""
    from . import ar
    ar.clear(scene)                       # AR mode's compositor, passes and settings first
    key = ids.scene_key(scene)
    summary = write.clear_relight_data(scene)
    if key is not None:
        materials.forget_slots(scene, key)
    state.forget(scene)
    return summary
