# SPDX-License-Identifier: GPL-3.0-or-later
"""Write the AR composite into the scene: the receivers' materials, the compositor's
differential composite, the render settings it needs.

* Receivers: each slot of a receiver shows a material ``"<original>.relight_ar"`` (the user's
  material is kept, as the relit materials keep theirs: materials.py): a holdout for camera
  rays (the compositor puts the photo there, darkened by the shadow factor), the photo as
  Emission for every other ray (it is what the surface sends: the objects' reflections and
  the light bounced onto them see it), read through ``"Relight AR Camera"`` (the camera's
  projection of the shading point); its coverage, position and normal go to three AOVs.
* Compositor: ``"Relight AR Composite"`` (ar_nodes.py) between the Render Layers and the
  output: of the scene's compositing node group if it has one (inserted after the Render
  Layers' Image, undone by clear), else of a new one.
* The virtual objects keep their own materials: the render engine lights them with the World
  (diffuse, glossy, their occlusion) and they see the receivers' photo around them.  EEVEE
  lights them by the World alone (its world probe), which below the horizon shows the map's
  own ground where Cycles' rays meet the receivers: the World's output is kept for Cycles and
  a second one, for EEVEE, shows the photo projected onto the ground there (write_world,
  core/ar/ground.py); Clear removes it.
* Render settings: the Standard view transform (the photo must come out as it went in) and a
  transparent film (the photo is put behind in the compositor).  Their previous values are
  remembered.
"""
from __future__ import annotations

import bpy
import numpy as np

from . import ar_nodes, ids, materials
from .drivers import add_driver, frame_vars, world_point_expressions
from .nodes import Builder

AR_MATERIAL = "relight_ar_material"     # on a receiver's AR material: "receiver"
MAT_SUFFIX = ".relight_ar"
COMPOSITOR_PREFIX = "Relight AR"        # compositor nodes made here
ADDED_SLOT = "relight_ar_added_slot"    # on a receiver that had no material slot
OUR_TREE = "relight_ar_compositing"     # on a compositing node group made here
SETTINGS = (("view_settings", "view_transform", "Standard"), ("view_settings", "look", "None"),
            ("view_settings", "exposure", 0.0), ("view_settings", "gamma", 1.0),
            ("render", "film_transparent", True), ("render", "use_compositing", True))


# -- the receivers' material -------------------------------------------------------------------

def receiver_material(name, camera, photo, key):
    """A new receiver material (see the module docstring)."""
    mat = bpy.data.materials.new(name)
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True
    tree = mat.node_tree
    for n in list(tree.nodes):
        tree.nodes.remove(n)
    b = Builder(tree)
    geo = b.node("ShaderNodeNewGeometry")
    path = b.node("ShaderNodeLightPath")
    b.column()
    cam = ar_nodes.group_node(b, camera, Position=geo.outputs["Position"], Point=1.0)
    tex = b.node("ShaderNodeTexImage", "Photo", image=photo, interpolation="Linear",
                 extension="EXTEND")
    # the UV held in the frame: behind the camera (and far outside its frame) the projection
    # runs to 1e7, and Cycles' image lookup returned values of up to 1e6 there, which
    # fireflied the objects' reflections (400 x 300: 80 object pixels above 100); EXTEND
    # shows the frame's edge either way
    uv = b.vmath("MINIMUM", b.vmath("MAXIMUM", cam.outputs["UV"], (0.0, 0.0, 0.0)),
                 (1.0, 1.0, 0.0))
    b.link(uv, tex.inputs["Vector"])
    b.column()
    emit = b.node("ShaderNodeEmission")
    b.link(tex.outputs["Color"], emit.inputs["Color"])
    hold = b.node("ShaderNodeHoldout")
    mix = b.node("ShaderNodeMixShader")
    b.link(path.outputs["Is Camera Ray"], mix.inputs[0])
    b.link(emit.outputs[0], mix.inputs[1])
    b.link(hold.outputs[0], mix.inputs[2])
    b.column()
    for aov, sock in ((ar_nodes.AOV_COVERAGE, None), (ar_nodes.AOV_POSITION, "Position"),
                      (ar_nodes.AOV_NORMAL, "Normal")):
        out = b.node("ShaderNodeOutputAOV")
        out.aov_name = aov
        if sock is None:
            out.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
        else:
            b.link(geo.outputs[sock], out.inputs["Color"])
    o = b.node("ShaderNodeOutputMaterial")
    b.link(mix.outputs[0], o.inputs["Surface"])
    o.is_active_output = True
    ids.tag(mat, key)
    mat[AR_MATERIAL] = "receiver"
    # the photo lights the objects by the rays they send it; sampled as a lamp it costs more
    if hasattr(mat, "cycles"):
        mat.cycles.emission_sampling = "NONE"
    return mat


