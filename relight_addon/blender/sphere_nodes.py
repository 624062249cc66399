"""Moving virtual objects: their soft shadows evaluated by the relit materials at render time.

A virtual object whose shadows are set to "Moving" is not put into the precompute; it is
approximated by spheres in its own coordinates (core/relight/spheres.py) and every relit material
multiplies each lamp's term by ``1 - a_k (1 - V_k)``: ``V_k`` the part of lamp k seen past the
spheres (core/relight/sphere_shadow.py, of which the node group below is a twin: the same
operations in the same order), ``a_k`` the part of the map that is the lamp's direct light (the
map image's alpha).  Nothing runs in Python at render time:

* ``"Relight Lamp <lamp>"`` node groups (one per lamp, made by write.py) output the lamp's world
  position and radius, driven from the light (TRANSFORMS driver variables, simple expressions);
  a sun is a disk SUN_DISTANCE away along its direction; an emissive-face lamp is a constant disk.
* ``"Relight Spheres <object>"`` node groups (one per moving object) take the shading point and a
  lamp, bring both into the object's frame (its world location, rotation and scale, driven) and
  return V: one ``"Relight Sphere Cap"`` node (a shared group) per sphere, chained through a
  running product and maximum so that Cycles evaluates one sphere after the other (side by
  side, their intermediate values overflowed its 255-float SVM stack beyond 16-24 spheres).
  Spheres are fitted once; the object's animation, drags and parenting move them.
* Culling (what cannot shadow costs no sphere): each lamp term a moving object can darken is its
  own Mix Shader closure on "Reach" (a ``"Relight Reach <object>"`` group: the double cone
  tangent to the object's bounding sphere and the lamp's ball, sphere_shadow.may_shadow, and a
  direct part in the map there), which Cycles' SVM jumps over where it is 0; a lamp whose map
  has no direct part anywhere gets no spheres.  EEVEE evaluates both branches: there only the
  lamps dropped save time.  A material holds a sphere group only for the lamps an engine
  evaluates spheres for (Cycles reads every node of a tree, used or not).

* Cycles, where the scene's Cycles Moving Shadows is "Rays": the materials get a second output,
  for Cycles, whose factors take V from rays cast at the objects' real meshes (ray_shadow.py;
  before Blender 5.1, which has no Raycast node, each ray reads the object's line table:
  line_nodes.py).
* EEVEE, where the scene's EEVEE Moving Shadows is "Shadow Maps": the material's own output
  takes V of (at most) two lamps from EEVEE's shadow maps of probe lights (eevee_shadow.py), and
  a second output serves Cycles (rays, or the spheres).  The spheres' reach branches stay (the
  reach tests are shared by both outputs); EEVEE then compiles no sphere for those lamps.

So a keyframed object renders its moving shadows in Cycles and EEVEE from the .blend alone, with
the extension absent and Python auto-run off.  Deforming the mesh or changing the sphere count
needs Update (the spheres are fitted again).

Settled: where the objects stand when Update runs, their real triangles' shadows are ray-traced
once (core/relight/settled.py) into ``"<photo>.relight.settled.<n>"`` images (four lamps per
image, one channel each), and a ``"Relight Settled"`` group outputs 1 while every moving object
keeps that transform (a driver comparing the ten transform channels of each): the materials then
take the exact V_k instead of the spheres', and the spheres' again as soon as one moves.  The
shadows fall on the relit surfaces only, the
indirect light the object blocks or reflects is not modelled (the "Exact" mode does that, on
Update), and an object's own appearance is lit as any object in the scene.
"""
from __future__ import annotations

import hashlib

import bpy
import numpy as np

from ..core.relight.settled import object_visibility, visibility_images
from ..core.relight.sphere_shadow import EPS_ANGLE, SUN_DISTANCE, bounding_sphere
from ..core.relight.spheres import fit_spheres, silhouette_sphere
from . import eevee_shadow, ids, ray_shadow
from .drivers import add_driver, frame_vars, world_point_expressions
from .ids import MAP_SOURCE, scene_key
from .images import CONTENT, MapWriter
from .nodes import Builder, local_frame, new_group
from .roles import DEFAULT_SPHERES, moving, moving_objects, sphere_count  # noqa: F401
from .write import MAP_PREFIX, SHADOW_PREFIX, T_NODE

LAMP_KEY = "relight_lamp"              # on a lamp group: the lamp's name (as in the maps)
OBJECT_KEY = "relight_sphere_object"   # on a sphere group: the object's name
REACH_KEY = "relight_reach_object"     # on a reach group: the object's name
REACH_MESH_KEY = "relight_reach_mesh"   # on a reach group: 1 when its bound holds the mesh's
FIT_KEY = "relight_sphere_fit"         # on a sphere group: hash of the mesh and sphere count
SPHERES_KEY = "relight_spheres"        # on a sphere group: x, y, z, radius per sphere (own frame)
HULL_KEY = "relight_sphere_hull"       # on a sphere group: x, y, z, radius of the silhouette sphere
BOUND_KEY = "relight_sphere_bound"     # on a sphere group: x, y, z, radius of the bounding sphere
CAP_KEY = "relight_sphere_cap"         # on the shared per-sphere group: its version
WIRING_KEY = "relight_sphere_wiring"   # on a relit material: the groups it is wired to
NODE_PREFIX = "Relight Shadow"         # material nodes made here (removed before each sync)
SURFACE_KEY = "relight_sphere_surface" # on a relit material: the closure its output had before
DIRECT_KEY = "relight_direct_max"      # on a map image: its largest alpha, for its content hash
RAYS_KEY = "relight_sphere_rays"     # on a relit material: its own output was set to EEVEE
CYCLES_OUTPUT = f"{NODE_PREFIX} Cycles output"
WIRING_VERSION = 6                     # of the material wiring (older wirings are made again)
# A map whose direct part (alpha) stays below this everywhere gets no sphere shadow: dropping
# it changes the lamp's term by at most this fraction (the half-float maps' own spacing is 1e-3).
DIRECT_FLOOR = 1e-3
SQRT_PI = float(np.sqrt(np.pi))
SETTLED_KEY = "relight_settled"        # on a settled image: its channels' lamps; on the group:
SETTLED_FITS = "relight_settled_fits"  # the objects' fit hashes it was computed for
SETTLED_GROUP = "Relight Settled"
SETTLED_SUFFIX = ".relight.settled"
TRANSFORM_CHANNELS = ("LOC_X", "LOC_Y", "LOC_Z", "ROT_W", "ROT_X", "ROT_Y", "ROT_Z",
                      "SCALE_X", "SCALE_Y", "SCALE_Z")
SETTLE_TOLERANCE = 1e-4                # sum of |transform - settled transform|
# Sphere tests (lamps x spheres of all moving objects) per relit material that EEVEE compiled in
# benchmarks/results/moving_objects.md (2 lamps x 2 x 32; 2 x 2 x 128 rendered magenta).
EEVEE_SPHERE_TESTS = 128


# -- drivers ---------------------------------------------------------------------------------

def _transform_vars(obj, what):
    return [(w.lower().replace("_", ""), "TRANSFORMS", obj, w) for w in what]


# -- lamps -------------------------------------------------------------------------------------

