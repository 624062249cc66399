# SPDX-License-Identifier: GPL-3.0-or-later
"""The viewport's draw handlers' shared plumbing (ar_draw.py, relit_draw.py): install a
SpaceView3D POST_VIEW callback outside background mode, remove it, and run a frame so that a
failure is printed once and turns that drawing off (a traceback at every redraw would flood
the console) until the handler is installed again.  Each handler keeps its state in a
``cache`` dict with at least "handle" and "failed"."""
from __future__ import annotations


def guarded(cache, draw_frame, what):
    """A callback running ``draw_frame()``; its first failure is printed ("Relight: <what>
    stopped (...)") and stops the drawing."""
    def callback():
        if cache["failed"] is not None:
            return
        try:
            draw_frame()
        except Exception as ex:  # noqa: BLE001 - any gpu or data error: stop drawing, say why
            cache["failed"] = f"{type(ex).__name__}: {ex}"
            print(f"Relight: {what} stopped ({cache['failed']})")
    return callback


def install(cache, callback):
    """Install ``callback`` as the handler; False (and nothing done) in background mode."""
    import bpy
    if bpy.app.background:
        return False
    if cache["handle"] is None:
        cache["handle"] = bpy.types.SpaceView3D.draw_handler_add(callback, (), "WINDOW",
                                                                  "POST_VIEW")
    return True


def remove(cache, **reset):
    """Remove the handler (if any); ``reset`` the cache's other entries (its gpu objects)."""
    import bpy
    handle = cache["handle"]
    cache.update(handle=None, failed=None, **reset)
    if handle is not None:
        bpy.types.SpaceView3D.draw_handler_remove(handle, "WINDOW")
