"""The bridge's ID-property keys and tags, each spelled once.

Everything Relight makes (images, materials, node groups, the EEVEE volume) carries
``relight_generated = 1`` and the key of the scene it was made for (``relight_scene``); a
scene keeps its key in ``relight_id``.  Lights and objects carry a stored identity
(``relight_uid``) that survives a rename, so that a lamp of the photo stays that lamp.
"""
from __future__ import annotations

import uuid

import bpy
import numpy as np

# -- on datablocks Relight made -----------------------------------------------------------------
GENERATED = "relight_generated"
SCENE_KEY = "relight_scene"          # the key of the scene it was made for
# -- on a scene ---------------------------------------------------------------------------------
SCENE_ID = "relight_id"              # its key
SCENE_OWNER = "relight_id_owner"     # the name it had when the key was made
STATUS = "relight_status"            # the last precompute's status (state.py)
AR_STATE = "relight_ar"              # AR mode's set-up on a scene, and on its images (ar.py)
# the kept solution (state.py): a leading underscore keeps them out of the Custom Properties
# panel, which would list a multi-megabyte array
KEPT_HEADER = "_relight_kept"           # JSON: run id, version, the arrays' table
KEPT_STREAM = "_relight_kept_stream"    # bytes: the object graph
KEPT_DATA = "_relight_kept_data"        # int32 array: every array of the graph
# -- on a relit material ------------------------------------------------------------------------
ORIGINAL = "relight_original"        # the user's material (an ID reference: a user of it)
OBJECT_LINKS = "relight_object_slots"  # override objects whose slot we linked at object level
MAT_SUFFIX = ".relight"
# -- on an object whose slots show relit materials -----------------------------------------------
SLOT_ORIGINALS = "relight_slot_originals"   # {slot index: the user's material}
# -- on the user's original material ----------------------------------------------------------
FAKE_USER_WAS = "relight_fake_user_was"     # its own fake-user flag, while Relight keeps it
# -- on lights and objects ------------------------------------------------------------------------
UID = "relight_uid"
POWER0 = "relight_power0"            # on light data: the power its map is computed at
ROLE = "relight_role"                # on objects: relit / occluder / ignored / virtual / receiver
SHADOWS = "relight_shadows"          # on virtual objects: EXACT or SPHERES
SPHERES = "relight_spheres"          # on virtual objects: how many spheres
# -- on map images ------------------------------------------------------------------------------
MAP_SOURCE = "relight_map_source"    # the photo's name (names may be renamed)
MAP_LAMP = "relight_map_lamp"        # its lamp's label


def array(value, dtype=float) -> np.ndarray:
    """A copy of an ID property's array (or of any sequence).  ``np.asarray`` of an ID
    property array shares its memory (the buffer protocol), which Blender frees when the
    property is set again or its ID removed: an AR Update that re-made the first object's
    shadow group read that object's spheres from the old group's freed memory, and the next
    render's shadow changed from run to run (zeros on Blender 5.2)."""
    return np.array(value, dtype=dtype, copy=True)


def is_generated(idb) -> bool:
    return bool(idb.get(GENERATED, 0))


def tag(idb, key):
    idb[GENERATED] = 1
    idb[SCENE_KEY] = key


def ours(idb, key) -> bool:
    return key is not None and is_generated(idb) and idb.get(SCENE_KEY) == key


def scene_key(scene, create=False):
    """The key that ties generated data to ``scene`` (made on the first write; ``create`` is
    only allowed where ID properties may be written, never in a poll or a draw).  A copied
    scene (Full Copy) carries its original's key: the key stays with the scene that still has
    the name it was made under, and the copy gets its own on its first write."""
    key = scene.get(SCENE_ID)
    if key is not None and scene.get(SCENE_OWNER) != scene.name:
        if any(s != scene and s.get(SCENE_ID) == key and s.get(SCENE_OWNER) == s.name
               for s in bpy.data.scenes):
            key = None                               # a copy: not its key
        elif create:
            scene[SCENE_OWNER] = scene.name          # renamed
    if key is None and create:
        key = scene[SCENE_ID] = uuid.uuid4().hex
        scene[SCENE_OWNER] = scene.name
    return key


def uid(idb):
    """The stored identity of a light or object (None before Relight gave it one)."""
    value = idb.get(UID) if idb is not None else None
    return value if isinstance(value, str) and value else None


def give_uid(idb, fresh=False) -> str:
    """``idb``'s identity, made now if it has none (or ``fresh``: a duplicate's copy of its
    original's identity is replaced)."""
    value = None if fresh else uid(idb)
    if value is None:
        value = idb[UID] = uuid.uuid4().hex
    return value


def editable(idb) -> bool:
    """Whether Relight may write to ``idb`` (local data, not linked from a library)."""
    if idb is None:
        return True
    return bool(getattr(idb, "is_editable", idb.library is None)) and idb.library is None