def _area_radius_expression(light):
    shape = getattr(light, "shape", "SQUARE")
    if shape == "SQUARE":
        return f"s * sc / {SQRT_PI!r}"
    if shape == "RECTANGLE":
        return f"sqrt(s * t) * sc / {SQRT_PI!r}"
    if shape == "DISK":
        return "s * sc / 2"
    return "sqrt(s * t) * sc / 2"            # ELLIPSE


def make_lamp_group(name, key, obj=None, centre=None, radius=0.0):
    """The node group of lamp ``name``: outputs its world position and radius (driven from the
    light object ``obj``, or the constants ``centre`` / ``radius`` of an emissive-face lamp)."""
    ng, gin, gout = new_group(f"Relight Lamp {name}", [],
                               [("Position", "NodeSocketVector"), ("Radius", "NodeSocketFloat")],
                               key)
    ng[LAMP_KEY] = name
    ng.use_fake_user = True        # kept when no moving object uses it yet (save, reopen)
    pos = ng.nodes.new("ShaderNodeCombineXYZ")
    rad = ng.nodes.new("ShaderNodeValue")
    ng.links.new(pos.outputs[0], gout.inputs["Position"])
    ng.links.new(rad.outputs[0], gout.inputs["Radius"])
    if obj is None or obj.type != "LIGHT":
        c = np.zeros(3) if centre is None else np.asarray(centre, float)
        for i in range(3):
            pos.inputs[i].default_value = float(c[i])
        rad.outputs[0].default_value = float(radius)
        return ng
    light = obj.data
    if light.type == "SUN":
        q = _transform_vars(obj, ("ROT_W", "ROT_X", "ROT_Y", "ROT_Z"))
        d = SUN_DISTANCE
        exprs = (f"{d!r} * 2 * (rotx * rotz + rotw * roty)",
                 f"{d!r} * 2 * (roty * rotz - rotw * rotx)",
                 f"{d!r} * (1 - 2 * (rotx * rotx + roty * roty))")
        for i, e in enumerate(exprs):
            add_driver(pos.inputs[i], e, q)
        add_driver(rad.outputs[0], f"{d!r} * tan(a / 2)", [("a", "LIGHT", light, "angle")])
        return ng
    for i, w in enumerate(("LOC_X", "LOC_Y", "LOC_Z")):
        add_driver(pos.inputs[i], "v", [("v", "TRANSFORMS", obj, w)])
    if light.type == "AREA":
        add_driver(rad.outputs[0], _area_radius_expression(light),
                [("s", "LIGHT", light, "size"), ("t", "LIGHT", light, "size_y"),
                 ("sc", "TRANSFORMS", obj, "SCALE_AVG")])
    else:
        add_driver(rad.outputs[0], "r", [("r", "LIGHT", light, "shadow_soft_size")])
    return ng


def emissive_disk(scene_data, k):
    """(centre, radius) of emissive-face lamp ``k``: the area-weighted centroid of its faces and
    the disk with the same spread (a uniform disk of radius R has RMS radius R / sqrt 2)."""
    from ..core.lights import POLYGON
    from ..core.scene import quad_area_normal
    sel = np.flatnonzero(np.asarray(scene_data.lamp) == k)
    lights = scene_data.lights
    rows = np.flatnonzero((lights.lamp == k) & (lights.kind == POLYGON))
    # its faces: patches, or polygon lights (a small virtual emissive mesh)
    faces = np.concatenate([scene_data.corners[sel], lights.corners[rows]])
    if len(faces) == 0:
        return np.zeros(3), 0.0
    area, _ = quad_area_normal(faces)
    a = np.maximum(area, 0.0)
    pts = faces.mean(axis=1)
    w = a / max(a.sum(), 1e-300)
    centre = (pts * w[:, None]).sum(0)
    rms = float(np.sqrt((w * np.sum((pts - centre) ** 2, axis=1)).sum()))
    return centre, float(np.sqrt(2.0) * rms)


def lamp_groups(key):
    return {ng[LAMP_KEY]: ng for ng in bpy.data.node_groups
            if LAMP_KEY in ng and ng.get(ids.SCENE_KEY) == key}


# -- objects -----------------------------------------------------------------------------------

def object_triangles(obj, depsgraph):
    """The evaluated mesh's triangles (t, 3, 3) in the object's own coordinates."""
    ev = obj.evaluated_get(depsgraph)
    me = ev.to_mesh()
    try:
        me.calc_loop_triangles()
        nv, nt = len(me.vertices), len(me.loop_triangles)
        co = np.empty(nv * 3, np.float32)
        me.vertices.foreach_get("co", co)
        tri = np.empty(nt * 3, np.int32)
        me.loop_triangles.foreach_get("vertices", tri)
    finally:
        ev.to_mesh_clear()
    return co.reshape(-1, 3).astype(np.float64)[tri.reshape(-1, 3)]


GROUP_VERSION = 4                      # of the sphere groups (older ones are made again)


def _fit_hash(tris, n):
    h = hashlib.sha1(np.ascontiguousarray(tris, np.float32).tobytes())
    h.update(f"{n}:{GROUP_VERSION}".encode())
    return h.hexdigest()


CAP_GROUP = "Relight Sphere Cap"
CAP_VERSION = 2


def _clamped(socket):
    socket.node.use_clamp = True
    return socket


def _map_range(b, value, from_min, from_max, to_min, to_max, smooth=False):
    """A Map Range node (float): to_min + (to_max - to_min) x ramp((value - from_min) /
    (from_max - from_min)), the ramp a smoothstep or a clamped line.  One node for what takes a
    division, a clamp and a multiply-add in Math nodes."""
    n = b.node("ShaderNodeMapRange", data_type="FLOAT",
               interpolation_type="SMOOTHSTEP" if smooth else "LINEAR", clamp=not smooth)
    for name, v in (("Value", value), ("From Min", from_min), ("From Max", from_max),
                    ("To Min", to_min), ("To Max", to_max)):
        if isinstance(v, (int, float)):
            n.inputs[name].default_value = float(v)
        else:
            b.link(v, n.inputs[name])
    return n.outputs["Result"]