def ar_materials(key):
    return [m for m in bpy.data.materials if ids.ours(m, key) and m.get(AR_MATERIAL)]


def write_receivers(scene, receivers, camera, photo, key):
    """Every slot of every receiver shows the AR material of its original; slots of objects
    no longer receivers get their original back; old AR materials are removed.  Returns the
    number of slots written."""
    old = ar_materials(key)
    made = {}
    count = 0
    names = {o.name for o in receivers}
    for obj in receivers:
        if not materials.slots_editable(obj):
            continue
        if not obj.material_slots:
            obj.data.materials.append(None)
            obj[ADDED_SLOT] = 1
        for i, slot in enumerate(obj.material_slots):
            orig = materials.original_material(slot.material)
            label = orig.name_full if orig is not None else ""
            mat = made.get(label)
            if mat is None:
                mat = made[label] = receiver_material(
                    (orig.name if orig is not None else "Relight AR Receiver") + MAT_SUFFIX,
                    camera, photo, key)
                if orig is not None:
                    mat[ids.ORIGINAL] = orig
            materials.assign(obj, i, mat, key)
            count += 1
    for obj in scene.objects:
        if obj.name in names:
            continue
        for slot in obj.material_slots:
            if slot.material is not None and slot.material in old:
                slot.material = materials.original_material(slot.material)
    for m in old:
        bpy.data.materials.remove(m)
    return count


def restore_receivers(scene, key):
    """The receivers' originals back, our slots removed, the AR materials deleted."""
    old = ar_materials(key)
    for obj in scene.objects:
        for slot in obj.material_slots:
            if slot.material is not None and slot.material in old:
                orig = materials.original_material(slot.material)
                slot.material = orig
                materials.release_original(orig)
        if obj.get(ADDED_SLOT) and obj.type == "MESH" and len(obj.data.materials) == 1 \
                and obj.data.materials[0] is None:
            obj.data.materials.clear()
            del obj[ADDED_SLOT]
    for m in old:
        bpy.data.materials.remove(m)


# -- the World EEVEE sees ------------------------------------------------------------------------

WORLD_OUTPUT = "Relight AR World (EEVEE)"   # the World output node made here (target EEVEE)
WORLD_GROUP_NODE = "Relight AR Ground"      # its group node
WORLD_SAVED = "relight_ar_world"            # on the World: the scene key, its active outputs
WORLD_TAG = "relight_ar_world_node"         # on the nodes made here: the scene key
SHADER = "NodeSocketShader"


