"""What a scene remembers of its last precompute: the status the panel shows, the lamps of the
maps, and the solution that Update starts from.

* The status is the scene's ID property ``relight_status`` (a dict): saved with the .blend and
  following undo like the relit materials it describes.  Its ``lamp_records`` say, per lamp of
  the maps and in their order, which light it is (a stored identity that survives a rename),
  whether it was in the photo, its power and colour in the photo and the power its map was
  computed at: data of the maps, never read from the light's current settings.
* The last result (the radiosity solution, the maps per texel, the texel light) lives in memory
  per scene, tied to the status by a run id, and is kept in the .blend when the file is saved
  (two ID properties written just before the save and dropped from memory after it, so undo
  steps never copy them), so that an Update after reopening starts from it.  A kept solution
  that does not match the status (another run, another add-on version) is never used.
"""
from __future__ import annotations

import importlib
import json
import math
import uuid

import bpy
import numpy as np
from bpy.app.handlers import persistent

from . import ids

# scene.session_uid -> [(run id, result)], newest last: the last result of each scene in
# memory, and the one before it while its maps are small enough (an undo of the last Update
# brings back the status that names it, and the next Update starts from it).
_RESULTS = {}
KEEP_PREVIOUS_BYTES = 256 << 20
KEPT_KEYS = (ids.KEPT_HEADER, ids.KEPT_STREAM, ids.KEPT_DATA)


def _version():
    """Solutions are kept for the add-on version that wrote them (its classes may change)."""
    from ..core import persist
    from ..version import addon_version
    return f"{addon_version()}/{persist.FORMAT}"


# -- the status -------------------------------------------------------------------------------

def status(scene):
    """The last precompute's status dict, or None (also for a copy of a scene, which carries its
    original's status: it describes the original's lamps and result)."""
    st = scene.get(ids.STATUS)
    if st is None or ids.scene_key(scene) is None:
        return None
    return st.to_dict() if hasattr(st, "to_dict") else dict(st)


def update_status(scene, **fields):
    st = status(scene) or {}
    st.update(fields)
    scene[ids.STATUS] = st


def lamp_records(scene) -> list:
    """The lamps of the scene's maps, in their order (see the module docstring)."""
    st = status(scene) or {}
    return [dict(r) for r in st.get("lamp_records", ())]


def lamp_object(scene, label, records=None):
    """The light object of the lamp ``label`` of the scene's maps (by its stored identity, so a
    renamed light is found; None when it is gone or an emissive mesh)."""
    records = lamp_records(scene) if records is None else records
    record = next((r for r in records if r.get("label") == label), None)
    if record is None:
        obj = scene.objects.get(label)
        return obj if obj is not None and obj.type == "LIGHT" else None
    return find_light(scene, record)


def find_light(scene, record):
    """The light object holding ``record``'s identity (the one named as the record when a
    duplicate shares it), or None."""
    uid = record.get("uid")
    if not uid:
        return None
    found = [o for o in scene.objects if o.type == "LIGHT" and ids.uid(o) == uid]
    named = [o for o in found if o.name == record.get("object")]
    return (named or sorted(found, key=lambda o: o.name) or [None])[0]


def _finite(x, default):
    return float(x) if math.isfinite(x) else default


