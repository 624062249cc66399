"""The user's materials and their relit copies: which is which, showing one or the other, and
keeping the user's safe.

* A relit material holds the user's in ``relight_original`` (an ID reference), and each object
  whose slots show relit materials keeps, per scene key and slot, the user's material that slot
  had (``relight_slot_originals``): a slot whose relit material was deleted by hand still gets
  its original back, and the original never drops to zero users while it is relit.
* Restore puts the originals back in the slots holding this scene's relit materials only (an
  object shared with another scene keeps that scene's); the relit materials get a fake user so
  that saving keeps them; Reapply (Update, or Show Relit) puts them back.
"""
from __future__ import annotations

from . import ids


def original_material(mat):
    """The user's material behind a relit one (``mat`` itself when it is not relit)."""
    for _ in range(8):                       # a relit material is never relit again; be safe
        if mat is None or not ids.is_generated(mat):
            return mat
        nxt = mat.get(ids.ORIGINAL)
        if nxt is None:                      # relit data written before the reference existed
            import bpy
            nxt = bpy.data.materials.get(mat.name[: -len(ids.MAT_SUFFIX)]) \
                if mat.name.endswith(ids.MAT_SUFFIX) else None
        mat = nxt
    return None


def scene_objects(scene):
    """The objects of ``scene``, and those of the collections its objects instance."""
    seen, todo, out = set(), list(scene.objects), []
    while todo:
        obj = todo.pop()
        if obj.name_full in seen:
            continue
        seen.add(obj.name_full)
        out.append(obj)
        coll = obj.instance_collection if obj.instance_type == "COLLECTION" else None
        if coll is not None:
            todo.extend(coll.all_objects)
    return out


def relit_slots(scene, key=None):
    """(object, slot index, relit material) for every slot of ``scene``'s objects holding a
    relit material (of the scene with ``key`` only, when given)."""
    for obj in scene_objects(scene):
        for i, slot in enumerate(obj.material_slots):
            mat = slot.material
            if mat is not None and ids.is_generated(mat) and (key is None or ids.ours(mat, key)):
                yield obj, i, mat


def relit_slot_count(scene) -> int:
    return sum(1 for _ in relit_slots(scene, ids.scene_key(scene)))


def slot_access(obj):
    """How ``obj``'s material slots can be reassigned: "direct" (local data), "override" (a
    library-override object whose linked mesh holds the slots: an object-level slot is used),
    or None (linked, read-only)."""
    if not ids.editable(obj):
        return None
    if all(ids.editable(obj.data if slot.link == "DATA" else obj) for slot in obj.material_slots):
        return "direct"
    return "override" if obj.override_library is not None else None


def slots_editable(obj) -> bool:
    return slot_access(obj) is not None


# -- the user's originals kept safe ---------------------------------------------------------------

def _slot_record(obj, key, create=False):
    """{slot index (str): original material} of ``obj`` for the scene with ``key``."""
    if not ids.editable(obj):
        return None
    if ids.SLOT_ORIGINALS not in obj:
        if not create:
            return None
        obj[ids.SLOT_ORIGINALS] = {}
    group = obj[ids.SLOT_ORIGINALS]
    if key not in group:
        if not create:
            return None
        group[key] = {}
    return group[key]


def keep_original(orig):
    """While relit, the user's material has a fake user (its own flag is remembered)."""
    if orig is None or not ids.editable(orig) or ids.FAKE_USER_WAS in orig:
        return
    orig[ids.FAKE_USER_WAS] = bool(orig.use_fake_user)
    orig.use_fake_user = True


def release_original(orig):
    """The user's material gets its own fake-user flag back."""
    if orig is None or not ids.editable(orig) or ids.FAKE_USER_WAS not in orig:
        return
    orig.use_fake_user = bool(orig[ids.FAKE_USER_WAS])
    del orig[ids.FAKE_USER_WAS]


def assign(obj, i, relit, key):
    """Show ``relit`` in slot ``i`` of ``obj`` (an override object's slot of a linked mesh at
    object level), remembering the original there; returns that original."""
    slot = obj.material_slots[i]
    orig = original_material(slot.material)
    if orig is None:
        orig = original_material(relit)
    record = _slot_record(obj, key, create=True)
    if record is not None and orig is not None:
        record[str(i)] = orig
    keep_original(orig)
    if slot_access(obj) == "override" and slot.link == "DATA" and not ids.editable(obj.data):
        slot.link = "OBJECT"
        relit[ids.OBJECT_LINKS] = list(relit.get(ids.OBJECT_LINKS, ())) + [obj.name]
    slot.material = relit
    relit.use_fake_user = False
    return orig


def restore_originals(scene) -> int:
    """Put the user's materials back in every slot of ``scene``'s objects that shows one of this
    scene's relit materials, or that lost it (deleted by hand).  Returns the slots restored.
    Relit materials and images are kept (with a fake user: a save keeps them) until Clear."""
    key = ids.scene_key(scene)
    if key is None:
        return 0
    count = 0
    for obj in scene_objects(scene):
        record = _slot_record(obj, key)
        originals = {int(i): m for i, m in record.items()} if record is not None else {}
        for i, slot in enumerate(obj.material_slots):
            mat = slot.material
            ours = mat is not None and ids.ours(mat, key)
            if not ours and not (mat is None and i in originals):
                continue
            orig = originals.get(i) or original_material(mat)
            if orig is None:
                continue
            slot.material = orig
            if ours:
                mat.use_fake_user = True
                if obj.name in mat.get(ids.OBJECT_LINKS, ()) and slot.link == "OBJECT":
                    slot.link = "DATA"
            count += 1
    return count


def reapply(scene) -> int:
    """Show this scene's relit materials again where Restore put the originals back (the slots
    remembered for it, holding the original now).  Returns the slots assigned."""
    import bpy
    key = ids.scene_key(scene)
    if key is None:
        return 0
    relit_of = {}
    for mat in bpy.data.materials:
        if ids.ours(mat, key):
            orig = original_material(mat)
            if orig is not None:
                relit_of[orig.name_full] = mat
    count = 0
    for obj in scene_objects(scene):
        record = _slot_record(obj, key)
        if record is None:
            continue
        for i, orig in list(record.items()):
            i = int(i)
            if i >= len(obj.material_slots) or orig is None:
                continue
            slot = obj.material_slots[i]
            relit = relit_of.get(orig.name_full)
            if relit is None or (slot.material is not None and slot.material != orig):
                continue
            assign(obj, i, relit, key)
            count += 1
    return count


def forget_slots(scene, key):
    """Drop the slot records of the scene with ``key`` and give the originals their own fake-user
    flags back (Clear, after Restore)."""
    import bpy
    originals = set()
    for obj in scene_objects(scene):
        record = _slot_record(obj, key)
        if record is None:
            continue
        originals.update(m.name_full for m in record.values() if m is not None)
        del obj[ids.SLOT_ORIGINALS][key]
        if not len(obj[ids.SLOT_ORIGINALS]):
            del obj[ids.SLOT_ORIGINALS]
    still = set()                   # originals another scene still relights
    for obj in bpy.data.objects:
        group = obj.get(ids.SLOT_ORIGINALS)
        if group is not None:
            for record in group.values():
                still.update(m.name_full for m in record.values() if m is not None)
    for mat in bpy.data.materials:
        if mat.name_full in originals and mat.name_full not in still:
            release_original(mat)
