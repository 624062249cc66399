# SPDX-License-Identifier: GPL-3.0-or-later
"""The AR composite's node maths, evaluated with no Python (drivers with simple expressions,
packed images): the receivers' shader and the compositor's differential composite
(core/ar/composite.py is the twin).

Shader side (``"Relight AR Camera"``): where a world point (or direction) falls in the photo,
the camera model of core/ar/view.py with the camera's location, rotation, lens, sensor, shift
and the render's resolution read by drivers: the receivers show the photo to the rays that are
not the camera's (reflections in the objects, light bounced onto them).

Compositor side, per pixel once a frame (cost independent of the samples):

* ``"Relight AR Table UV"``: the coordinates of a direction in one band of the tables image
  (core/ar/envmap.py's latitude-node lookup ``sample_nodes``), for a Map UV node;
* ``"Relight AR Cap Cosine"``: the exact clamped-cosine integral of a cap (core/ar/cap.py);
* ``"Relight AR Residual Cap"``: one sphere's hidden part of the residual irradiance, chained
  through a running product and maximum (env_shadow.residual_visibility); the lights' spheres
  are the lamps' own ``"Relight Sphere Cap"`` group (sphere_nodes.py, the compositor's copy)
  with the light as a disk SUN_DISTANCE away;
* ``"Relight AR Shadow <object>"`` (one per virtual object): its spheres and silhouette in
  world space, driven from the object's transform (a drag or an animation moves them, nothing
  recompiles), and the visible parts of the residual and of each light;
* ``"Relight AR Composite"``: the photo, the render and its passes (the receivers' coverage,
  position and normal: AOVs) -> the composite.

Images: ``"Relight AR tables"``, one float image of latitude-node bands of 33 x 64 (band 0 the
irradiance table E(n), bands 1.. the residual's cap-filtered tables), rows bottom first; the
receiver view (core/ar/receiver_view.py) as ``"Relight AR view sun / open / cone"``, aligned
with the photo.
"""
from __future__ import annotations

import bpy
import numpy as np

from ..core.ar.cap_filter import CAP_ANGLES
from ..core.ar.composite import COVERAGE_FLOOR, DARK_FLOOR, SEEN_MIN_ANGLE
from ..core.relight.sphere_shadow import SUN_DISTANCE
from . import ids
from .drivers import add_driver
from .nodes import Builder, new_group
from .sphere_nodes import cap_group

AR_KEY = "relight_ar"                   # on AR node groups: their kind / version
OBJECT_KEY = "relight_ar_object"        # on an object's shadow group: the object's name
FIT_KEY = "relight_ar_fit"              # on an object's shadow group: its fit's hash
TABLES_IMAGE = "Relight AR tables"
VIEW_IMAGES = ("Relight AR view sun", "Relight AR view open", "Relight AR view cone")
COMPOSITE_GROUP = "Relight AR Composite"
VERSION = 1
TINY = 1e-12            # the twin's guard of a distance or a length
PART_FLOOR = 1e-6       # sphere_shadow.combined_visibility's floor of the silhouette's part
S2_MAX = 1.0 - 1e-6     # cap.py's sin^2 below 1 (float32: 1 - 1e-12 is 1)
COMPOSITOR = "CompositorNodeTree"
# the receivers' passes (view layer AOVs): coverage, position, normal
AOV_COVERAGE, AOV_POSITION, AOV_NORMAL = "relight_ar_cov", "relight_ar_pos", "relight_ar_nor"
# all three colour passes: EEVEE in Blender 5.2 writes zeros to a Value AOV listed before Color
# AOVs (the coverage came out 0 and the composite lost every shadow; a Value AOV after them, or
# a Color one, is written); the coverage is grey (c, c, c)
AOVS = ((AOV_COVERAGE, "COLOR"), (AOV_POSITION, "COLOR"), (AOV_NORMAL, "COLOR"))

VEC, FLT, COL = "NodeSocketVector", "NodeSocketFloat", "NodeSocketColor"


# -- the tables image --------------------------------------------------------------------------

def table_bands(lighting):
    """(k, h, w, 3) float32 latitude-node bands, top row first: the irradiance table, then the
    residual's cap tables (one per cap_filter.CAP_ANGLES)."""
    return np.concatenate([lighting.irradiance[None], lighting.caps]).astype(np.float32)


def tables_pixels(lighting):
    """(k h, w, 3) the bands stacked for the image: band b's rows from the image's bottom row
    b h (the nadir) to b h + h - 1 (the zenith)."""
    return np.ascontiguousarray(np.concatenate([b[::-1] for b in table_bands(lighting)]))


