# SPDX-License-Identifier: GPL-3.0-or-later
"""The viewport's draw handlers' shared plumbing (ar_draw.py, relit_draw.py): install a
SpaceView3D POST_VIEW callback outside background mode, remove it, and run a frame so that a
failure is printed once and turns that drawing off (a traceback at every redraw would flood
the console) until :func:`retry`: the user toggles the drawing, new data is written (Update,
Set Up AR) or another file is opened.  Each handler keeps its state in a ``cache`` dict with at
least "handle" and "failed".

Also what every handler's batches need: numpy arrays handed to the gpu module without a copy
through Python lists (:func:`float_buffer`, :func:`int_buffer`, :func:`vertex_array`: a
2048^2 RGBA texture's ``tolist`` alone takes 0.7 s here, and filling a Buffer from the list as
long again), and what an object's triangles depend on beyond its transform
(:func:`geometry_key`: moving vertices in edit mode, a modifier's value or an armature changes
no count, so the geometry's own updates are followed).
"""
from __future__ import annotations

from contextlib import contextmanager

import numpy as np
from bpy.app.handlers import persistent

_GEOMETRY = {}          # object session_uid -> generation of its geometry (bumped on a change)
_CACHES = []            # the handlers' caches installed once (their "handle": still installed)

# the panel's line of a failure (a shader's compile log runs to many lines)
FAILURE_CHARS = 100


def guarded(cache, draw_frame, what):
    """A callback running ``draw_frame()``; its first failure is printed in full ("Relight:
    <what> stopped (...)"), kept in ``cache["failed"]`` as one line, and stops the drawing."""
    def callback():
        if cache["failed"] is not None:
            return
        try:
            draw_frame()
        except Exception as ex:  # noqa: BLE001 - any gpu or data error: stop drawing, say why
            text = f"{type(ex).__name__}: {ex}"
            print(f"Relight: {what} stopped ({text})")
            line = text.strip().splitlines()[0] if text.strip() else type(ex).__name__
            cache["failed"] = line if len(line) <= FAILURE_CHARS else \
                line[:FAILURE_CHARS - 3] + "..."
    return callback


def retry(cache, **reset):
    """Draw again after a failure, from new gpu objects (``reset``: the cache's entries to
    drop, e.g. batches={})."""
    cache.update(failed=None, **reset)


def install(cache, callback):
    """Install ``callback`` as the handler; False (and nothing done) in background mode."""
    import bpy
    if bpy.app.background:
        return False
    if cache["handle"] is None:
        cache["handle"] = bpy.types.SpaceView3D.draw_handler_add(callback, (), "WINDOW",
                                                                  "POST_VIEW")
    if not any(c is cache for c in _CACHES):
        _CACHES.append(cache)
    watch_geometry()
    return True


def remove(cache, **reset):
    """Remove the handler (if any); ``reset`` the cache's other entries (its gpu objects)."""
    import bpy
    handle = cache["handle"]
    cache.update(handle=None, failed=None, **reset)
    if handle is not None:
        bpy.types.SpaceView3D.draw_handler_remove(handle, "WINDOW")
    if not any(c["handle"] is not None for c in _CACHES):
        unwatch_geometry()


# -- numpy to the gpu module ---------------------------------------------------------------------
# Buffer and GPUVertBuf.attr_fill take the buffer protocol and copy its raw bytes in the format
# they are told (FLOAT, F32 attributes) without checking the array's dtype: float64 would be
# read as garbage, so every array is made float32 (int32) and C-contiguous here.

def float_buffer(array):
    """A gpu.types.Buffer of ``array`` as float32, sharing its memory (the Buffer keeps the
    array alive)."""
    import gpu
    a = np.ascontiguousarray(array, dtype=np.float32).reshape(-1)
    return gpu.types.Buffer("FLOAT", a.size, a)


def int_buffer(array):
    """The same as int32."""
    import gpu
    a = np.ascontiguousarray(array, dtype=np.int32).reshape(-1)
    return gpu.types.Buffer("INT", a.size, a)


def vertex_array(array):
    """``array`` as the C-contiguous float32 (n, k) a vertex attribute is filled from."""
    return np.ascontiguousarray(array, dtype=np.float32)


# -- geometry generations ------------------------------------------------------------------------

def geometry_key(obj) -> tuple:
    """What ``obj``'s triangles depend on beyond its transform: its and its mesh's session ids
    (another file, another mesh) and the generation of its geometry, which changes whenever a
    depsgraph update or a frame change reports its geometry updated (while a handler is
    installed, or within :func:`watching`)."""
    data = getattr(obj, "data", None)
    return (obj.session_uid, getattr(data, "session_uid", None),
            _GEOMETRY.get(obj.session_uid, 0))


@persistent
def _on_update(scene, depsgraph):
    import bpy
    for update in depsgraph.updates:
        if update.is_updated_geometry and isinstance(update.id, bpy.types.Object):
            uid = update.id.original.session_uid
            _GEOMETRY[uid] = _GEOMETRY.get(uid, 0) + 1


def _handler_lists():
    """The handlers the geometry is followed from: edits (depsgraph updates) and animation
    (a frame change runs no depsgraph_update_post: an armature's or a shape key's deformation
    is seen there only)."""
    import bpy
    return bpy.app.handlers.depsgraph_update_post, bpy.app.handlers.frame_change_post


def is_watching() -> bool:
    return any(_on_update in h for h in _handler_lists())


def watch_geometry():
    """Follow the objects' geometry updates (idempotent)."""
    for handlers in _handler_lists():
        if _on_update not in handlers:
            handlers.append(_on_update)


def unwatch_geometry():
    for handlers in _handler_lists():
        while _on_update in handlers:
            handlers.remove(_on_update)


@contextmanager
def watching():
    """Follow the geometry within the block, as it was followed before afterwards (tests)."""
    was = is_watching()
    watch_geometry()
    try:
        yield
    finally:
        if not was:
            unwatch_geometry()