def ground_group(key, model, photo, plane):
    """``"Relight AR Ground"`` (a shader group for the World): Surface (the World's shader),
    Origin (the object's centre) -> Surface: below the horizon, where the direction from Origin
    meets the ground rectangle ``plane`` (core/ar/ground.py) in the photo's frame, the photo
    there (a Background of its colour, as the receivers emit it); elsewhere the World's own.
    The photo's frame is that of the camera ``model`` (core/ar/view.py) as constants: the
    receivers' driven camera group in the World made EEVEE's renders last minutes on
    llvmpipe, and the World's ground waits for Update after a camera move."""
    height, (x0, x1, y0, y1) = plane
    ng, gin, gout, b = ar_nodes.world_group(key, [("Surface", SHADER),
                                                  ("Origin", "NodeSocketVector")],
                                            [("Surface", SHADER)])
    if b is None:
        return ng
    coord = b.node("ShaderNodeTexCoord")
    d = b.vmath("NORMALIZE", coord.outputs["Generated"])
    dz = ar_nodes.separate(b, d)[2]
    oz = ar_nodes.separate(b, gin.outputs["Origin"])[2]
    b.column()
    # t = (height - Origin_z) / d_z along directions going down (d_z < 0: t > 0 over the ground)
    t = b.math("DIVIDE", b.math("SUBTRACT", height, oz), b.math("MINIMUM", dz, -1e-6))
    hit = b.vmath("ADD", gin.outputs["Origin"], b.vmath("SCALE", d, scale=t))
    hx, hy = ar_nodes.separate(b, hit)[:2]
    b.column()
    # the camera frame q = (p - o) R (view.CameraModel.to_camera), u and v as project() has them
    m = np.asarray(model.matrix, float)
    r = m[:3, :3] / np.maximum(np.linalg.norm(m[:3, :3], axis=0, keepdims=True), 1e-300)
    o = m[:3, 3]
    q = [b.math("SUBTRACT", b.vmath("DOT_PRODUCT", hit, tuple(r[:, j])), float(o @ r[:, j]))
         for j in range(3)]
    depth = b.math("MULTIPLY", q[2], -1.0)
    front = b.math("GREATER_THAN", depth, 1e-6)
    safe = b.math("MAXIMUM", depth, 1e-6)
    a_u, a_v, b_u, b_v = model.factors()
    u = b.math("MULTIPLY_ADD", b.math("DIVIDE", q[0], safe), a_u, 0.5 - b_u)
    v = b.math("MULTIPLY_ADD", b.math("DIVIDE", q[1], safe), a_v, 0.5 - b_v)
    b.column()
    tests = [b.math("LESS_THAN", dz, -1e-4), b.math("GREATER_THAN", oz, height), front]
    for value, lo, hi in ((hx, x0, x1), (hy, y0, y1), (u, 0.0, 1.0), (v, 0.0, 1.0)):
        tests += [b.math("GREATER_THAN", value, lo), b.math("LESS_THAN", value, hi)]
    seen = tests[0]
    for other in tests[1:]:
        seen = b.math("MULTIPLY", seen, other)
    b.column()
    uv = b.node("ShaderNodeCombineXYZ")
    b.link(u, uv.inputs[0])
    b.link(v, uv.inputs[1])
    tex = b.node("ShaderNodeTexImage", "Photo", image=photo, interpolation="Linear",
                 extension="EXTEND")
    b.link(uv.outputs[0], tex.inputs["Vector"])
    bg = b.node("ShaderNodeBackground")
    b.link(tex.outputs["Color"], bg.inputs["Color"])
    b.column()
    mix = b.node("ShaderNodeMixShader")
    b.link(seen, mix.inputs[0])
    b.link(gin.outputs["Surface"], mix.inputs[1])
    b.link(bg.outputs[0], mix.inputs[2])
    b.link(mix.outputs[0], gout.inputs["Surface"])
    return ng