def cap_group(key, tree_type="ShaderNodeTree"):
    """The shared node group of one sphere (sphere_shadow.blocked_part's b, in the object's
    frame, chained): Product' = Product (1 - min(b / Part, 1)), Max' = max(Max, b).
    ``tree_type``: a shader group, or the compositor's (AR mode)."""
    for ng in bpy.data.node_groups:
        if ng.get(CAP_KEY) == CAP_VERSION and ng.get(ids.SCENE_KEY) == key and \
                ng.bl_idname == tree_type:
            return ng
    for old in [ng for ng in bpy.data.node_groups if CAP_KEY in ng
                and ng.get(ids.SCENE_KEY) == key and ng.bl_idname == tree_type
                and ng.users <= 1]:
        bpy.data.node_groups.remove(old)              # an older version nothing uses
    vec, flt = "NodeSocketVector", "NodeSocketFloat"
    ng, gin, gout = new_group(CAP_GROUP, [
        ("Position", vec), ("Direction", vec), ("Lamp Distance", flt), ("Lamp Angle", flt),
        ("Lamp Cap", flt), ("Centre", vec), ("Radius", flt), ("Product", flt), ("Max", flt),
        ("Part", flt)], [("Product", flt), ("Max", flt)], key, tree_type)
    ng[CAP_KEY] = CAP_VERSION
    ng.use_fake_user = True
    b = Builder(ng)
    i = gin.outputs
    # the centre waits for the previous sphere's product (x 1e-30: no change in float32)
    c = b.vmath("MULTIPLY_ADD", i["Product"], (1e-30, 1e-30, 1e-30))
    ng.links.new(i["Centre"], c.node.inputs[2])
    to_c = b.vmath("SUBTRACT", c, i["Position"])
    d_c = b.vmath("LENGTH", to_c)
    cos_g = b.node("ShaderNodeClamp")           # acos's domain (EEVEE gives 0 outside it)
    cos_g.inputs["Min"].default_value, cos_g.inputs["Max"].default_value = -1.0, 1.0
    b.link(b.math("DIVIDE", b.vmath("DOT_PRODUCT", to_c, i["Direction"]), d_c),
           cos_g.inputs["Value"])
    gamma = b.math("ARCCOSINE", cos_g.outputs[0])
    s_o = _clamped(b.math("DIVIDE", i["Radius"], d_c))
    th_o = b.math("ARCSINE", s_o)
    om_o = b.math("MULTIPLY", b.math("TANGENT", b.math("MULTIPLY", th_o, 0.5)), s_o)
    # overlap / Omega_L, 0 for a sphere behind the lamp
    ratio = _map_range(b, om_o, 0.0, i["Lamp Cap"], 0.0,
                       b.math("LESS_THAN", d_c, i["Lamp Distance"]))
    th_l = i["Lamp Angle"]
    a = b.math("ADD", th_l, th_o)
    held = b.math("MULTIPLY_ADD", b.math("MINIMUM", th_l, th_o), -2.0, a)
    blocked = _map_range(b, gamma, a, held, 0.0, ratio, smooth=True)
    blocked = b.math("MAXIMUM", blocked, b.math("LESS_THAN", d_c, i["Radius"]))
    keep = _map_range(b, blocked, 0.0, i["Part"], 1.0, 0.0)
    ng.links.new(b.math("MULTIPLY", i["Product"], keep), gout.inputs["Product"])
    ng.links.new(b.math("MAXIMUM", i["Max"], blocked), gout.inputs["Max"])
    return ng


def reach_bound(bound, mesh=None):
    """(centre, radius): the spheres' ``bound``, grown to hold ``mesh`` = (centre, radius) too
    (the mesh's own bound, which the rays meet) when given."""
    if mesh is None:
        return bound
    gap = float(np.linalg.norm(np.asarray(mesh[0], float) - np.asarray(bound[0], float)))
    return bound[0], max(float(bound[1]), gap + float(mesh[1]))


def make_reach_group(obj, bound, key, fit_hash="", holds_mesh=False):
    """The node group "Relight Reach <object>": inputs Position, Lamp and Lamp Radius (world),
    output Reach, 1 where some sphere inside ``bound`` (the object's frame) can hide a part of
    the lamp, 0 where the spheres' visibility is exactly 1 (sphere_shadow.may_shadow);
    ``holds_mesh``: the bound holds the mesh's too (reach_bound), which Cycles' rays meet.  Its own
    group, so that a material whose lamps need no sphere (Cycles' rays, EEVEE's shadow maps)
    holds none: Cycles reads every node of a material's tree before it drops the unused ones
    (measured: 32 spheres, two lamps, nine materials: +0.09 s a frame)."""
    old = reach_group(key, obj.name)
    if old is not None:
        bpy.data.node_groups.remove(old)
    ng, gin, gout = new_group(f"Relight Reach {obj.name}",
                               [("Position", "NodeSocketVector"), ("Lamp", "NodeSocketVector"),
                                ("Lamp Radius", "NodeSocketFloat")],
                               [("Reach", "NodeSocketFloat")], key)
    ng[REACH_KEY] = obj.name
    ng[FIT_KEY] = fit_hash
    ng[REACH_MESH_KEY] = int(bool(holds_mesh))
    b = Builder(ng)
    tree = ng.nodes
    # Reach, in world space (so that points out of reach never pay the transform below): the
    # bounding sphere, carried by the object's transform and grown to its largest scale, and
    # the lamp's ball, grown by the largest over the mean scale (the spheres see the lamp with
    # a radius over the mean scale): the double cone tangent to both (sphere_shadow.may_shadow,
    # a superset of what the object's frame would test, see world_bound).  All but the last
    # nine nodes are the same at every point (Cycles folds them into constants).
    pos_w = gin.outputs["Position"]
    lamp_w = gin.outputs["Lamp"]
    grow = tree.new("ShaderNodeValue")
    add_driver(grow.outputs[0], "max(a, b, c) / max(d, 1e-9)",
               [(n, "TRANSFORMS", obj, w) for n, w in zip("abcd", ("SCALE_X", "SCALE_Y",
                                                                   "SCALE_Z", "SCALE_AVG"))])
    centre_w = tree.new("ShaderNodeCombineXYZ")
    for i, expr in enumerate(world_point_expressions(bound[0])):
        add_driver(centre_w.inputs[i], expr, frame_vars(obj))
    radius_w = tree.new("ShaderNodeValue")
    radius_w.label = "Bound radius"
    add_driver(radius_w.outputs[0], f"{float(bound[1])!r} * max(a, b, c)",
               [(n, "TRANSFORMS", obj, w) for n, w in zip("abc", ("SCALE_X", "SCALE_Y",
                                                                  "SCALE_Z"))])
    cl = b.vmath("SUBTRACT", centre_w.outputs[0], lamp_w)
    dist = b.vmath("LENGTH", cl)
    axis = b.vmath("NORMALIZE", cl)
    slack = b.math("MULTIPLY", b.math("ADD", dist, radius_w.outputs[0]),
                   2.0 * float(np.sin(0.5 * EPS_ANGLE)))
    r_w = b.math("MULTIPLY_ADD", gin.outputs["Lamp Radius"], grow.outputs[0], slack)
    both = b.math("ADD", radius_w.outputs[0], r_w)
    offset = b.math("DIVIDE", b.math("MULTIPLY", dist, radius_w.outputs[0]), both)
    tan_b = b.math("DIVIDE", both, b.math("SQRT", b.math("MAXIMUM", b.math(
        "SUBTRACT", b.math("MULTIPLY", dist, dist), b.math("MULTIPLY", both, both)), 1e-30)))
    meet = b.math("LESS_THAN", dist, both)
    b.column()
    e = b.vmath("SUBTRACT", pos_w, centre_w.outputs[0])
    along = b.math("ABSOLUTE", b.math("ADD", b.vmath("DOT_PRODUCT", e, axis), offset))
    across = b.vmath("LENGTH", b.vmath("CROSS_PRODUCT", e, axis))
    inside = b.math("LESS_THAN", across, b.math("MULTIPLY", along, tan_b))
    ng.links.new(b.math("MAXIMUM", inside, meet), gout.inputs["Reach"])
    b.column()
    return ng


def reach_group(key, name):
    """The reach group of object ``name``, or None."""
    return next((ng for ng in bpy.data.node_groups
                 if ng.get(REACH_KEY) == name and ng.get(ids.SCENE_KEY) == key), None)


