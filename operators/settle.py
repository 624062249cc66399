# SPDX-License-Identifier: GPL-3.0-or-later
"""Settle moving objects' shadows when a drag stops (issue 11), in the UI.

While an object is dragged its shadow comes from its spheres (drivers: no Python).  A depsgraph
handler notes when a moving object's transform differs from the one its settled shadow was
traced at; a timer then waits until no such change came for ``STILL`` seconds and no transform
is running (a mouse that pauses mid-drag must not freeze it for a trace) and runs what
Update's fast path runs (``sphere_nodes.sync`` with the scene's last result), which traces the
shadow where the object now stands.  Not in background mode (scripts and farms call Update).
Nothing happens without a last result (in memory, or kept in the file: it is read when the
first settle runs).
"""

import time

import bpy
from bpy.app.handlers import persistent

STILL = 0.5             # s without a transform change before settling
POLL = 0.2              # s between the timer's checks

pending = {}            # scene name -> time of the last transform change seen



def _modules():
    from ..relight_addon.blender import ids, sphere_nodes, state
    from . import precompute
    return sphere_nodes, ids, precompute, state


def unsettled(scene) -> bool:
    """Whether a moving object of ``scene`` stands elsewhere than its settled shadow."""
    sphere_nodes, ids, _, state = _modules()
    if not getattr(getattr(scene, "relight", None), "settle", False):
        return False
    if not state.has_kept(scene):          # (cheap: a kept solution is read when it is used)
        return False
    key = ids.scene_key(scene)
    fitted = sphere_nodes.sphere_groups(key) if key is not None else {}
    objs = [o for o in sphere_nodes.moving_objects(scene) if o.name in fitted]   # as sync's
    if key is None or not objs:
        return False
    group = sphere_nodes.settled_group(key)
    return group is None or group.get("relight_settled_run") != sphere_nodes.settled_run(objs)


def _job_running(kind) -> bool:
    try:
        return bool(bpy.app.is_job_running(kind))
    except (TypeError, ValueError):      # a job type this Blender does not know
        return False


def dragging() -> bool:
    """A transform (grab, rotate, scale) is running in some window: the mouse may only pause."""
    wm = getattr(bpy.context, "window_manager", None)
    for window in (wm.windows if wm is not None else ()):
        for op in getattr(window, "modal_operators", ()):   # Blender 4.2+
            if op.bl_idname.startswith(("TRANSFORM_OT_", "VIEW3D_OT_")):
                return True
    return False


def _depsgraph(scene):
    """The evaluated depsgraph of a window showing ``scene`` (None when none does)."""
    wm = getattr(bpy.context, "window_manager", None)
    for window in (wm.windows if wm is not None else ()):
        if window.scene == scene:
            return scene.view_layers[window.view_layer.name].depsgraph
    if bpy.context.scene == scene:
        return bpy.context.evaluated_depsgraph_get()
    return None


def settle_now(scene) -> bool:
    """Trace ``scene``'s moving objects' shadows where they stand; False when nothing ran."""
    sphere_nodes, _, precompute, state = _modules()
    busy = _job_running("RENDER") or _job_running("OBJECT_BAKE")
    if busy or precompute.solve_running() or not unsettled(scene):
        return False
    depsgraph = _depsgraph(scene)
    if depsgraph is None:
        return False
    sphere_nodes.sync(scene, depsgraph, result=state.last_result(scene), settle_shadows=True)
    return True


def tick(now=None):
    """Timer: settle the scenes whose objects stood still for STILL seconds."""
    now = time.monotonic() if now is None else now
    held = dragging()                    # a trace would freeze the drag: wait for its end
    for name, t in list(pending.items()):
        if now - t < STILL or held:
            continue
        del pending[name]
        scene = bpy.data.scenes.get(name)
        if scene is not None:
            try:
                settle_now(scene)
            except Exception as ex:          # a timer must not raise; the spheres stay
                print(f"Relight: the moving shadows could not be settled: {ex}")
    return POLL if pending else None


@persistent
def _watch(scene, depsgraph=None):
    if bpy.app.background or not depsgraph_moves(scene, depsgraph):
        return
    pending[scene.name] = time.monotonic()
    if not bpy.app.timers.is_registered(tick):
        bpy.app.timers.register(tick, first_interval=POLL)


def depsgraph_moves(scene, depsgraph) -> bool:
    """A moving object's transform changed in this update and its shadow is not settled."""
    if depsgraph is not None:
        sphere_nodes = _modules()[0]
        moving = {o.name for o in sphere_nodes.moving_objects(scene)}
        moved = {u.id.original.name for u in depsgraph.updates
                 if u.is_updated_transform and isinstance(u.id, bpy.types.Object)}
        if not moved & moving:
            return False
    try:
        return unsettled(scene)
    except Exception:
        return False


def attach():
    if _watch not in bpy.app.handlers.depsgraph_update_post:
        bpy.app.handlers.depsgraph_update_post.append(_watch)


def detach():
    if _watch in bpy.app.handlers.depsgraph_update_post:
        bpy.app.handlers.depsgraph_update_post.remove(_watch)
    if bpy.app.timers.is_registered(tick):
        bpy.app.timers.unregister(tick)
    pending.clear()


classes = ()