def write_world(scene, model, photo, plane, obj, key):
    """EEVEE's World: the shader EEVEE rendered the World with, through ``ground_group`` (the
    photo below the horizon), in a World output of its own targeted at EEVEE (Blender renders
    each engine with the output of its own target before one for all); Cycles keeps its output
    as it was.  Origin follows the middle of ``obj``'s bounding box (drivers: the object moved,
    turned or scaled needs no Update; the ground's rectangle is Update's).  Returns a warning
    (one sentence) or None; nothing is written without a ground ``plane``, or where the World
    is not the scene's to change."""
    restore_world(key)
    world = scene.world
    tree = world.node_tree if world is not None else None
    if tree is None or obj is None:
        return None
    if plane is None:
        return ("EEVEE: no receiver faces up under the objects, so below the horizon they see "
                "the environment map's own ground, not the photo's (Cycles sees the receivers)")
    if world.library is not None or not getattr(world, "is_editable", True):
        return (f"EEVEE: the World '{world.name}' is linked from a library, so below the "
                "horizon the objects see the environment map's own ground, not the photo's")
    src = tree.get_output_node("EEVEE")
    if src is None or not src.inputs["Surface"].is_linked:
        return None
    outputs = [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputWorld"]
    world[WORLD_SAVED] = {"key": key,
                          "active": "\n".join(n.name for n in outputs if n.is_active_output)}
    b = Builder(tree, src.location.x, src.location.y - 300)
    g = ar_nodes.group_node(b, ground_group(key, model, photo, plane))
    g.name = g.label = WORLD_GROUP_NODE
    g[WORLD_TAG] = key
    b.link(src.inputs["Surface"].links[0].from_socket, g.inputs["Surface"])
    corners = np.array([tuple(c) for c in obj.bound_box], float)
    local = 0.5 * (corners.min(axis=0) + corners.max(axis=0))
    for i, expr in enumerate(world_point_expressions(local)):
        add_driver(g.inputs["Origin"], expr, frame_vars(obj), index=i)
    b.column()
    new = b.node("ShaderNodeOutputWorld", WORLD_OUTPUT, target="EEVEE")
    new[WORLD_TAG] = key
    b.link(g.outputs["Surface"], new.inputs["Surface"])
    if src.inputs["Volume"].is_linked:
        b.link(src.inputs["Volume"].links[0].from_socket, new.inputs["Volume"])
    if src.target == "EEVEE":       # the user's own EEVEE output: ours must be the active one
        new.is_active_output = True
    users = [s.name for s in bpy.data.scenes if s.world == world and s != scene]
    if users:
        return (f"EEVEE: the World '{world.name}' is also the World of {', '.join(users)}: "
                "there EEVEE's World shows this scene's photo below the horizon too (give this "
                "scene a World of its own to keep theirs)")
    return None


def restore_world(key):
    """Every World as it was before write_world for the scene with ``key``: our nodes removed
    (their drivers with them), the outputs that were active active again."""
    for world in bpy.data.worlds:
        tree = world.node_tree
        if tree is None:
            continue
        for node in [n for n in tree.nodes if n.get(WORLD_TAG) == key]:
            tree.nodes.remove(node)
        saved = world.get(WORLD_SAVED)
        if saved is not None and saved.get("key") == key:
            for name in str(saved.get("active", "")).split("\n"):
                node = tree.nodes.get(name) if name else None
                if node is not None:
                    node.is_active_output = True
            del world[WORLD_SAVED]


def has_world(scene, key) -> bool:
    """Whether the scene's World has the EEVEE output of write_world."""
    tree = scene.world.node_tree if scene.world is not None else None
    return tree is not None and any(n.get(WORLD_TAG) == key for n in tree.nodes)


# -- the view layer's passes and the compositor -------------------------------------------------

def add_aovs(scene):
    """The receivers' AOVs on every view layer of ``scene`` (returns those added)."""
    added = []
    for layer in scene.view_layers:
        have = {a.name: a for a in layer.aovs}
        for name, kind in ar_nodes.AOVS:
            if name not in have:
                a = layer.aovs.add()
                a.name, a.type = name, kind
                added.append(f"{layer.name}/{name}")
            elif have[name].type != kind:      # a file set up when the coverage was a Value
                have[name].type = kind
    return added


def remove_aovs(scene):
    for layer in scene.view_layers:
        for a in [a for a in layer.aovs if a.name in dict(ar_nodes.AOVS)]:
            layer.aovs.remove(a)


def _render_layers(tree, scene):
    nodes = [n for n in tree.nodes if n.bl_idname == "CompositorNodeRLayers"
             and (n.scene is None or n.scene == scene)]
    return nodes[0] if nodes else None


def clear_compositor(scene):
    """Our composite out of the scene's compositor: the node group made here is dropped, or
    our group node removed from the user's and its links restored."""
    tree = getattr(scene, "compositing_node_group", None)
    if tree is None:
        return
    if tree.get(OUR_TREE):
        scene.compositing_node_group = None
        if tree.users == 0:
            bpy.data.node_groups.remove(tree)
        return
    node = tree.nodes.get(f"{COMPOSITOR_PREFIX} Composite")
    if node is None:
        return
    src = node.inputs["Image"].links[0].from_socket if node.inputs["Image"].is_linked else None
    targets = [link.to_socket for link in node.outputs[0].links]
    tree.nodes.remove(node)
    if src is not None:
        for t in targets:
            tree.links.new(src, t)


def write_compositor(scene, group, key):
    """``group`` ("Relight AR Composite") after the Render Layers: in the scene's compositing
    node group (after its Render Layers' Image), or in a new one."""
    clear_compositor(scene)
    tree = getattr(scene, "compositing_node_group", None)
    if tree is None:
        tree = bpy.data.node_groups.new("Relight AR Compositing", ar_nodes.COMPOSITOR)
        tree.interface.new_socket("Image", in_out="OUTPUT", socket_type="NodeSocketColor")
        tree[OUR_TREE] = 1
        ids.tag(tree, key)
        rl = tree.nodes.new("CompositorNodeRLayers")
        rl.scene = scene
        out = tree.nodes.new("NodeGroupOutput")
        out.location = (900, 0)
        targets = [out.inputs[0]]
        scene.compositing_node_group = tree
    else:
        rl = _render_layers(tree, scene)
        if rl is None:
            rl = tree.nodes.new("CompositorNodeRLayers")
            rl.scene = scene
        targets = [link.to_socket for link in rl.outputs["Image"].links]
    node = tree.nodes.new("CompositorNodeGroup")
    node.name = node.label = f"{COMPOSITOR_PREFIX} Composite"
    node.node_tree = group
    node.location = (rl.location.x + 400, rl.location.y)
    for sock, name in (("Image", "Image"), ("Alpha", "Alpha"),
                       (ar_nodes.AOV_COVERAGE, "Coverage"), (ar_nodes.AOV_POSITION, "Position"),
                       (ar_nodes.AOV_NORMAL, "Normal")):
        tree.links.new(rl.outputs[sock], node.inputs[name])
    for t in targets:
        tree.links.new(node.outputs["Image"], t)
    return tree


# -- render settings ---------------------------------------------------------------------------

def apply_settings(scene, saved):
    """Set what the composite needs (SETTINGS), remembering the previous values in ``saved``
    (a dict, filled once); returns the names changed."""
    changed = []
    for owner, attr, value in SETTINGS:
        target = getattr(scene, owner)
        now = getattr(target, attr)
        if f"{owner}.{attr}" not in saved:
            saved[f"{owner}.{attr}"] = now
        if now != value:
            setattr(target, attr, value)
            changed.append(attr)
    return changed


def restore_settings(scene, saved):
    for owner, attr, _ in SETTINGS:
        k = f"{owner}.{attr}"
        if k in saved:
            try:
                setattr(getattr(scene, owner), attr, saved[k])
            except (TypeError, ValueError):
                pass


def light_records(lighting):
    """The lights as stored on the scene (JSON-able)."""
    return [{"direction": [float(x) for x in lt.direction], "half_angle": float(lt.half_angle),
             "solid_angle": float(lt.solid_angle), "radiance": [float(x) for x in lt.radiance],
             "share": float(lt.share)} for lt in lighting.lights if lt.solid_angle > 0]


def light_terms(records):
    """(direction, angle, cap, radiance, sin^2 half-angle) of each stored light."""
    from ..core.ar.cap import cone_sin2
    from ..core.ar.main_light import MainLight
    out = []
    for r in records:
        lt = MainLight(ids.array(r["direction"]), r["solid_angle"], r["half_angle"],
                       ids.array(r["radiance"]), np.zeros(3), r["share"], 1)
        d, angle, cap = ar_nodes.light_constants(lt)
        out.append((d, angle, cap, ids.array(r["radiance"]),
                    float(cone_sin2(r["half_angle"]))))
    return out