# -- small helpers -----------------------------------------------------------------------------

def _group(name, kind, inputs, outputs, key, tree_type=COMPOSITOR):
    """The shared group of ``kind`` for the scene with ``key`` if made already (then Builder is
    None), else a new one: (group, input node, output node, Builder)."""
    tag = f"{kind}/{VERSION}"
    for ng in bpy.data.node_groups:
        if ng.get(AR_KEY) == tag and ng.get(ids.SCENE_KEY) == key and ng.bl_idname == tree_type:
            return ng, None, None, None
    ng, gin, gout = new_group(name, inputs, outputs, key, tree_type)
    ng[AR_KEY] = tag
    ng.use_fake_user = True
    return ng, gin, gout, Builder(ng)


def world_group(key, inputs, outputs):
    """The World's ground group of the scene with ``key`` (ar_write.ground_group): (group,
    input node, output node, Builder), Builder None when it is made already."""
    return _group("Relight AR Ground", "ground", inputs, outputs, key, "ShaderNodeTree")


def separate(b, v):
    """The x, y, z outputs of a Separate XYZ of ``v``."""
    return _sep(b, v)


def _clamped(sock):
    sock.node.use_clamp = True
    return sock


def _sep(b, v):
    n = b.node("ShaderNodeSeparateXYZ")
    b.link(v, n.inputs[0])
    return n.outputs


def _combine(b, x, y, z):
    n = b.node("ShaderNodeCombineXYZ")
    for i, c in enumerate((x, y, z)):
        if isinstance(c, (int, float)):
            n.inputs[i].default_value = float(c)
        else:
            b.link(c, n.inputs[i])
    return n.outputs[0]


def _select(b, cond, yes, no):
    """cond in {0, 1}: no + cond (yes - no) (floats)."""
    return b.math("MULTIPLY_ADD", cond, b.math("SUBTRACT", yes, no), no)


def _vselect(b, cond, yes, no):
    """cond in {0, 1} (a float): no + cond (yes - no) (vectors)."""
    d = b.vmath("SUBTRACT", yes, no)
    return b.vmath("ADD", b.vmath("SCALE", d, scale=cond), no)


def group_node(b, tree, **inputs):
    """A group node of ``tree`` in the builder's tree, its inputs set or linked (keyword
    names with '_' for ' ')."""
    kind = "CompositorNodeGroup" if b.tree.bl_idname == COMPOSITOR else "ShaderNodeGroup"
    g = b.node(kind)
    g.node_tree = tree
    for name, value in inputs.items():
        name = name.replace("_", " ")
        if isinstance(value, (int, float)):
            g.inputs[name].default_value = float(value)
        elif isinstance(value, (tuple, list, np.ndarray)):
            g.inputs[name].default_value = [float(c) for c in value]
        else:
            b.link(value, g.inputs[name])
    return g


# -- the camera (shader) -----------------------------------------------------------------------

# core/ar/view.py CameraModel.factors as simple expressions (fit: AUTO 0, HORIZONTAL 1, VERTICAL 2)
_HORIZONTAL = "(fit == 1 or (fit == 0 and ax * rx >= ay * ry))"
_F_OVER_W = f"(1 if {_HORIZONTAL} else ay * ry / (ax * rx))"          # F / W
_F_OVER_CH = f"(ax * rx / (ay * ry) if {_HORIZONTAL} else 1)"          # F / (c H)
_K = "f / (sh if fit == 2 else sw)"
CAMERA_FACTORS = (("a_u", f"{_K} * {_F_OVER_W}"), ("a_v", f"{_K} * {_F_OVER_CH}"),
                  ("b_u", f"0.5 - sx * {_F_OVER_W}"), ("b_v", f"0.5 - sy * {_F_OVER_CH}"))


def _camera_vars(scene, cam):
    data, r = cam.data, "render."
    return [("f", "CAMERA", data, "lens"), ("sw", "CAMERA", data, "sensor_width"),
            ("sh", "CAMERA", data, "sensor_height"), ("fit", "CAMERA", data, "sensor_fit"),
            ("sx", "CAMERA", data, "shift_x"), ("sy", "CAMERA", data, "shift_y"),
            ("rx", "SCENE", scene, r + "resolution_x"), ("ry", "SCENE", scene, r + "resolution_y"),
            ("ax", "SCENE", scene, r + "pixel_aspect_x"),
            ("ay", "SCENE", scene, r + "pixel_aspect_y")]