def store_status(scene, result, seconds, correction, run, warnings, parts, records,
                 objects=False, kept_room=False, action=""):
    """Write what the panel shows and what Update compares: counts, time, model misfit, lamps
    and their exitances, warnings, the fingerprints of the scene's parts and the lamp records."""
    stats = result.stats
    scale = [float(x) for x in result.exitance_scale]
    mean = sum(scale) / len(scale) if scale and sum(scale) > 0 else 1.0
    est = result.lamps
    old = status(scene) or {}
    scene[ids.STATUS] = {
        "preset": result.options.preset, "correction": correction, "run": run,
        "action": action,
        "elements": int(stats.get("elements", 0)), "links": int(stats.get("links", 0)),
        "seconds": float(seconds), "misfit": float(stats.get("photo_misfit", float("nan"))),
        "lamps": [r["label"] for r in records],
        "virtual": [r["label"] for r in records if r.get("virtual")],
        "lamp_records": records,
        "exitance_scale": scale, "relative_exitance": [s / mean for s in scale],
        # the photo's view of each lamp against its set power (geometric mean 1 over the lamps
        # on in the photo; -1 where the photo cannot tell), its uncertainty, whether it is used
        "photo_ratio": [_finite(x, -1.0) for x in est.photo_ratio],
        "photo_sigma": [_finite(x, -1.0) for x in est.uncertainty],
        "photo_used": [bool(x) for x in est.applied],
        "photo_weight": [float(x) for x in est.photo_weight],
        "rho_mean": _finite(est.rho_mean, -1.0),
        "rho_sigma": _finite(getattr(est, "rho_sigma", float("inf")), -1.0),
        "proxy_faces": int(stats.get("proxy_faces", 0)),
        "input_faces": int(stats.get("input_faces", 0)),
        "proxy_deviation": _finite(float(stats.get("proxy_deviation", 0.0)), 0.0),
        "warnings": [str(w) for w in warnings],
        "parts": json.dumps(parts),
        # whether the result has virtual objects, and whether the room without them is kept
        # with it (an Update that only changes objects starts from that)
        "objects": bool(objects), "room_kept": bool(kept_room),
        "restored": False,
        "kept_mb": float(old.get("kept_mb", 0.0)) if old.get("run") == run else 0.0,
    }


def stored_parts(st) -> dict:
    try:
        return json.loads(st.get("parts", "{}")) if st else {}
    except (TypeError, ValueError):
        return {}


# -- the last result: memory first, then the file ----------------------------------------------

def _map_bytes(result):
    return sum(int(getattr(a, "nbytes", 0)) for part in (result.maps, result.texture)
               for a in (part or {}).values())


def remember(scene, result) -> str:
    """Keep ``result`` as ``scene``'s last result; returns the run id stored in its status."""
    run = uuid.uuid4().hex
    kept = _RESULTS.get(scene.session_uid, [])[-1:]
    if kept and _map_bytes(kept[0][1]) > KEEP_PREVIOUS_BYTES:
        kept = []
    _RESULTS[scene.session_uid] = kept + [(run, result)]
    return run


def _in_memory(scene, run):
    for r, result in reversed(_RESULTS.get(scene.session_uid, ())):
        if r == run:
            return result
    return None


def last_result(scene, load=True):
    """The result of ``scene``'s last precompute that its status names: in memory, else kept in
    the file (``load``), else None."""
    st = status(scene)
    if not st:
        return None
    result = _in_memory(scene, st.get("run"))
    if result is None and load:
        result = _read_kept(scene, st.get("run"))
        if result is not None:
            _RESULTS.setdefault(scene.session_uid, []).append((st.get("run"), result))
    return result


def has_kept(scene) -> bool:
    """Whether the file holds a kept solution for the scene's last run (read or not yet)."""
    st = status(scene)
    if not st:
        return False
    if _in_memory(scene, st.get("run")) is not None:
        return True
    header = _kept_header(scene)
    return header is not None and header.get("run") == st.get("run")


def kept_problem(scene):
    """Why the file's kept solution is not used (None: there is none, or it is used)."""
    st = status(scene)
    header = _kept_header(scene)
    if not st or header is None or _in_memory(scene, st.get("run")) is not None:
        return None
    if header.get("version") != _version():
        return (f"the solution kept in the file was made by Relight "
                f"{header.get('version', '?').split('/')[0]}")
    if header.get("run") != st.get("run"):
        return "the solution kept in the file is of an earlier run"
    return None


def forget(scene):
    """Drop ``scene``'s status, last result and kept solution (Clear)."""
    _RESULTS.pop(scene.session_uid, None)
    for key in (ids.STATUS, *KEPT_KEYS):
        if key in scene:
            del scene[key]


def _kept_header(scene):
    raw = scene.get(ids.KEPT_HEADER)
    if not isinstance(raw, str):
        return None
    try:
        return json.loads(raw)
    except ValueError:
        return None