def remove_sphere_group(ng):
    """Remove a sphere group and its object's reach group."""
    reach = reach_group(ng.get(ids.SCENE_KEY), ng.get(OBJECT_KEY))
    bpy.data.node_groups.remove(ng)
    if reach is not None:
        bpy.data.node_groups.remove(reach)


def make_sphere_group(obj, centres, radii, key, fit_hash="", hull=None, mesh=None):
    """The node group returning the part of a lamp seen past ``obj``'s spheres (object frame),
    and beside it the object's reach group (make_reach_group) for a bound holding the spheres
    and ``mesh`` = (centre, radius), the mesh's own bound (the rays meet the mesh, which the
    spheres' bound may not hold: a cube's corners)."""
    ng, gin, gout = new_group(f"Relight Spheres {obj.name}",
                               [("Position", "NodeSocketVector"), ("Lamp", "NodeSocketVector"),
                                ("Lamp Radius", "NodeSocketFloat")],
                               [("Visibility", "NodeSocketFloat")], key)
    bound = bounding_sphere(centres, radii)
    ng[OBJECT_KEY] = obj.name
    ng[FIT_KEY] = fit_hash
    # kept when no material holds it (Cycles' rays and EEVEE's shadow maps): the settling
    # after a drag and the next Update read its spheres
    ng.use_fake_user = True
    ng[SPHERES_KEY] = np.column_stack([centres, radii]).astype(float).ravel().tolist()
    ng[BOUND_KEY] = [*map(float, bound[0]), float(bound[1])]
    if hull is not None:
        ng[HULL_KEY] = [*map(float, hull[0]), float(hull[1])]
    make_reach_group(obj, reach_bound(bound, mesh), key, fit_hash, mesh is not None)
    b = Builder(ng)
    tree = ng.nodes
    local = local_frame(b, obj)
    inv_avg = tree.new("ShaderNodeValue")
    add_driver(inv_avg.outputs[0], "1 / max(v, 1e-9)", [("v", "TRANSFORMS", obj, "SCALE_AVG")])
    # the lamp's cap seen from the point, in the object's frame (sphere_shadow.lamp_cap)
    p = local(gin.outputs["Position"])
    to_l = b.vmath("SUBTRACT", local(gin.outputs["Lamp"]), p)
    d_l = b.vmath("LENGTH", to_l)
    direction = b.vmath("NORMALIZE", to_l)
    r_l = b.math("MULTIPLY", gin.outputs["Lamp Radius"], inv_avg.outputs[0])
    th_l = b.math("MAXIMUM", b.math("ARCSINE", _clamped(b.math("DIVIDE", r_l, d_l))),
                  0.5 * EPS_ANGLE)
    half = b.math("SINE", b.math("MULTIPLY", th_l, 0.5))
    om_l = b.math("MULTIPLY", b.math("MULTIPLY", half, half), 2.0)
    # One "Relight Sphere Cap" node per sphere, chained through the running product and
    # maximum: Cycles' SVM compiler generates every node whose inputs are ready, so spheres
    # that only depended on the shading point would all be evaluated at once and overflow its
    # stack (measured: black materials beyond 16-24 spheres); each cap waits for the previous.
    # The chain starts from a 1 that depends on the lamp: identical nodes are merged by
    # Cycles, and a first sphere shared by two lamps' groups would be evaluated outside both
    # lamps' branches (see _wire_material).
    cap = cap_group(key)
    one = b.math("GREATER_THAN", d_l, -1.0)

    def cap_node(centre, radius, product, maximum, part):
        g = b.node("ShaderNodeGroup")
        g.node_tree = cap
        for name, sock in (("Position", p), ("Direction", direction), ("Lamp Distance", d_l),
                           ("Lamp Angle", th_l), ("Lamp Cap", om_l)):
            ng.links.new(sock, g.inputs[name])
        g.inputs["Centre"].default_value = [float(x) for x in centre]
        g.inputs["Radius"].default_value = float(radius)
        for name, value in (("Product", product), ("Max", maximum), ("Part", part)):
            if isinstance(value, float):
                g.inputs[name].default_value = value
            else:
                ng.links.new(value, g.inputs[name])
        return g

    if hull is not None:        # the part of the lamp the silhouette can hide
        part = b.math("MAXIMUM", cap_node(hull[0], hull[1], one, 0.0, 1.0).outputs["Max"], 1e-6)
    else:
        part = 1.0
    product, maximum = one, 0.0
    for c, r in zip(centres, radii):
        g = cap_node(c, r, product, maximum, part)
        product, maximum = g.outputs["Product"], g.outputs["Max"]
    if isinstance(maximum, float):
        acc = b.math("ADD", 1.0, 0.0)
    else:                       # V = 1 - max(S (1 - product), max)
        lost = b.math("SUBTRACT", 1.0, product)
        if not isinstance(part, float):
            lost = b.math("MULTIPLY", part, lost)
        acc = b.math("SUBTRACT", 1.0, b.math("MAXIMUM", lost, maximum))
    ng.links.new(acc, gout.inputs["Visibility"])
    return ng


def group_bound(ng):
    """(centre, radius) of the bounding sphere a sphere group tests its Reach with."""
    a = ids.array(ng[BOUND_KEY])
    return a[:3], float(a[3])


def group_spheres(ng):
    """(centres (m, 3), radii (m,), hull (centre, radius) or None) stored on a sphere group, in
    its object's frame."""
    a = ids.array(ng.get(SPHERES_KEY, [])).reshape(-1, 4)
    h = ng.get(HULL_KEY)
    hull = None if h is None else (np.asarray(h[:3], float), float(h[3]))
    return a[:, :3], a[:, 3], hull


def sphere_groups(key):
    """{object name: its sphere group} of the scene with ``key``."""
    return {ng[OBJECT_KEY]: ng for ng in bpy.data.node_groups
            if OBJECT_KEY in ng and ng.get(ids.SCENE_KEY) == key}


# -- settled shadows ---------------------------------------------------------------------------

def _transform_values(obj):
    """The world transform channels as TRANSFORMS driver variables read them."""
    loc, rot, scale = obj.matrix_world.decompose()
    return [*loc, rot.w, rot.x, rot.y, rot.z, *map(abs, scale)]     # drivers read lengths


def settled_run(objs) -> str:
    """A key of the objects' present transforms (what a settled shadow was traced at)."""
    return hashlib.sha1(repr([(o.name, [round(v, 6) for v in _transform_values(o)])
                              for o in objs]).encode()).hexdigest()


def settled_group(key):
    """The scene's "Relight Settled" group, or None."""
    return next((ng for ng in bpy.data.node_groups
                 if SETTLED_FITS in ng and ng.get(ids.SCENE_KEY) == key), None)


def _settled_images(key):
    return [im for im in bpy.data.images if SETTLED_KEY in im and ids.ours(im, key)]


def drop_settled(key):
    for im in _settled_images(key):
        bpy.data.images.remove(im)
    ng = settled_group(key)
    if ng is not None:
        bpy.data.node_groups.remove(ng)


