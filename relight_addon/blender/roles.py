"""Object roles: how Relight treats an object (``relight_role``), and the moving virtual objects.

The role is the add-on's Object enum property, or a plain string custom property of the same
name set by a script (read first, so that scripts work without the add-on registered).  Before
Blender 5.0 an enum property keeps its value as an index in that same ID property, so only a
string is read raw.
"""
from __future__ import annotations

from . import ids

ROLES = ("relit", "occluder", "ignored", "virtual", "receiver")
ROLE_ITEMS = (
    ("relit", "Relit", "A photographed surface: its textures are relit"),
    ("occluder", "Occluder", "Only casts shadows and blocks light (not relit, reflects "
                             "nothing)"),
    ("ignored", "Ignored", "Not read at all"),
    ("virtual", "Virtual", "A virtual object, not in the photo: it casts shadows on and "
                           "reflects light onto the relit surfaces"),
    ("receiver", "Receiver", "AR mode: a stand-in for a photographed surface (ground, table, "
                             "wall) that shows the photo and receives the virtual objects' "
                             "shadows; relighting reads it as an occluder"),
)
SHADOW_ITEMS = (
    ("EXACT", "Exact", "Ray-traced into the maps on Update, with the light the object blocks "
                       "and reflects; Update after moving it"),
    ("SPHERES", "Moving", "Soft shadows of a set of spheres, evaluated by the relit materials: "
                          "they follow the object's animation and drags at once, and render "
                          "on a farm without the extension (direct light only)"),
)
DEFAULT_SPHERES = 32
# the most that renders in reasonable time (issue 44.10, 2 cores: a 16 x 16 one-sample Cycles
# frame took 5.6 s at 128 and did not finish in 180 s at 512; EEVEE's compiler fails past
# about 128 per lamp); AR mode's shader holds as many (core/ar/shader_data.MAX_SPHERES)
MAX_SPHERES = 128


def raw_property(obj, name, default):
    """A plain custom property set from a script, else the add-on's property (see the module
    docstring: an enum's raw value is trusted only as a string)."""
    raw = obj.get(name) if hasattr(obj, "get") else None
    if isinstance(raw, str) or (isinstance(default, int) and isinstance(raw, int)
                                and not isinstance(raw, bool)):
        return raw
    return getattr(obj, name, default)


def object_role(obj, roles=None):
    """The role of ``obj`` (the ``roles`` argument, name -> role, first), or None when the value
    is unknown."""
    if roles and obj.name in roles:
        role = roles[obj.name]
    else:
        role = raw_property(obj, ids.ROLE, "relit")
    return role if role in ROLES else None


def has_role(obj, roles=None) -> bool:
    """Whether a role other than the default is set on ``obj``."""
    return bool(roles and obj.name in roles) or object_role(obj) not in (None, "relit")


def moving(obj) -> bool:
    """A virtual object whose shadows follow it at render time (spheres)."""
    return (obj.type == "MESH" and object_role(obj) == "virtual"
            and raw_property(obj, ids.SHADOWS, "EXACT") == "SPHERES")


def sphere_count(obj) -> int:
    return max(1, min(MAX_SPHERES, int(raw_property(obj, ids.SPHERES, DEFAULT_SPHERES))))


def moving_objects(scene):
    return [o for o in scene.objects if moving(o) and not o.hide_render]