def camera_group(scene, cam, key):
    """``"Relight AR Camera"`` (a shader group): Position (a world point, or a direction with
    Point = 0) -> UV (u, v, 0) in the photo's frame, Front (1 in front of the camera)."""
    ng, gin, gout, b = _group(f"Relight AR Camera {cam.name}", f"camera {cam.name}",
                              [("Position", VEC), ("Point", FLT)], [("UV", VEC), ("Front", FLT)],
                              key, "ShaderNodeTree")
    if b is None:
        return ng
    ng.interface.items_tree["Point"].default_value = 1.0
    tree = ng.nodes
    loc = tree.new("ShaderNodeCombineXYZ")
    for i, w in enumerate(("LOC_X", "LOC_Y", "LOC_Z")):
        add_driver(loc.inputs[i], "v", [("v", "TRANSFORMS", cam, w)])
    u = tree.new("ShaderNodeCombineXYZ")      # the rotation's conjugate: R^T
    for i, w in enumerate(("ROT_X", "ROT_Y", "ROT_Z")):
        add_driver(u.inputs[i], "-v", [("v", "TRANSFORMS", cam, w)])
    w = tree.new("ShaderNodeValue")
    add_driver(w.outputs[0], "v", [("v", "TRANSFORMS", cam, "ROT_W")])
    factors = {}
    for name, expr in CAMERA_FACTORS:
        val = tree.new("ShaderNodeValue")
        val.label = name
        add_driver(val.outputs[0], expr, _camera_vars(scene, cam))
        factors[name] = val.outputs[0]
    # q = R^T (p - Point x location), with the quaternion's conjugate (u, w)
    d = b.vmath("SUBTRACT", gin.outputs["Position"],
                b.vmath("SCALE", loc.outputs[0], scale=gin.outputs["Point"]))
    t = b.vmath("SCALE", b.vmath("CROSS_PRODUCT", u.outputs[0], d), scale=2.0)
    q = b.vmath("ADD", b.vmath("ADD", d, b.vmath("SCALE", t, scale=w.outputs[0])),
                b.vmath("CROSS_PRODUCT", u.outputs[0], t))
    x, y, z = _sep(b, q)[:3]
    depth = b.math("MULTIPLY", z, -1.0)
    front = b.math("GREATER_THAN", depth, 1e-6)
    safe = b.math("MAXIMUM", depth, 1e-6)
    uu = b.math("MULTIPLY_ADD", b.math("DIVIDE", x, safe), factors["a_u"], factors["b_u"])
    vv = b.math("MULTIPLY_ADD", b.math("DIVIDE", y, safe), factors["a_v"], factors["b_v"])
    ng.links.new(_combine(b, uu, vv, 0.0), gout.inputs["UV"])
    ng.links.new(front, gout.inputs["Front"])
    return ng


# -- directions in the tables ------------------------------------------------------------------

def table_uv_group(key, bands, rows):
    """``"Relight AR Table UV"``: Direction (unit), Band -> UV of the latitude-node lookup of
    that band (envmap.sample_nodes: u = 0.5 - atan2(y, x) / 2 pi, row 0.5 + v (h - 1) within
    the band, v = 0.5 + asin(z) / pi); z = 1 (Map UV reads it as the lookup's alpha)."""
    ng, gin, gout, b = _group("Relight AR Table UV", f"table_uv {bands}x{rows}",
                              [("Direction", VEC), ("Band", FLT)], [("UV", VEC)], key)
    if b is None:
        return ng
    x, y, z = _sep(b, gin.outputs["Direction"])[:3]
    u = b.math("MULTIPLY_ADD", b.math("ARCTAN2", y, x), -1.0 / (2 * np.pi), 0.5)
    zc = b.math("MAXIMUM", b.math("MINIMUM", z, 1.0), -1.0)
    v = b.math("MULTIPLY_ADD", b.math("ARCSINE", zc), 1.0 / np.pi, 0.5)
    row = b.math("MULTIPLY_ADD", gin.outputs["Band"], float(rows),
                 b.math("MULTIPLY_ADD", v, float(rows - 1), 0.5))
    ng.links.new(_combine(b, u, b.math("DIVIDE", row, float(bands * rows)), 1.0),
                 gout.inputs["UV"])
    return ng


def table_lookup(b, tree_uv, image, direction, band):
    """The tables ``image`` read (bilinear, wrapping in u) at ``direction`` in ``band`` (a
    number or a socket): a Map UV node's colour output."""
    g = group_node(b, tree_uv, Direction=direction, Band=band)
    img = b.node("CompositorNodeImage", image=image)
    m = b.node("CompositorNodeMapUV")
    b.link(img.outputs["Image"], m.inputs["Image"])
    b.link(g.outputs["UV"], m.inputs["UV"])
    m.inputs["Interpolation"].default_value = "Bilinear"
    m.inputs["Extension X"].default_value = "Repeat"
    m.inputs["Extension Y"].default_value = "Extend"
    return m.outputs["Image"]