def make_settled_group(objs, fits, key):
    """A group whose output is 1 while every object of ``objs`` keeps its present transform."""
    ng, _, gout = new_group(SETTLED_GROUP, [], [("Settled", "NodeSocketFloat")], key)
    ng[SETTLED_FITS] = dict(fits)
    ng["relight_settled_run"] = settled_run(objs)
    ng.use_fake_user = True
    # one driven value per object (a driver expression holds at most 256 characters), their
    # minimum the output
    out = None
    for obj in objs:
        flag = ng.nodes.new("ShaderNodeValue")
        variables, terms = [], []
        for name, what, value in zip("abcdefghij", TRANSFORM_CHANNELS, _transform_values(obj)):
            variables.append((name, "TRANSFORMS", obj, what))
            terms.append(f"abs({name}{-float(value):+.9g})")
        add_driver(flag.outputs[0], f"({'+'.join(terms)})<{SETTLE_TOLERANCE!r}", variables)
        if out is None:
            out = flag.outputs[0]
        else:
            both = ng.nodes.new("ShaderNodeMath")
            both.operation = "MINIMUM"
            ng.links.new(out, both.inputs[0])
            ng.links.new(flag.outputs[0], both.inputs[1])
            out = both.outputs[0]
    ng.links.new(out, gout.inputs["Settled"])
    return ng


def settle(scene, result, objs, fits, depsgraph, key, seed=0):
    """Ray-trace the shadows of ``objs`` (at their present transforms) on every texel of
    ``result`` (a texel-mode ShadowFreeResult of ``scene``'s last run) and write the settled
    images and group; returns the group."""
    drop_settled(key)
    tris = []
    for obj in objs:
        t = object_triangles(obj, depsgraph)
        M = np.array(obj.matrix_world)
        tris.append(t @ M[:3, :3].T + M[:3, 3])
    sc = result.scene if result.scene is not None else result.solution.scene
    tm = result.texel_map
    V = object_visibility(sc, tm, np.concatenate(tris), seed=seed)
    names = list(sc.lamp_names)
    per_image = visibility_images(tm, V)
    writer = MapWriter(key)
    try:
        for i, v in enumerate(per_image):
            if i not in result.maps or float(v.min(initial=1.0)) >= 0.999:
                continue                   # nothing of this image is shadowed
            src = sc.images[i].name
            for g in range(0, len(names), 4):
                chans = names[g:g + 4]
                block = np.ones(v.shape[:2] + (4,), np.float32)
                block[..., :len(chans)] = v[..., g:g + len(chans)]
                img = writer.write(f"{src}{SETTLED_SUFFIX}.{g // 4}", block[..., :3],
                                   block[..., 3])
                img[SETTLED_KEY] = list(chans) + [""] * (4 - len(chans))
                img["relight_settled_source"] = src
                img.use_fake_user = True
    finally:
        writer.close()
    return make_settled_group(objs, fits, key)


# -- materials ---------------------------------------------------------------------------------

def _lamp_terms(mat):
    """(lamp name, its map node, its shadow factor node) of a relit material."""
    nodes = mat.node_tree.nodes
    out = []
    for node in nodes:
        if node.name.startswith(SHADOW_PREFIX):
            lname = node.name[len(SHADOW_PREFIX):]
            m = nodes.get(MAP_PREFIX + lname)
            if m is not None:
                out.append((lname, m, node))
    return out


def _settled_channel(settled_images, m_node, lname):
    """(image, channel 0-3) holding lamp ``lname``'s settled V for the material whose map node
    for that lamp is ``m_node``, or None."""
    image = m_node.image
    if image is None:
        return None
    src = image.get(MAP_SOURCE)
    if src is None:                        # maps written before they were tagged
        tail = f".relight.{lname}"
        if not image.name.endswith(tail):
            return None
        src = image.name[:-len(tail)]
    for im in settled_images:
        if im.get("relight_settled_source") == src and lname in list(im[SETTLED_KEY]):
            return im, list(im[SETTLED_KEY]).index(lname)
    return None


def direct_max(image) -> float:
    """The largest direct part (alpha) of a map image, kept on the image with the content hash
    it was read for (MapWriter tags each image with one)."""
    if image is None:
        return 1.0
    digest = image.get(CONTENT, "")
    kept = image.get(DIRECT_KEY)
    if kept is not None and digest and kept.get("content") == digest:
        return float(kept["max"])
    px = np.empty(len(image.pixels), np.float32)
    image.pixels.foreach_get(px)
    top = float(px[3::4].max(initial=0.0)) if image.channels == 4 else 1.0
    if digest:
        image[DIRECT_KEY] = {"content": digest, "max": top}
    return top


def shadowed_terms(mat, lamp_group_of, cull=True):
    """The lamp terms of ``mat`` a moving object can darken: (lamp name, map node, shadow node)
    of the lamps with a group (where the spheres see them from) whose map has a direct part
    somewhere (above DIRECT_FLOOR).  Elsewhere the factor 1 - a (1 - V) is 1 within the floor,
    wherever the object goes: a lamp behind a wall, a ceiling above downward lamps.  Without
    ``cull``: every lamp with a group."""
    return [(lname, m, s) for lname, m, s in _lamp_terms(mat)
            if lname in lamp_group_of and (not cull or direct_max(m.image) > DIRECT_FLOOR)]


def _surface_socket(tree):
    out = next((n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial"
                and n.is_active_output and not n.name.startswith(NODE_PREFIX)), None)
    return None if out is None else out.inputs["Surface"]


def _unwire(mat):
    """Take this module's nodes out of ``mat``: the shadow factors back to 1, the material's
    own closure back on its output."""
    tree = mat.node_tree
    surface = _surface_socket(tree)
    own = tree.nodes.get(mat.get(SURFACE_KEY, ""))
    for node in [n for n in tree.nodes if n.name.startswith(NODE_PREFIX)]:
        tree.nodes.remove(node)
    if mat.get(RAYS_KEY):                # its own output serves every engine again
        for node in tree.nodes:
            if node.bl_idname == "ShaderNodeOutputMaterial" and node.target == "EEVEE":
                node.target = "ALL"
        del mat[RAYS_KEY]
    for _, _, s_node in _lamp_terms(mat):
        for link in list(s_node.inputs["Scale"].links):
            tree.links.remove(link)
        s_node.inputs["Scale"].default_value = 1.0
    if surface is not None and own is not None and not surface.is_linked:
        tree.links.new(own.outputs[0], surface)


