"""Leave a Python that imported bpy 4.x without running bpy's C++ static destructors.

bpy 4.5 (and 4.2) can hang forever after the interpreter has finalized: the static destructor of
the audio module's ``GlobalState`` destroys a condition variable that bpy's own
``delayed_close_thread_run`` thread still waits on, and glibc's ``pthread_cond_destroy`` waits
for that waiter for ever (gdb: main thread in ``~GlobalState`` -> ``pthread_cond_destroy``).  It
happens when the bpy module outlives the interpreter's teardown, so its own clean-up never runs;
bpy 5.x does not hang.  It is Blender's bug, not the add-on's, and it hits every process that
imports bpy 4.5: pytest, its xdist workers and the fresh Pythons tests start.

The Makefile loads this file in every Python of the LTS venv (a ``.pth`` line in its
site-packages).  It registers, first and so run last, an ``atexit`` handler that, when bpy 4.x
was imported, flushes stdout and stderr and leaves with ``os._exit`` and the exit status the
process would have had: 1 after an uncaught exception, ``sys.exit``'s argument, else 0.
"""

import atexit
import os
import sys

_status = {"code": 0}
_excepthook = sys.excepthook
_exit = sys.exit


def _record_exception(kind, value, traceback):
    _status["code"] = 1
    _excepthook(kind, value, traceback)


def _record_exit(code=None):
    if code is None:
        _status["code"] = 0
    elif isinstance(code, int):
        _status["code"] = code
    else:  # a message: printed to stderr by the interpreter, status 1
        _status["code"] = 1
    _exit(code)


def _leave():
    bpy = sys.modules.get("bpy")
    app = getattr(bpy, "app", None)
    if app is None or tuple(app.version) >= (5, 0, 0):
        return
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except Exception:  # noqa: BLE001 - a closed stream: nothing left to flush
            pass
    os._exit(_status["code"])


sys.excepthook = _record_exception
sys.exit = _record_exit
atexit.register(_leave)