def _read_kept(scene, run):
    """The kept solution of run ``run`` in the scene's ID properties, or None."""
    from ..core import persist
    stream, blob = scene.get(ids.KEPT_STREAM), scene.get(ids.KEPT_DATA)
    header = _kept_header(scene)
    if header is None or blob is None or not isinstance(stream, bytes) \
            or header.get("run") != run or header.get("version") != _version():
        return None
    try:
        meta = {"format": header["format"], "table": header["table"], "stream": stream}
        with memoryview(blob) as view:           # released before the property may change
            return persist.unpack(meta, view)
    except Exception as ex:                 # a damaged or foreign solution: solve again
        print(f"Relight: the solution kept in the file is not used ({ex})")
        return None


def write_kept(scene, limit_bytes):
    """Store the scene's last result in its ID properties (before a save); returns the bytes
    written (0: none, because there is no result, it is larger than ``limit_bytes``, or the
    scene is not editable)."""
    from ..core import persist
    st = status(scene)
    if not st or not ids.editable(scene):
        return 0
    result = _in_memory(scene, st.get("run"))
    if result is None:
        header = _kept_header(scene)
        if header is not None and header.get("run") != st.get("run"):
            drop_kept(scene)                 # a stale solution: never saved again
        return 0
    try:
        meta, blob = persist.pack(result)
    except Exception as ex:
        print(f"Relight: the solution cannot be kept in the file ({ex})")
        drop_kept(scene)
        return 0
    if blob.nbytes > limit_bytes:
        drop_kept(scene)
        update_status(scene, kept_mb=-blob.nbytes / 2**20)
        return 0
    header = {"run": st.get("run"), "version": _version(), "format": meta["format"],
              "table": meta["table"]}
    drop_kept(scene)
    scene[ids.KEPT_HEADER] = json.dumps(header)
    scene[ids.KEPT_STREAM] = meta["stream"]
    scene[ids.KEPT_DATA] = blob.view(np.int32)
    update_status(scene, kept_mb=blob.nbytes / 2**20)
    return int(blob.nbytes)


def drop_kept(scene):
    for key in KEPT_KEYS:
        if key in scene:
            del scene[key]


# -- handlers ---------------------------------------------------------------------------------

# the largest solution written into a file (bytes; 0: none), set by the add-on's preferences
_limit = {"bytes": lambda: 1 << 30}


def _limit_bytes():
    return _limit["bytes"]()


def _warm_up():
    """Import what an Update reads a kept solution with (scipy, the core's solver and
    relighting, OpenCV for the seams, Embree: seconds on a cold start), so that the first Update
    after opening a relit file takes about what the next ones take."""
    from ..core import fingerprint, persist  # noqa: F401
    from ..core.relight import diagnose, object_change, shadowfree, virtual  # noqa: F401
    for name in ("cv2", "embreex.rtcore_scene", "embreex.mesh_construction"):
        try:
            importlib.import_module(name)
        except ImportError:                  # a fallback is used (mapping.py, raycast.py)
            pass


@persistent
def _on_load(*_args):
    _RESULTS.clear()
    if not bpy.app.background and any(ids.STATUS in s for s in bpy.data.scenes):
        import threading
        threading.Thread(target=_warm_up, name="relight-warm-up", daemon=True).start()


@persistent
def _on_save_pre(*_args):
    limit = _limit_bytes()
    for scene in bpy.data.scenes:
        if limit <= 0:
            if ids.editable(scene):
                drop_kept(scene)
            continue
        write_kept(scene, limit)


@persistent
def _on_save_post(*_args):
    # the file has them; memory keeps the result itself (the blob would double it)
    for scene in bpy.data.scenes:
        st = status(scene)
        if st and _in_memory(scene, st.get("run")) is not None and ids.editable(scene):
            drop_kept(scene)


_HANDLERS = (("load_post", _on_load), ("save_pre", _on_save_pre),
             ("save_post", _on_save_post))


def attach(limit_bytes=None):
    """Register the file handlers; ``limit_bytes()``: the largest solution kept in a file."""
    if limit_bytes is not None:
        _limit["bytes"] = limit_bytes
    for name, fn in _HANDLERS:
        handlers = getattr(bpy.app.handlers, name)
        if fn not in handlers:
            handlers.append(fn)


def detach():
    for name, fn in _HANDLERS:
        handlers = getattr(bpy.app.handlers, name)
        if fn in handlers:
            handlers.remove(fn)
    _RESULTS.clear()