def _wire_material(mat, lamp_group_of, sphere_groups, settled=None, cull=True, rays=(),
                   probes=None):
    """(Re)wire ``mat``'s shadow factors; nothing is touched when the wiring would be the same
    (a rebuilt tree makes every engine compile the material's shader again).  ``settled``:
    (settled group, settled images) or None.  ``cull`` False: every lamp term evaluates the
    spheres at every shading point (the reach branch and the DIRECT_FLOOR test left out; what
    the culled wiring is measured and tested against).

    Each lamp k that a moving object can darken (shadowed_terms) gets its own closure,
    Mix Shader(Reach_k, Emission(T x plain_k), Emission(T x term_k x (1 - a_k (1 - V_k)))), the
    other lamps one Emission of their sum, all added; Reach_k = 1 where some object's bounding
    sphere can hide a part of lamp k (sphere_shadow.may_shadow) and the map has a direct part
    (a_k > 0); where it is 0 the factor 1 - a_k (1 - V_k) is exactly 1.  Cycles' SVM jumps over the branch a Mix Shader's 0 / 1 factor leaves out, with
    the nodes only that branch uses, so a shading point out of every object's reach pays the
    reach tests and not the spheres (EEVEE evaluates both branches).  Settled: the plain branch
    holds the settled shadow and the reach is 0 while the objects stand where it was traced (a
    constant factor: Cycles keeps only that branch).

    ``probes`` ({lamp name: slot}, eevee_shadow.py): those lamps' V comes from EEVEE's shadow
    maps of the probe lights in the material's own output, which then serves EEVEE only.
    ``rays`` (ray_shadow's groups): likewise, a second output then serves Cycles:
    one Emission of T x (sum of the lamp terms, each shadowed term's factor taking V from the
    rays towards a point of the lamp, or the settled V while the objects stand where it was
    traced).  With probes and no rays that second output takes V from the spheres."""
    tree = mat.node_tree
    flag_group, settled_images = settled if settled is not None else (None, [])
    terms = shadowed_terms(mat, lamp_group_of, cull) if sphere_groups else []
    rays = list(rays) if sphere_groups else []
    probes = {n: s for n, s in (probes or {}).items() if n in {t[0] for t in terms}}
    signature = repr((WIRING_VERSION, cull, sorted((g.name, g.get(FIT_KEY, "")) for g in sphere_groups),
                      sorted((g.name, g.get(FIT_KEY, "")) for g in rays), sorted(probes.items()),
                      sorted(t[0] for t in terms),
                      None if flag_group is None else
                      (flag_group.get("relight_settled_run"),
                       sorted(im.name for im in settled_images))))
    if mat.get(WIRING_KEY) == signature and all(
            getattr(n, "node_tree" if n.bl_idname == "ShaderNodeGroup" else "image") is not None
            for n in tree.nodes if n.name.startswith(NODE_PREFIX)
            and n.bl_idname in ("ShaderNodeGroup", "ShaderNodeTexImage")):
        return 1 if terms else 0
    _unwire(mat)
    mat[WIRING_KEY] = signature
    surface = _surface_socket(tree)
    t_node = tree.nodes.get(T_NODE)
    if not terms or surface is None or not surface.is_linked or t_node is None:
        return 0
    own = surface.links[0].from_node
    mat[SURFACE_KEY] = own.name
    strength = own.inputs["Strength"].default_value if "Strength" in own.inputs else 1.0
    count = 0

    def node(kind, label, loc, **props):
        nonlocal count
        n = tree.nodes.new(kind)
        count += 1
        n.name = n.label = f"{NODE_PREFIX} {label} {count}"
        n.location = loc
        for k, v in props.items():
            setattr(n, k, v)
        return n

    def math(op, a, b, label, loc):
        n = node("ShaderNodeMath", label, loc, operation=op)
        for sock, v in zip(n.inputs, (a, b)):
            if isinstance(v, float):
                sock.default_value = v
            else:
                tree.links.new(v, sock)
        return n.outputs[0]

    def emission(colour, label, loc):
        """Emission of T x colour."""
        mul = node("ShaderNodeVectorMath", f"{label} colour", loc, operation="MULTIPLY")
        tree.links.new(t_node.outputs["Color"], mul.inputs[0])
        tree.links.new(colour, mul.inputs[1])
        emit = node("ShaderNodeEmission", label, (loc[0] + 160, loc[1]))
        emit.inputs["Strength"].default_value = strength
        tree.links.new(mul.outputs[0], emit.inputs["Color"])
        return emit.outputs[0]

    x0 = min(t[2].location.x for t in _lamp_terms(mat)) - 900
    x1 = own.location.x
    geo = node("ShaderNodeNewGeometry", "Position", (x0, 200))
    flag = still = None
    if flag_group is not None:           # 1 while the objects stand where it was traced
        flag = node("ShaderNodeGroup", "Settled", (x0, 400))
        flag.node_tree = flag_group
        flag = flag.outputs["Settled"]
        still = math("SUBTRACT", 1.0, flag, "Moving", (x0 + 200, 400))
    closures = []
    wired = {t[0] for t in terms}
    ray_terms = []             # (lamp node, term, alpha, reach, plain term, spheres' V)
    probe_vis = {}                       # slot: V of its probes
    for lname, m_node, s_node in terms:
        y = s_node.location.y - 60
        lamp = node("ShaderNodeGroup", f"Lamp {lname}", (x0, y))
        lamp.node_tree = lamp_group_of[lname]
        vis = reach = None
        # the spheres only where an engine evaluates them: no sphere in the tree when EEVEE
        # takes this lamp's V from its shadow maps and Cycles from rays (make_reach_group)
        spheres = lname not in probes or not rays

        def group(tree_of, label, k):
            g = node("ShaderNodeGroup", f"{label} {tree_of.get(OBJECT_KEY) or tree_of.get(REACH_KEY)}",
                     (x0 + 200, y - 120 * k))
            g.node_tree = tree_of
            tree.links.new(geo.outputs["Position"], g.inputs["Position"])
            tree.links.new(lamp.outputs["Position"], g.inputs["Lamp"])
            tree.links.new(lamp.outputs["Radius"], g.inputs["Lamp Radius"])
            return g

        for i, sg in enumerate(sphere_groups):
            r_out = group(reach_group(sg.get(ids.SCENE_KEY), sg[OBJECT_KEY]), "Reach",
                          2 * i + 1).outputs["Reach"]
            reach = r_out if reach is None else math("MAXIMUM", reach, r_out, "Reach",
                                                     (x0 + 400, y - 120 * i - 60))
            if spheres:
                v_out = group(sg, "Spheres", 2 * i).outputs["Visibility"]
                vis = v_out if vis is None else math("MULTIPLY", vis, v_out, "Product",
                                                     (x0 + 400, y - 120 * i))
        sphere_vis = vis
        if lname in probes:              # EEVEE's shadow maps (the spheres serve Cycles)
            slot = probes[lname]
            if slot not in probe_vis:
                probe_vis[slot] = eevee_shadow.visibility(node, math, tree, slot,
                                                          (x0 - 1400, 900 + 300 * slot))
            vis = probe_vis[slot]
        alpha = m_node.outputs["Alpha"]
        # where the map has no direct part (a = 0: the lamp's real shadow, faces turned away)
        # the factor below is exactly 1: those points are out of reach too
        reach = math("MULTIPLY", reach, math("GREATER_THAN", alpha, 0.0, "Direct",
                                              (x0 + 400, y + 60)), "Reach direct", (x0 + 480, y + 60))
        # 1 - a (1 - V): only the direct part (the map's alpha) is shadowed
        lost = math("MULTIPLY", alpha, math("SUBTRACT", 1.0, vis, "Lost", (x0 + 560, y)),
                    "Direct part", (x0 + 700, y))
        tree.links.new(math("SUBTRACT", 1.0, lost, "Factor", (x0 + 840, y)),
                       s_node.inputs["Scale"])
        term = s_node.inputs[0].links[0].from_socket
        plain = term
        exact = None
        if flag is not None:             # fac: in reach and moving; plain: the settled shadow
            reach = math("MULTIPLY", reach, still, "Reach moving", (x0 + 560, y + 60))
            found = _settled_channel(settled_images, m_node, lname)
            if found is not None:
                im, channel = found
                tex = node("ShaderNodeTexImage", "Settled V", (x0 + 200, y + 300),
                           image=im, interpolation=m_node.interpolation,
                           extension=m_node.extension)
                if m_node.inputs["Vector"].is_linked:
                    tree.links.new(m_node.inputs["Vector"].links[0].from_socket,
                                   tex.inputs["Vector"])
                if channel == 3:
                    exact = tex.outputs["Alpha"]
                else:
                    sep = node("ShaderNodeSeparateColor", "Settled channels", (x0 + 320, y + 300))
                    tree.links.new(tex.outputs["Color"], sep.inputs[0])
                    exact = sep.outputs[channel]
                lost_e = math("MULTIPLY", math("SUBTRACT", 1.0, exact, "Settled lost",
                                                (x0 + 420, y + 180)),
                              flag, "Settled lost now", (x0 + 560, y + 180))
                lost_e = math("MULTIPLY", alpha, lost_e, "Settled direct part", (x0 + 700, y + 180))
                f_e = math("SUBTRACT", 1.0, lost_e, "Settled factor", (x0 + 840, y + 180))
                scaled = node("ShaderNodeVectorMath", "Settled term", (x0 + 980, y + 180),
                              operation="SCALE")
                tree.links.new(term, scaled.inputs[0])
                tree.links.new(f_e, scaled.inputs["Scale"])
                plain = scaled.outputs[0]
        shadowed = emission(s_node.outputs[0], f"Shadowed {lname}", (x1, y - 60))
        if not cull:                     # reach taken as 1: the spheres everywhere
            reach = still
        ray_terms.append((lamp, term, alpha, reach, plain, sphere_vis))
        if reach is None:
            closures.append(shadowed)
            continue
        mix = node("ShaderNodeMixShader", f"Branch {lname}", (x1 + 400, y))
        tree.links.new(reach, mix.inputs["Fac"])
        tree.links.new(emission(plain, f"Plain {lname}", (x1, y + 60)), mix.inputs[1])
        tree.links.new(shadowed, mix.inputs[2])
        closures.append(mix.outputs[0])
    rest = [s for lname, _, s in _lamp_terms(mat) if lname not in wired]
    if rest:                             # the lamps no moving object darkens: one emission
        total = rest[0].outputs[0]
        for k, s_node in enumerate(rest[1:]):
            add = node("ShaderNodeVectorMath", "Unshadowed sum", (x1 - 200, 400 + 60 * k),
                       operation="ADD")
            tree.links.new(total, add.inputs[0])
            tree.links.new(s_node.outputs[0], add.inputs[1])
            total = add.outputs[0]
        closures.insert(0, emission(total, "Unshadowed", (x1, 500)))
    out = closures[0]
    for k, c in enumerate(closures[1:]):
        add = node("ShaderNodeAddShader", "Lamps", (x1 + 600, -120 * k))
        tree.links.new(out, add.inputs[0])
        tree.links.new(c, add.inputs[1])
        out = add.outputs[0]
    tree.links.new(out, surface)
    if rays or probes:
        _wire_cycles(mat, node, math, emission, geo, ray_terms, rest, rays, surface.node,
                     (x0, x1))
    return 1


