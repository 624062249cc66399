"""Moving virtual objects' shadows in EEVEE from EEVEE's own shadow maps.

EEVEE compiles every node of a material, and the sphere groups (sphere_nodes.py) give each
relit material some 25 nodes per sphere and lamp: 64 spheres took two minutes to compile on two
cores.  Here EEVEE draws the moving objects' real meshes into its shadow maps instead, and the
relit materials read the result at a cost that does not depend on the mesh:

* Per shadowed lamp two *probe lights* stand where the lamp's group says it is (position and
  radius driven as the group's are; a sun is a sun of the same direction and angle): the
  *shadowed* probe casts the shadows of the moving objects alone (shadow linking: its blocker
  collection holds them), the *free* probe none (``use_shadow`` off).  Both light the relit
  surfaces alone (light linking: the receiver collection).
* A light can be limited to the diffuse or to the specular closures: slot 0's probes light only
  Diffuse BSDFs, slot 1's only Glossy ones, so two lamps fit (a third and later ones keep the
  spheres).  The shadowed probe is red, the free one green.
* A relit material shades a white Diffuse (slot 0) or Glossy (slot 1) BSDF with Shader to RGB:
  R over G is the part of the probe, so of the lamp, that the objects leave visible at the
  point, V_k, with the penumbra of EEVEE's soft shadows (the probe's radius is the lamp's).  The
  rest of the material is as the spheres wire it: ``1 - a_k (1 - V_k)`` on the lamp's term.
* The probes are POWER watts, so that the scene's own lamps, world and EEVEE's indirect light,
  which reach the same closures, shift V by less than about 1e-5 (a 1 kW lamp at the probe's
  place: 1e-6); where G is below FLOOR the probe does not reach the point (the surface faces
  away) and V is 1.

Cycles: the probes light the receivers' BSDFs, and the relit materials' Cycles output has none
(sphere_nodes gives these materials an output of their own for Cycles, with rays or spheres);
so only objects whose every material is relit are receivers, and Restore Originals switches
the probes off (they would light the user's own materials).  Nothing runs in Python at render
time: drivers with simple expressions, as the spheres'.
"""
from __future__ import annotations

import re

import bpy
import numpy as np

from . import ids
from .drivers import add_driver, copy_driver

PROBE_KEY = "relight_probe"           # on a probe light object: {lamp, slot, shadowed (1/0)}
SOURCE_KEY = "relight_probe_source"   # on a probe: what it was made from (made again if other)
COLLECTION_KEY = "relight_probe_set"  # on the collections made here: "probes", "receivers", ...
SLOTS = 2                             # closures a light can keep to: diffuse, specular
POWER = 1.0e9                         # W, a point probe
SUN_STRENGTH = 1.0e7                  # W/m2, a sun probe
FLOOR = 1.0e-3                        # the free probe's light below which V is 1
PREFIX = "Relight Probe"
COLOURS = {1: (1.0, 0.0, 0.0), 0: (0.0, 1.0, 0.0)}     # shadowed: R, free: G
COLLECTION_NAMES = {"probes": "Relight Shadow Probes", "receivers": "Relight Probe Receivers",
                    "blockers": "Relight Probe Blockers"}
_NODE_PATH = re.compile(r'nodes\["(.+?)"\]\.(inputs|outputs)\[(\d+)\]')


def available() -> bool:
    """Whether this Blender links lights to receivers and blockers and has Shader to RGB."""
    return (hasattr(bpy.types, "ObjectLightLinking")
            and hasattr(bpy.types, "ShaderNodeShaderToRGB"))


def probes(key) -> dict:
    """{(lamp name, slot, shadowed): probe object} of the scene with ``key``."""
    out = {}
    for obj in bpy.data.objects:
        if PROBE_KEY in obj and ids.ours(obj, key):
            p = obj[PROBE_KEY]
            out[(p["lamp"], int(p["slot"]), int(p["shadowed"]))] = obj
    return out


def _collection(key, role, scene=None):
    found = next((c for c in bpy.data.collections
                  if c.get(COLLECTION_KEY) == role and ids.ours(c, key)), None)
    if found is None:
        found = bpy.data.collections.new(COLLECTION_NAMES[role])
        ids.tag(found, key)
        found[COLLECTION_KEY] = role
    if scene is not None and found.name not in scene.collection.children:
        scene.collection.children.link(found)
    return found


def _members(coll, objs):
    want = {o.name: o for o in objs}
    for o in list(coll.objects):
        if o.name not in want:
            coll.objects.unlink(o)
    for name, o in want.items():
        if name not in coll.objects:
            coll.objects.link(o)