# -- the cap's clamped cosine --------------------------------------------------------------------

def cap_cosine_group(key):
    """``"Relight AR Cap Cosine"``: Cos Beta, Sin2 Alpha -> C (cap.cap_cosine_integral)."""
    ng, gin, gout, b = _group("Relight AR Cap Cosine", "cap_cosine",
                              [("Cos Beta", FLT), ("Sin2 Alpha", FLT)], [("C", FLT)], key)
    if b is None:
        return ng
    cb = b.math("MAXIMUM", b.math("MINIMUM", gin.outputs["Cos Beta"], 1.0), -1.0)
    s2 = b.math("MAXIMUM", gin.outputs["Sin2 Alpha"], 0.0)
    inside = b.math("GREATER_THAN", s2, 1.0 - 1e-7)             # s2 >= 1
    s2c = b.math("MINIMUM", s2, S2_MAX)
    cb2 = b.math("MULTIPLY", cb, cb)
    above = b.math("GREATER_THAN", cb2, s2c)
    sb = b.math("SQRT", b.math("MAXIMUM", b.math("SUBTRACT", 1.0, cb2), 0.0))
    x = b.math("SQRT", b.math("SUBTRACT", b.math("DIVIDE", 1.0, b.math("MAXIMUM", s2c, 1e-30)),
                              1.0))
    y = b.math("DIVIDE", b.math("MULTIPLY", x, b.math("MULTIPLY", cb, -1.0)),
               b.math("MAXIMUM", sb, 1e-30))
    y = b.math("MAXIMUM", b.math("MINIMUM", y, 1.0), -1.0)
    sy = b.math("MULTIPLY", sb, b.math("SQRT", b.math("MAXIMUM", b.math(
        "SUBTRACT", 1.0, b.math("MULTIPLY", y, y)), 0.0)))
    straddle = b.math("ADD", b.math("MULTIPLY", b.math(
        "SUBTRACT", b.math("MULTIPLY", cb, b.math("ARCCOSINE", y)), b.math("MULTIPLY", x, sy)),
        s2c), b.math("ARCTAN2", sy, x))
    plain = b.math("MULTIPLY", b.math("MULTIPLY", s2c, b.math("MAXIMUM", cb, 0.0)), np.pi)
    out = _select(b, above, plain, straddle)
    out = _select(b, inside, np.pi, out)
    ng.links.new(b.math("MAXIMUM", b.math("MINIMUM", out, np.pi), 0.0), gout.inputs["C"])
    return ng


def layer_curve(node):
    """Set the Float Curve ``node`` to the layer coordinate of a cap half-angle: a / (pi / 2)
    -> k / (len(CAP_ANGLES) - 1) at the table angles (linear between, flat below the first),
    so that its floor and fraction give cap_filter.sample_cap_filtered's tables and weight."""
    curve = node.mapping.curves[0]
    pts = [(0.0, 0.0)] + [(a / (np.pi / 2), k / (len(CAP_ANGLES) - 1))
                          for k, a in enumerate(CAP_ANGLES)]
    while len(curve.points) < len(pts):
        curve.points.new(0.5, 0.5)
    for p, (x, y) in zip(curve.points, pts):
        p.location = (x, y)
        p.handle_type = "VECTOR"
    node.mapping.use_clip = True
    node.mapping.update()