def _wire_cycles(mat, node, math, emission, geo, ray_terms, rest, rays, own_out, xs):
    """The Cycles output of a material wired by _wire_material (see there): each shadowed lamp
    term on the same reach branch as the spheres' (the reach tests are computed once, both
    outputs use them: Cycles compiles only the nodes its output needs), with V from the rays,
    or without rays from the spheres."""
    tree = mat.node_tree
    x0, x1 = xs
    own_out.target = "EEVEE"
    mat[RAYS_KEY] = 1
    target = ray_shadow.target_group(mat.get(ids.SCENE_KEY)) if rays else None
    closures = []
    for idx, (lamp, term, alpha, reach, plain, sphere_vis) in enumerate(ray_terms):
        y = lamp.location.y - 400
        vis = None if rays else sphere_vis
        if rays:
            tgt = node("ShaderNodeGroup", "Ray target", (x0 + 200, y))
            tgt.node_tree = target
            tree.links.new(geo.outputs["Position"], tgt.inputs["Position"])
            tree.links.new(lamp.outputs["Position"], tgt.inputs["Lamp"])
            tree.links.new(lamp.outputs["Radius"], tgt.inputs["Lamp Radius"])
            tgt.inputs["Seed"].default_value = float(idx + 1)
        for j, rg in enumerate(rays):
            g = node("ShaderNodeGroup", f"Ray {rg[ray_shadow.RAY_OBJECT_KEY]}",
                     (x0 + 400, y - 120 * j))
            g.node_tree = rg
            tree.links.new(geo.outputs["Position"], g.inputs["Position"])
            tree.links.new(tgt.outputs["Target"], g.inputs["Target"])
            vis = g.outputs["Visibility"] if vis is None else \
                math("MULTIPLY", vis, g.outputs["Visibility"], "Ray product",
                     (x0 + 600, y - 120 * j))
        lost = math("MULTIPLY", alpha, math("SUBTRACT", 1.0, vis, "Ray lost", (x0 + 700, y)),
                    "Ray direct part", (x0 + 840, y))
        scaled = node("ShaderNodeVectorMath", "Ray term", (x0 + 1120, y), operation="SCALE")
        tree.links.new(term, scaled.inputs[0])
        tree.links.new(math("SUBTRACT", 1.0, lost, "Ray factor", (x0 + 980, y)),
                       scaled.inputs["Scale"])
        shadowed = emission(scaled.outputs[0], "Ray shadowed", (x1, y - 400))
        if reach is None:
            closures.append(shadowed)
            continue
        mix = node("ShaderNodeMixShader", "Ray branch", (x1 + 400, y - 400))
        tree.links.new(reach, mix.inputs["Fac"])
        tree.links.new(emission(plain, "Ray plain", (x1, y - 340)), mix.inputs[1])
        tree.links.new(shadowed, mix.inputs[2])
        closures.append(mix.outputs[0])
    if rest:
        total = rest[0].outputs[0]
        for s_node in rest[1:]:
            total = _vadd(node, tree, total, s_node.outputs[0], s_node.location.y)
        closures.insert(0, emission(total, "Ray unshadowed", (x1, -900)))
    out = closures[0]
    for k, c in enumerate(closures[1:]):
        add = node("ShaderNodeAddShader", "Ray lamps", (x1 + 600, -900 - 120 * k))
        tree.links.new(out, add.inputs[0])
        tree.links.new(c, add.inputs[1])
        out = add.outputs[0]
    c_out = node("ShaderNodeOutputMaterial", "Cycles output", (x1 + 900, -900), target="CYCLES")
    c_out.name = CYCLES_OUTPUT
    tree.links.new(out, c_out.inputs["Surface"])


def _vadd(node, tree, a, b, y):
    add = node("ShaderNodeVectorMath", "Ray sum", (0, y), operation="ADD")
    tree.links.new(a, add.inputs[0])
    tree.links.new(b, add.inputs[1])
    return add.outputs[0]


def _use_rays(scene, rays):
    """Whether Cycles takes the moving shadows from rays (ray_shadow.py; the line tables where
    this Blender has no Raycast node): the scene's setting ("Cycles Moving Shadows") unless
    ``rays`` says."""
    if rays is None:
        rays = getattr(getattr(scene, "relight", None), "cycles_shadows", "RAYS") == "RAYS"
    return bool(rays)