def receivers(scene, key):
    """The objects the probes may light: meshes of ``scene`` with a relit material in every
    slot (a user's material on the same object would be lit by them too)."""
    out = []
    for obj in scene.objects:
        if obj.type != "MESH" or ids.is_generated(obj):
            continue
        mats = [s.material for s in obj.material_slots if s.material is not None]
        if mats and all(ids.ours(m, key) for m in mats):
            out.append(obj)
    return out


def _lamp_object(group):
    ad = group.animation_data
    for fc in (ad.drivers if ad else ()):
        for var in fc.driver.variables:
            if var.type == "TRANSFORMS" and var.targets[0].id is not None:
                return var.targets[0].id
    return None


def _source(group) -> str:
    """What a probe copies from the lamp group: its drivers and constants."""
    ad = group.animation_data
    drivers = sorted((fc.data_path, fc.driver.expression,
                      [(v.name, v.targets[0].id.name if v.targets[0].id else "",
                        v.targets[0].data_path, v.targets[0].transform_type)
                       for v in fc.driver.variables]) for fc in (ad.drivers if ad else ()))
    consts = [tuple(s.default_value) if hasattr(s.default_value, "__len__") else s.default_value
              for n in group.nodes if n.bl_idname in ("ShaderNodeCombineXYZ", "ShaderNodeValue")
              for s in (list(n.inputs) + list(n.outputs)) if hasattr(s, "default_value")]
    lamp = _lamp_object(group)
    sun = lamp is not None and lamp.type == "LIGHT" and lamp.data.type == "SUN"
    return repr((drivers, consts, sun, lamp.name if lamp else ""))


def _make_probe(name, group, slot, shadowed, key, coll, recv, block, source):
    lamp = _lamp_object(group)
    sun = lamp is not None and lamp.type == "LIGHT" and lamp.data.type == "SUN"
    label = f"{PREFIX} {name} {slot} {'shadowed' if shadowed else 'free'}"
    data = bpy.data.lights.new(label, "SUN" if sun else "POINT")
    ids.tag(data, key)
    data.color = COLOURS[shadowed]
    data.energy = SUN_STRENGTH if sun else POWER
    data.use_shadow = bool(shadowed)
    if shadowed and hasattr(data, "use_shadow_jitter"):
        # a render's samples draw points of the lamp: the true penumbra, closer to Cycles' than
        # the filtered one (benchmarks/results/eevee_shadow.md gives what it costs)
        data.use_shadow_jitter = True
    data.diffuse_factor = 1.0 if slot == 0 else 0.0
    data.specular_factor = 0.0 if slot == 0 else 1.0
    for other in ("volume_factor", "transmission_factor"):
        if hasattr(data, other):
            setattr(data, other, 0.0)
    obj = bpy.data.objects.new(label, data)
    ids.tag(obj, key)
    obj[PROBE_KEY] = {"lamp": name, "slot": slot, "shadowed": int(shadowed)}
    obj[SOURCE_KEY] = source
    obj.visible_camera = False          # Cycles would show a point light's sphere
    obj.hide_select = True
    coll.objects.link(obj)
    obj.light_linking.receiver_collection = recv
    if shadowed:
        obj.light_linking.blocker_collection = block
    if sun:
        obj.rotation_mode = "QUATERNION"
        for i, w in enumerate(("ROT_W", "ROT_X", "ROT_Y", "ROT_Z")):
            add_driver(obj, "q", [("q", "TRANSFORMS", lamp, w)], "rotation_quaternion", i)
        add_driver(data, "a", [("a", "LIGHT", lamp.data, "angle")], "angle")
        return obj
    pos = next(n for n in group.nodes if n.bl_idname == "ShaderNodeCombineXYZ")
    rad = next(n for n in group.nodes if n.bl_idname == "ShaderNodeValue")
    obj.location = [pos.inputs[i].default_value for i in range(3)]
    data.shadow_soft_size = rad.outputs[0].default_value
    ad = group.animation_data
    for fc in (ad.drivers if ad else ()):
        m = _NODE_PATH.match(fc.data_path)
        if m is None:
            continue
        node = group.nodes[m.group(1)]
        if node == pos:
            copy_driver(fc, obj, "location", int(m.group(3)))
        elif node == rad:
            copy_driver(fc, data, "shadow_soft_size")
    return obj


def _remove(obj):
    data = obj.data
    bpy.data.objects.remove(obj)
    if data is not None and data.users == 0:
        bpy.data.lights.remove(data)