def residual_cap_group(key, image, bands, rows):
    """``"Relight AR Residual Cap"``: one sphere's hidden part b of the residual irradiance
    (env_shadow.residual_visibility's ``blocked``, then combined_visibility's step):
    Product' = Product (1 - min(b / Part, 1)), Max' = max(Max, b); Blocked = b."""
    ng, gin, gout, b = _group("Relight AR Residual Cap", f"residual_cap {image.name}", [
        ("Position", VEC), ("Normal", VEC), ("Residual", VEC), ("Centre", VEC), ("Radius", FLT),
        ("Part", VEC), ("Product", VEC), ("Max", VEC)],
        [("Product", VEC), ("Max", VEC), ("Blocked", VEC)], key)
    if b is None:
        return ng
    i = gin.outputs
    tree_uv = table_uv_group(key, bands, rows)
    cosine = cap_cosine_group(key)
    n = i["Normal"]
    to_c = b.vmath("SUBTRACT", i["Centre"], i["Position"])
    d = b.math("MAXIMUM", b.vmath("LENGTH", to_c), TINY)
    axis = b.vmath("SCALE", to_c, scale=b.math("DIVIDE", 1.0, d))
    cb = b.vmath("DOT_PRODUCT", axis, n)
    ratio = b.math("DIVIDE", i["Radius"], d)
    s2 = b.math("MULTIPLY", ratio, ratio)
    b.column()
    # visible_cap: the part of the cap above the horizon
    alpha = b.math("ARCSINE", b.math("SQRT", _clamped(b.math("ADD", s2, 0.0))))
    e = b.math("ARCSINE", b.math("MAXIMUM", b.math("MINIMUM", cb, 1.0), -1.0))
    lo = b.math("MAXIMUM", b.math("SUBTRACT", e, alpha), 0.0)
    hi = b.math("ADD", e, alpha)
    straddle = b.math("MULTIPLY", b.math("LESS_THAN", e, alpha), b.math("GREATER_THAN", hi, 0.0))
    t = b.vmath("SUBTRACT", axis, b.vmath("SCALE", n, scale=cb))
    tn = b.vmath("LENGTH", t)
    t = _vselect(b, b.math("GREATER_THAN", tn, TINY),
                 b.vmath("SCALE", t, scale=b.math("DIVIDE", 1.0, b.math("MAXIMUM", tn, 1e-30))),
                 axis)
    e2 = b.math("MULTIPLY", b.math("ADD", lo, hi), 0.5)
    ax2 = b.vmath("ADD", b.vmath("SCALE", t, scale=b.math("COSINE", e2)),
                  b.vmath("SCALE", n, scale=b.math("SINE", e2)))
    ax2 = _vselect(b, straddle, ax2, axis)
    a2 = _select(b, straddle, b.math("MAXIMUM", b.math("MULTIPLY", b.math("SUBTRACT", hi, lo),
                                                        0.5), 0.0), alpha)
    b.column()
    # cosine_centroid of the cap (ax2, a2)
    cb2 = b.vmath("DOT_PRODUCT", ax2, n)
    ca = b.math("COSINE", a2)
    ca3 = b.math("MULTIPLY", b.math("MULTIPLY", ca, ca), ca)
    A = b.math("MULTIPLY", b.math("SUBTRACT", 1.0, ca3), 2 * np.pi / 3)
    B = b.math("MULTIPLY", b.math("ADD", b.math("SUBTRACT", 2.0 / 3.0, ca),
                                  b.math("MULTIPLY", ca3, 1.0 / 3.0)), np.pi)
    along = b.vmath("SCALE", ax2, scale=cb2)
    m = b.vmath("ADD", b.vmath("SCALE", along, scale=A),
                b.vmath("SCALE", b.vmath("SUBTRACT", n, along), scale=B))
    mn = b.vmath("LENGTH", m)
    direction = _vselect(b, b.math("GREATER_THAN", mn, TINY),
                         b.vmath("SCALE", m, scale=b.math("DIVIDE", 1.0,
                                                          b.math("MAXIMUM", mn, 1e-30))), ax2)
    b.column()
    # sample_cap_filtered: linear in the half-angle between the two nearest tables
    curve = b.node("ShaderNodeFloatCurve")
    layer_curve(curve)
    b.link(b.math("MULTIPLY", a2, 2.0 / np.pi), curve.inputs["Value"])
    x = b.math("MULTIPLY", curve.outputs["Value"], float(len(CAP_ANGLES) - 1))
    k = b.math("FLOOR", b.math("MINIMUM", x, len(CAP_ANGLES) - 1 - 1e-4))
    f = b.math("SUBTRACT", x, k)
    band = b.math("ADD", k, 1.0)                   # band 0 is the irradiance table
    l0 = table_lookup(b, tree_uv, image, direction, band)
    l1 = table_lookup(b, tree_uv, image, direction, b.math("ADD", band, 1.0))
    rad = b.vmath("ADD", l0, b.vmath("SCALE", b.vmath("SUBTRACT", l1, l0), scale=f))
    b.column()
    cg = group_node(b, cosine, Cos_Beta=cb, Sin2_Alpha=s2)
    blocked = b.vmath("DIVIDE", b.vmath("SCALE", rad, scale=cg.outputs["C"]), i["Residual"])
    blocked = b.vmath("MINIMUM", blocked, (1.0,) * 3)
    inside = b.math("GREATER_THAN", s2, 1.0 - 1e-7)
    blocked = b.vmath("MAXIMUM", blocked, _combine(b, inside, inside, inside))
    share = b.vmath("MINIMUM", b.vmath("DIVIDE", blocked, i["Part"]), (1.0,) * 3)
    product = b.vmath("MULTIPLY", i["Product"], b.vmath("SUBTRACT", (1.0,) * 3, share))
    ng.links.new(product, gout.inputs["Product"])
    ng.links.new(b.vmath("MAXIMUM", i["Max"], blocked), gout.inputs["Max"])
    ng.links.new(blocked, gout.inputs["Blocked"])
    return ng


