"""The user's data in a .blend, as plain JSON-able values: what Relight must never lose or change.

Shared by the tests and by the fresh Blender processes they start (``python -c`` with this folder
on ``sys.path``): materials (their node trees: nodes, links, unlinked input values), the images
(a hash of their pixels, packed or not), every material slot, lights' energies.  Relight's own
datablocks (``relight_generated``) are left out.
"""
import hashlib

import numpy as np


def _pixels_hash(img):
    n = len(img.pixels)
    if n == 0:
        return None
    buf = np.empty(n, np.float32)
    img.pixels.foreach_get(buf)
    return hashlib.sha256(buf.tobytes()).hexdigest()


def _value(sock):
    v = getattr(sock, "default_value", None)
    if v is None:
        return None
    try:
        return [round(float(x), 6) for x in v]
    except TypeError:
        return round(float(v), 6) if isinstance(v, (int, float)) else str(v)


def user_state(bpy):
    """{"materials", "images", "slots", "lights"} of the user's (not generated) data."""
    mats = {}
    for m in bpy.data.materials:
        if m.get("relight_generated"):
            continue
        nt = m.node_tree
        nodes = sorted((n.name, n.bl_idname, getattr(getattr(n, "image", None), "name", None),
                        getattr(n, "uv_map", None),
                        [(i.identifier, _value(i)) for i in n.inputs if not i.is_linked])
                       for n in (nt.nodes if nt else []))
        links = sorted((l.from_node.name, l.from_socket.identifier, l.to_node.name,
                        l.to_socket.identifier) for l in (nt.links if nt else []))
        mats[m.name] = [nodes, links]
    images = {im.name: _pixels_hash(im) for im in bpy.data.images
              if not im.get("relight_generated")}
    slots = {o.name: [[s.link, s.material.name if s.material else ""] for s in o.material_slots]
             for o in bpy.data.objects}
    lights = {l.name: round(float(l.energy), 6) for l in bpy.data.lights}
    return {"materials": mats, "images": images, "slots": slots, "lights": lights}
