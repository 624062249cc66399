"""Drivers that the relit materials and node groups evaluate at render time.

Kept to simple expressions, they run with Python auto-run off and without the extension
installed (render farms), which is why every live quantity goes through one.
"""
from __future__ import annotations


def add_driver(socket, expression, variables, prop="default_value", index=-1):
    """A SCRIPTED driver on ``socket``'s default value (or on its property ``prop``, element
    ``index``): ``expression`` over ``variables``, each (name, kind, target, what): kind
    "TRANSFORMS" reads the world-space transform channel ``what`` of the object ``target``
    (rotations as a quaternion), any other kind is the ID type of ``target`` whose property at
    the data path ``what`` is read."""
    fc = socket.driver_add(prop) if index < 0 else socket.driver_add(prop, index)
    for mod in list(fc.modifiers):
        fc.modifiers.remove(mod)
    drv = fc.driver
    drv.type = "SCRIPTED"
    for name, kind, target, what in variables:
        var = drv.variables.new()
        var.name = name
        t = var.targets[0]
        if kind == "TRANSFORMS":
            var.type = "TRANSFORMS"
            t.id = target
            t.transform_type = what
            t.transform_space = "WORLD_SPACE"
            if what.startswith("ROT"):
                t.rotation_mode = "QUATERNION"
        else:
            var.type = "SINGLE_PROP"
            t.id_type = kind
            t.id = target
            t.data_path = what
    drv.expression = expression
    return fc


def copy_driver(fc, owner, prop, index=-1):
    """The driver of F-curve ``fc`` (as add_driver makes them) on ``owner``'s ``prop``."""
    variables = []
    for var in fc.driver.variables:
        t = var.targets[0]
        if var.type == "TRANSFORMS":
            variables.append((var.name, "TRANSFORMS", t.id, t.transform_type))
        else:
            variables.append((var.name, t.id_type, t.id, t.data_path))
    return add_driver(owner, fc.driver.expression, variables, prop, index)


def ratio_expression(var, value0) -> str:
    """``var / value0``: a property over its value when the map was computed."""
    return f"{var} / {float(value0)!r}"


def ratio_driver(socket, var, kind, idb, data_path, value0):
    """``socket`` follows a property (the variable ``var``) over its value ``value0`` at
    precompute: ``var / value0``."""
    return add_driver(socket, ratio_expression(var, value0), [(var, kind, idb, data_path)])


def drivers_reading(tree, idb, data_path):
    """(F-curve, variable name) of the drivers of node tree ``tree`` that read ``data_path`` of
    ``idb``."""
    ad = tree.animation_data if tree is not None else None
    for fc in (ad.drivers if ad else []):
        for var in fc.driver.variables:
            t = var.targets[0]
            if t.id == idb and t.data_path == data_path:
                yield fc, var.name


def frame_vars(obj):
    """Location (l, m, n), rotation (w, x, y, z) and scale (a, b, c) of ``obj``, world space."""
    return [(n, "TRANSFORMS", obj, w) for n, w in zip(
        "lmnwxyzabc", ("LOC_X", "LOC_Y", "LOC_Z", "ROT_W", "ROT_X", "ROT_Y", "ROT_Z",
                       "SCALE_X", "SCALE_Y", "SCALE_Z"))]


def world_point_expressions(point):
    """Simple expressions (over frame_vars) of the world position of ``point``, given in the
    object's frame: location + rotation (scale x point), the rotation matrix of the unit
    quaternion (w, x, y, z)."""
    px, py, pz = (repr(float(v)) for v in point)
    sx, sy, sz = f"a * {px}", f"b * {py}", f"c * {pz}"
    return (f"l + (1 - 2 * (y * y + z * z)) * {sx} + 2 * (x * y - w * z) * {sy}"
            f" + 2 * (x * z + w * y) * {sz}",
            f"m + 2 * (x * y + w * z) * {sx} + (1 - 2 * (x * x + z * z)) * {sy}"
            f" + 2 * (y * z - w * x) * {sz}",
            f"n + 2 * (x * z - w * y) * {sx} + 2 * (y * z + w * x) * {sy}"
            f" + (1 - 2 * (x * x + y * y)) * {sz}")