# -- one object's shadow -----------------------------------------------------------------------

def _transform_vars(obj):
    names = (("X", "LOC_X"), ("Y", "LOC_Y"), ("Z", "LOC_Z"), ("w", "ROT_W"), ("x", "ROT_X"),
             ("y", "ROT_Y"), ("z", "ROT_Z"), ("u", "SCALE_X"), ("v", "SCALE_Y"),
             ("t", "SCALE_Z"))
    return [(n, "TRANSFORMS", obj, w) for n, w in names]


def world_point_expressions(c):
    """Three simple expressions of the world position of the object-frame point ``c``:
    location + R(q) (scale * c) (the TRANSFORMS variables of :func:`_transform_vars`)."""
    cx, cy, cz = (float(v) for v in c)
    return (f"X+u*{cx!r}*(1-2*(y*y+z*z))+v*{cy!r}*2*(x*y-w*z)+t*{cz!r}*2*(x*z+w*y)",
            f"Y+u*{cx!r}*2*(x*y+w*z)+v*{cy!r}*(1-2*(x*x+z*z))+t*{cz!r}*2*(y*z-w*x)",
            f"Z+u*{cx!r}*2*(x*z-w*y)+v*{cy!r}*2*(y*z+w*x)+t*{cz!r}*(1-2*(x*x+y*y))")


def _driven_point(tree, obj, c, label):
    node = tree.new("ShaderNodeCombineXYZ")
    node.label = label
    variables = _transform_vars(obj)
    for i, expr in enumerate(world_point_expressions(c)):
        add_driver(node.inputs[i], expr, variables)
    return node.outputs[0]


def _driven_radius(tree, obj, r, label):
    node = tree.new("ShaderNodeValue")
    node.label = label
    add_driver(node.outputs[0], f"s*{float(r)!r}", [("s", "TRANSFORMS", obj, "SCALE_AVG")])
    return node.outputs[0]


def light_constants(light):
    """(direction (3,), angle, cap) of a light as the lamps' formula sees a disk SUN_DISTANCE
    away of radius SUN_DISTANCE tan(half-angle) (sphere_shadow.sun_disk): theta_L and
    Omega_L / 2 pi."""
    s = float(min(np.tan(min(light.half_angle, np.pi / 2 - 1e-6)), 1.0))
    return (np.asarray(light.direction, float), float(np.arcsin(s)),
            max(s * s / (1.0 + np.sqrt(max(1.0 - s * s, 0.0))), 1e-30))