def _use_maps(scene, maps):
    """Whether EEVEE takes the moving shadows from its shadow maps (eevee_shadow.py): the
    scene's setting ("EEVEE Moving Shadows") unless ``maps`` says."""
    if maps is None:
        maps = getattr(getattr(scene, "relight", None), "eevee_shadows", "MAPS") == "MAPS"
    return bool(maps) and eevee_shadow.available()


def _material_users(scene):
    users = {}
    for obj in scene.objects:
        for slot in getattr(obj, "material_slots", ()):
            if slot.material is not None:
                users.setdefault(slot.material.name, set()).add(obj.name)
    return users


def _probe_slots(scene, key, mats, lamps, objs, cull):
    """{material name: {lamp name: probe slot}}: the lamps whose V EEVEE takes from the probes
    (eevee_shadow.py) in each relit material all of whose objects the probes may light; the
    lamps shadowed in the most such materials get the slots."""
    recv = eevee_shadow.receivers(scene, key)
    names = {o.name for o in recv}
    users = _material_users(scene)
    eligible = [m for m in mats if users.get(m.name) and users[m.name] <= names]
    count = {}
    for m in eligible:
        for lname, _, _ in shadowed_terms(m, lamps, cull):
            count[lname] = count.get(lname, 0) + 1
    order = sorted(count, key=lambda n: (-count[n], n))
    slots = eevee_shadow.sync(scene, key, lamps, order, recv, objs)
    return {m.name: slots for m in eligible} if slots else {}


def sync(scene, depsgraph=None, seed=0, result=None, settle_shadows=True, cull=True,
         rays=None, maps=None) -> dict:
    """Bring the moving objects' sphere shadows of ``scene``'s relit materials up to date: fit
    (again) the objects whose mesh or sphere count changed, drop the groups of objects that are
    no longer moving, settle their shadows where they stand (with ``result``, the scene's last
    ShadowFreeResult; without it the settled shadows are kept while the objects' meshes are the
    same), and wire every relit material (``cull``: see _wire_material; ``rays``: Cycles' shadows
    from rays, see _use_rays; ``maps``: EEVEE's from its shadow maps, see _use_maps).  Returns
    a summary."""
    key = scene_key(scene)
    if key is None:
        return {"objects": 0, "fitted": 0, "materials": 0}
    depsgraph = depsgraph or bpy.context.evaluated_depsgraph_get()
    groups = sphere_groups(key)
    use_rays = _use_rays(scene, rays)
    old_rays, rays_wanted = ray_shadow.ray_groups(key), []
    wanted, fitted = [], 0
    for obj in moving_objects(scene):
        n = sphere_count(obj)
        tris = object_triangles(obj, depsgraph)
        if len(tris) == 0:
            continue
        h = _fit_hash(tris, n)
        if use_rays:
            rg = old_rays.pop(obj.name, None)
            if rg is None or rg.get(FIT_KEY) != h or not ray_shadow.current_kind(rg):
                if rg is not None:
                    ray_shadow.remove_group(rg)
                rg = ray_shadow.make_ray_group(obj, tris, key)
                rg[FIT_KEY] = h
            rays_wanted.append(rg)
        # the reach holds the mesh's bound where Cycles' rays meet the mesh; the spheres' alone
        # (a smaller reach: fewer points pay the spheres) where Cycles shows the spheres
        mesh = ray_shadow.mesh_bound(tris) if use_rays else None
        old = groups.pop(obj.name, None)
        if old is not None and old.get(FIT_KEY) == h:
            reach = reach_group(key, obj.name)
            if reach is None or bool(reach.get(REACH_MESH_KEY)) != use_rays:
                make_reach_group(obj, reach_bound(group_bound(old), mesh), key, h, use_rays)
            wanted.append(old)
            continue
        if old is not None:
            remove_sphere_group(old)
        centres, radii = fit_spheres(tris, n, seed)
        wanted.append(make_sphere_group(obj, centres, radii, key, h, silhouette_sphere(tris),
                                        mesh))
        fitted += 1
    for stale in groups.values():
        remove_sphere_group(stale)
    for stale in old_rays.values():
        ray_shadow.remove_group(stale)
    objs = [bpy.data.objects[g[OBJECT_KEY]] for g in wanted]
    fits = {g[OBJECT_KEY]: g[FIT_KEY] for g in wanted}
    flag_group, settled_s = settled_group(key), 0.0
    if not wanted or not settle_shadows:
        drop_settled(key)
        flag_group = None
    elif (flag_group is not None and dict(flag_group[SETTLED_FITS]) == fits
          and flag_group.get("relight_settled_run") == settled_run(objs)):
        pass                               # nothing moved or changed since the last trace
    elif result is not None and getattr(result, "texel_map", None) is not None:
        import time
        t0 = time.perf_counter()
        flag_group = settle(scene, result, objs, fits, depsgraph, key, seed)
        settled_s = time.perf_counter() - t0
    elif flag_group is not None and dict(flag_group[SETTLED_FITS]) != fits:
        drop_settled(key)                  # meshes changed and no result to trace them again
        flag_group = None
    settled = None if flag_group is None else (flag_group, _settled_images(key))
    lamps = lamp_groups(key)
    mats = [m for m in bpy.data.materials if ids.ours(m, key) and m.node_tree is not None]
    probe_of = _probe_slots(scene, key, mats, lamps, objs, cull) \
        if wanted and _use_maps(scene, maps) else {}
    if not probe_of:
        eevee_shadow.remove(key)
    wired = sum(_wire_material(m, lamps, wanted, settled, cull, rays_wanted,
                               probe_of.get(m.name)) for m in mats)
    probed = set().union(*[set(v) for v in probe_of.values()]) if probe_of else set()
    spheres = sum(len(group_spheres(g)[1]) for g in wanted)
    # spheres evaluated per shading point: in EEVEE for the lamps without probes, in Cycles
    # for every lamp unless it casts rays
    eevee_tests = (len(lamps) - len(probed)) * spheres
    cycles_tests = 0 if rays_wanted else len(lamps) * spheres
    tests = max(eevee_tests, cycles_tests)
    warnings = []
    left = sorted({t[0] for m in mats for t in shadowed_terms(m, lamps, cull)} - probed)
    if probe_of and left:
        warnings.append(f"EEVEE: the moving objects' shadows of {', '.join(left)} come from "
                        f"spheres (its shadow maps serve {eevee_shadow.SLOTS} lamps)")
    if tests > EEVEE_SPHERE_TESTS:
        costs = []
        if eevee_tests > EEVEE_SPHERE_TESTS:
            costs.append(f"EEVEE may take minutes to compile that many or fail (measured on 2 "
                         f"cores: {EEVEE_SPHERE_TESTS} took about 2 minutes, 512 failed)")
        if cycles_tests > EEVEE_SPHERE_TESTS:
            costs.append("every Cycles frame takes longer to prepare and to shade with the "
                         "count (2 lamps x 128 spheres: some 7 s before the first sample)")
        warnings.append(f"Moving objects: {tests} sphere tests in every relit material "
                        f"({tests // max(spheres, 1)} lamps x {spheres} spheres); "
                        + "; ".join(costs) + ": lower the objects' Spheres")
    return {"objects": len(wanted), "fitted": fitted, "materials": wired,
            "settled": flag_group is not None, "settle_seconds": settled_s,
            "rays": bool(rays_wanted), "probes": sorted(probed),
            "warnings": warnings}