def sync(scene, key, lamp_groups, names, recv, blockers) -> dict:
    """The probes of ``scene`` for the lamps ``names`` (the first SLOTS of them, in that order),
    lighting ``recv`` (see receivers) and shadowed by ``blockers`` (the moving objects): made
    where missing or made from another lamp group, the others removed.  Returns {lamp name:
    slot}."""
    slots = {n: i for i, n in enumerate([n for n in names if n in lamp_groups][:SLOTS])}
    if not slots or not recv or not blockers:
        remove(key)
        return {}
    have = probes(key)
    rc, bc = _collection(key, "receivers"), _collection(key, "blockers")
    _members(rc, recv)
    _members(bc, blockers)
    coll = _collection(key, "probes", scene)
    sources = {name: _source(lamp_groups[name]) for name in slots}
    for k, obj in list(have.items()):
        name, slot, _ = k
        if slots.get(name) != slot or obj.get(SOURCE_KEY) != sources[name]:
            _remove(obj)
            del have[k]
    for name, slot in slots.items():
        for shadowed in (1, 0):
            if (name, slot, shadowed) not in have:
                _make_probe(name, lamp_groups[name], slot, shadowed, key, coll, rc, bc,
                            sources[name])
    reach = _reach(recv, lamp_groups.values())
    for obj in probes(key).values():
        if obj.data.type != "SUN":
            obj.data.use_custom_distance = True
            obj.data.cutoff_distance = reach
    show(scene, key, True)
    return slots


def _reach(recv, groups):
    """A distance past every receiver from every lamp: the probes' cutoff.  Without one EEVEE
    takes the distance at which a probe's POWER falls below its light threshold (hundreds of
    kilometres), and its shadow maps' depth range, so their precision, with it: no shadow."""
    pts = [np.array(o.matrix_world) @ np.append(np.array(c), 1.0)
           for o in recv for c in o.bound_box]
    for g in groups:
        pos = next((n for n in g.nodes if n.bl_idname == "ShaderNodeCombineXYZ"), None)
        if pos is not None:
            pts.append(np.append([pos.inputs[i].default_value for i in range(3)], 1.0))
    if not pts:
        return 100.0
    pts = np.array(pts)[:, :3]
    return float(2.0 * np.linalg.norm(pts.max(axis=0) - pts.min(axis=0)) + 1.0)


def show(scene, key, on):
    """Probes on (the relit materials shown) or off (the user's materials back)."""
    on = bool(on) and bool(receivers(scene, key))
    for obj in probes(key).values():
        obj.hide_render = obj.hide_viewport = not on


def remove(key):
    """Every probe and collection made here for the scene with ``key``."""
    for obj in probes(key).values():
        _remove(obj)
    for c in [c for c in bpy.data.collections if COLLECTION_KEY in c and ids.ours(c, key)]:
        bpy.data.collections.remove(c)


def visibility(node, math, tree, slot, loc):
    """V of the probes of ``slot`` at the shading point, built in a material with sphere_nodes'
    helpers ``node`` and ``math``: 1 - [G > FLOOR] (1 - clamp(R / max(G, FLOOR)))."""
    x, y = loc
    bsdf = node("ShaderNodeBsdfDiffuse" if slot == 0 else "ShaderNodeBsdfGlossy",
                f"Probe BSDF {slot}", (x, y))
    bsdf.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    if slot != 0:
        bsdf.inputs["Roughness"].default_value = 1.0     # broad: light wherever diffuse has
    rgb = node("ShaderNodeShaderToRGB", f"Probe light {slot}", (x + 160, y))
    tree.links.new(bsdf.outputs[0], rgb.inputs[0])
    sep = node("ShaderNodeSeparateColor", f"Probe channels {slot}", (x + 320, y))
    tree.links.new(rgb.outputs["Color"], sep.inputs[0])
    red, green = sep.outputs[0], sep.outputs[1]
    seen = math("DIVIDE", red, math("MAXIMUM", green, FLOOR, "Probe free", (x + 480, y - 60)),
                "Probe seen", (x + 640, y))
    seen.node.use_clamp = True
    reached = math("GREATER_THAN", green, FLOOR, "Probe reach", (x + 480, y + 60))
    lost = math("MULTIPLY", reached, math("SUBTRACT", 1.0, seen, "Probe hidden", (x + 800, y)),
                "Probe lost", (x + 960, y))
    return math("SUBTRACT", 1.0, lost, "Probe V", (x + 1120, y))