def shadow_group(obj, spheres, hull, lights, key, image, bands, rows, fit_hash=""):
    """``"Relight AR Shadow <object>"`` (compositor): Position, Normal, Residual (the residual
    irradiance) -> Residual (its visible part past the object's spheres within its
    silhouette) and Light j per light (``lights``: (direction, angle, cap) of
    :func:`light_constants`).  ``spheres`` (centres (m, 3), radii (m,)) and ``hull``
    ((centre, radius)) are in the object's frame, moved by drivers."""
    outputs = [("Residual", VEC), ("Seen", FLT)] + [(f"Light {j}", FLT)
                                                    for j in range(len(lights))]
    ng, gin, gout = new_group(f"Relight AR Shadow {obj.name}",
                              [("Position", VEC), ("Normal", VEC), ("Residual", VEC),
                               ("Cone", VEC), ("Cone Cos", FLT)], outputs, key, COMPOSITOR)
    ng[AR_KEY] = f"shadow/{VERSION}"
    ng[OBJECT_KEY] = obj.name
    ng[FIT_KEY] = fit_hash
    ng["relight_ar_spheres"] = np.column_stack(spheres).astype(float).ravel().tolist()
    ng["relight_ar_hull"] = [*map(float, hull[0]), float(hull[1])]
    ng.use_fake_user = True
    tree = ng.nodes
    b = Builder(ng)
    i = gin.outputs
    p, n, e_res = i["Position"], i["Normal"], i["Residual"]
    centres, radii = spheres
    world = [(_driven_point(tree, obj, c, f"Sphere {k}"), _driven_radius(tree, obj, r, f"R {k}"))
             for k, (c, r) in enumerate(zip(centres, radii))]
    hull_w = (_driven_point(tree, obj, hull[0], "Hull"),
              _driven_radius(tree, obj, hull[1], "R hull"))
    res_cap = residual_cap_group(key, image, bands, rows)
    lamp_cap = cap_group(key, COMPOSITOR)
    # the residual: every sphere within the silhouette's part
    one, zero = (1.0,) * 3, (0.0,) * 3
    h = group_node(b, res_cap, Position=p, Normal=n, Residual=e_res, Centre=hull_w[0],
                   Radius=hull_w[1], Part=one, Product=one, Max=zero)
    part = b.vmath("MAXIMUM", h.outputs["Blocked"], (PART_FLOOR,) * 3)
    product, maximum = one, zero
    for c, r in world:
        g = group_node(b, res_cap, Position=p, Normal=n, Residual=e_res, Centre=c, Radius=r,
                       Part=part, Product=product, Max=maximum)
        product, maximum = g.outputs["Product"], g.outputs["Max"]
    lost = b.vmath("MULTIPLY", part, b.vmath("SUBTRACT", one, product))
    ng.links.new(b.vmath("SUBTRACT", one, b.vmath("MAXIMUM", lost, maximum)),
                 gout.inputs["Residual"])
    # composite.seen: the silhouette inside the point's visibility cone
    b.column(2)
    v = b.vmath("SUBTRACT", hull_w[0], p)
    dist = b.math("MAXIMUM", b.vmath("LENGTH", v), TINY)
    cos_g = b.math("DIVIDE", b.vmath("DOT_PRODUCT", v, i["Cone"]), dist)
    gamma = b.math("ARCCOSINE", b.math("MAXIMUM", b.math("MINIMUM", cos_g, 1.0), -1.0))
    theta = b.math("ARCCOSINE", b.math("MAXIMUM", b.math("MINIMUM", i["Cone Cos"], 1.0), -1.0))
    alpha = b.math("ARCSINE", _clamped(b.math("DIVIDE", hull_w[1], dist)))
    x = b.math("DIVIDE", b.math("SUBTRACT", gamma, theta),
               b.math("MAXIMUM", alpha, SEEN_MIN_ANGLE))
    ng.links.new(b.math("SUBTRACT", 1.0, b.smoothstep(x)), gout.inputs["Seen"])
    # each light: the lamps' formula within the silhouette's part
    for j, (direction, angle, cap) in enumerate(lights):
        b.column(2)
        u = np.asarray(direction, float)
        lamp = dict(Position=p, Direction=tuple(u / max(float(np.linalg.norm(u)), 1e-300)),
                    Lamp_Distance=SUN_DISTANCE, Lamp_Angle=angle, Lamp_Cap=cap)
        hp = group_node(b, lamp_cap, Centre=hull_w[0], Radius=hull_w[1], Product=1.0, Max=0.0,
                        Part=1.0, **lamp)
        lpart = b.math("MAXIMUM", hp.outputs["Max"], PART_FLOOR)
        lprod, lmax = 1.0, 0.0
        for c, r in world:
            g = group_node(b, lamp_cap, Centre=c, Radius=r, Product=lprod, Max=lmax, Part=lpart,
                           **lamp)
            lprod, lmax = g.outputs["Product"], g.outputs["Max"]
        lost = b.math("MULTIPLY", lpart, b.math("SUBTRACT", 1.0, lprod))
        ng.links.new(b.math("SUBTRACT", 1.0, b.math("MAXIMUM", lost, lmax)),
                     gout.inputs[f"Light {j}"])
    return ng


def shadow_groups(key):
    """{object name: its shadow group} of the scene with ``key``."""
    return {ng[OBJECT_KEY]: ng for ng in bpy.data.node_groups
            if OBJECT_KEY in ng and ng.get(ids.SCENE_KEY) == key}


# -- the composite -----------------------------------------------------------------------------

def _map_node(b, image):
    """The receiver-view map ``image`` at the render's pixels (Scale to the render size)."""
    node = b.node("CompositorNodeImage", image=image)
    scale = b.node("CompositorNodeScale")
    b.link(node.outputs["Image"], scale.inputs["Image"])
    scale.inputs["Type"].default_value = "Render Size"
    scale.inputs["Frame Type"].default_value = "Stretch"
    return scale.outputs["Image"]


def _channel(b, colour, k):
    sep = b.node("CompositorNodeSeparateColor")
    b.link(colour, sep.inputs[0])
    return sep.outputs[k]


def composite_group(key, photo, image, bands, rows, lights, floor, shadows, view):
    """``"Relight AR Composite"`` (compositor): Image, Alpha (the render), Coverage, Position,
    Normal (the receivers' passes, premultiplied by their coverage) -> Image, the composite of
    core/ar/composite.py.  ``lights``: (direction, angle, cap, radiance, sin^2 of the
    half-angle) each; ``floor``: the residual irradiance's floor; ``shadows``: the objects'
    shadow groups; ``view``: the receiver-view images (sun, open, cone) or None."""
    ng, gin, gout = new_group(COMPOSITE_GROUP, [("Image", COL), ("Alpha", FLT),
                                                ("Coverage", FLT), ("Position", VEC),
                                                ("Normal", VEC)], [("Image", COL)], key,
                              COMPOSITOR)
    ng[AR_KEY] = f"composite/{VERSION}"
    ng.use_fake_user = True
    b = Builder(ng)
    i = gin.outputs
    photo_px = _map_node(b, photo)
    cov = i["Coverage"]
    one = (1.0,) * 3
    b.column()
    if shadows:
        inv = b.math("DIVIDE", 1.0, b.math("MAXIMUM", cov, COVERAGE_FLOOR))
        p = b.vmath("SCALE", i["Position"], scale=inv)
        n = b.vmath("NORMALIZE", i["Normal"])
        if view is not None:
            sun_px, open_px, cone_px = (_map_node(b, im) for im in view)
            cone_cos = _channel(b, cone_px, 3)
        else:
            sun_px, open_px, cone_px, cone_cos = None, one, (0.0, 0.0, 1.0), 0.0
        cosine = cap_cosine_group(key)
        tree_uv = table_uv_group(key, bands, rows)
        e_all = table_lookup(b, tree_uv, image, n, 0.0)
        e_lights = []
        for direction, _, _, radiance, sin2 in lights:
            g = group_node(b, cosine, Cos_Beta=b.vmath("DOT_PRODUCT", n, tuple(direction)),
                           Sin2_Alpha=sin2)
            e_lights.append(b.vmath("SCALE", tuple(radiance), scale=g.outputs["C"]))
        b.column()
        e_l = None
        for e in e_lights:
            e_l = e if e_l is None else b.vmath("ADD", e_l, e)
        e_res = e_all if e_l is None else b.vmath("SUBTRACT", e_all, e_l)
        e_res = b.vmath("MAXIMUM", e_res, (float(floor),) * 3)
        e_tot = e_res if e_l is None else b.vmath("ADD", e_res, e_l)
        groups = [group_node(b, g, Position=p, Normal=n, Residual=e_res, Cone=cone_px,
                             Cone_Cos=cone_cos) for g in shadows]
        b.column()
        # the residual: E_res O prod (1 - w (1 - V)) (composite.py)
        kept = None
        for g in groups:
            k = b.vmath("SUBTRACT", one, b.vmath("SCALE", b.vmath(
                "SUBTRACT", one, g.outputs["Residual"]), scale=g.outputs["Seen"]))
            kept = k if kept is None else b.vmath("MULTIPLY", kept, k)
        lit = b.vmath("MULTIPLY", e_res, b.vmath("MULTIPLY", open_px, kept))
        received = b.vmath("MULTIPLY", e_res, open_px)
        for j, e in enumerate(e_lights):
            s_j = _channel(b, sun_px, j) if sun_px is not None else 1.0
            vis = groups[0].outputs[f"Light {j}"]
            for g in groups[1:]:
                vis = b.math("MULTIPLY", vis, g.outputs[f"Light {j}"])
            lit = b.vmath("ADD", lit, b.vmath("SCALE", e, scale=b.math("MULTIPLY", vis, s_j)))
            received = b.vmath("ADD", received, b.vmath("SCALE", e, scale=s_j))
        dark = b.vmath("SCALE", e_tot, scale=DARK_FLOOR)
        factor = b.vmath("DIVIDE", b.vmath("ADD", lit, dark), b.vmath("ADD", received, dark))
        factor = b.vmath("MAXIMUM", b.vmath("MINIMUM", factor, one), (0.0,) * 3)
        # 1 - a - c (1 - F)
        keep = b.vmath("SUBTRACT", b.vmath("SUBTRACT", one, b.vmath("SCALE", one,
                                                                     scale=i["Alpha"])),
                       b.vmath("SCALE", b.vmath("SUBTRACT", one, factor), scale=cov))
    else:
        keep = b.vmath("SCALE", one, scale=b.math("SUBTRACT", 1.0, i["Alpha"]))
    b.column()
    out = b.vmath("ADD", i["Image"], b.vmath("MULTIPLY", photo_px, keep))
    rgba = b.node("CompositorNodeSetAlpha")
    b.link(out, rgba.inputs["Image"])
    rgba.inputs["Alpha"].default_value = 1.0
    ng.links.new(rgba.outputs["Image"], gout.inputs["Image"])
    return ng
