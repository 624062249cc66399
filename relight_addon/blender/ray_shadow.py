"""Moving virtual objects' shadows in Cycles by ray casting (Blender 5.1+'s Raycast node; before
it, the object's line table: line_nodes.py, the same group's interface).

The sphere groups (sphere_nodes.py) give EEVEE and Cycles the same approximate shadow.  Where
Blender has the Raycast node, the relit materials get a second output, for Cycles only, whose
factor ``1 - a_k (1 - V_k)`` takes V_k from a ray: from the shading point towards a point of
lamp k drawn at random on its disk (the disk the sphere code sees: radius from the lamp group,
facing the point), V = 0 when the ray meets the object.  So Cycles shows the object's real mesh's
shadow (any shape, no sphere fit; deformed as rendered, within the bounding sphere measured at
Update), soft as the samples add up, at the cost of one short ray per lamp and object; EEVEE
keeps the spheres (its Raycast node works in screen space and cannot see towards a lamp).

* The ray is cast only along the chord of the object's bounding sphere (driven by its transform,
  as the sphere groups' reach is): what the ray meets there is the object, so the room's own
  surfaces, whose shadows are already in the maps, are not counted again (a room surface inside
  the bounding sphere, the table top under the object, is, where it hides the lamp anyway).
* The random lamp point comes from a White Noise of the shading position and the lamp's index:
  Cycles jitters each sample's position within its pixel, so successive samples draw different
  points and the penumbra converges as samples add up.

Before 5.1 the group has the same inputs and output and reads the object's line table instead of
casting the ray (line_nodes.py): the mesh as it was at Update, carried by its transform, and
nothing but the object is met.

Nothing runs in Python at render time; the drivers are simple expressions as the spheres' are.
"""
from __future__ import annotations

import bpy
import numpy as np

from . import ids
from .drivers import add_driver, frame_vars, world_point_expressions
from .nodes import Builder, new_group

RAY_OBJECT_KEY = "relight_ray_object"   # on a ray group: the object's name
RAY_BOUND_KEY = "relight_ray_bound"     # on a ray group: x, y, z, radius (object frame)
KIND_KEY = "relight_ray_kind"           # on a ray group: "raycast" or "lines" (its Blender's)
TARGET_KEY = "relight_ray_target"       # on the shared lamp-point group: its version
TARGET_VERSION = 1
TARGET_GROUP = "Relight Ray Lamp Point"
# the ray starts this fraction of the bounding radius past the shading point (and stops as far
# before the lamp): the point's own surface is not met again
START = 1e-3
MARGIN = 1.02                           # the bounding sphere, grown: float round-off at its rim


def available() -> bool:
    """Whether this Blender has the Raycast shader node (5.1+)."""
    return hasattr(bpy.types, "ShaderNodeRaycast")


def current_kind(ng) -> bool:
    """Whether ray group ``ng`` is the kind this Blender makes (a file saved by another Blender
    line: the Raycast node where there is none, or a line table where there is one)."""
    return ng.get(KIND_KEY) == ("raycast" if available() else "lines")


def mesh_bound(tris):
    """(centre, radius) in the object's frame enclosing every vertex of ``tris`` (t, 3, 3): the
    box's centre and the farthest vertex from it, grown by MARGIN."""
    pts = np.asarray(tris, float).reshape(-1, 3)
    centre = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
    radius = float(np.sqrt(((pts - centre) ** 2).sum(axis=1).max())) * MARGIN
    return centre, max(radius, 1e-6)


def ray_groups(key):
    """{object name: its ray group} of the scene with ``key``."""
    return {ng[RAY_OBJECT_KEY]: ng for ng in bpy.data.node_groups
            if RAY_OBJECT_KEY in ng and ng.get(ids.SCENE_KEY) == key}


def make_ray_group(obj, tris, key):
    """The group of ``obj``: inputs Position and Target (world), output Visibility, 0 where the
    segment from Position to Target meets the object inside its bounding sphere, else 1.  Where
    Blender has no Raycast node, the same group reads the object's line table (line_nodes.py)."""
    centre, radius = mesh_bound(tris)
    if not available():
        from . import line_nodes
        ng = line_nodes.make_line_group(obj, tris, key, centre, radius)
        ng[RAY_OBJECT_KEY] = obj.name
        ng[RAY_BOUND_KEY] = [*map(float, centre), radius]
        ng[KIND_KEY] = "lines"
        return ng
    ng, gin, gout = new_group(f"Relight Ray {obj.name}",
                               [("Position", "NodeSocketVector"), ("Target", "NodeSocketVector")],
                               [("Visibility", "NodeSocketFloat")], key)
    ng[RAY_OBJECT_KEY] = obj.name
    ng[RAY_BOUND_KEY] = [*map(float, centre), radius]
    ng[KIND_KEY] = "raycast"
    b = Builder(ng)
    c_w = b.node("ShaderNodeCombineXYZ", label="Bound centre")
    for i, expr in enumerate(world_point_expressions(centre)):
        add_driver(c_w.inputs[i], expr, frame_vars(obj))
    r_w = b.node("ShaderNodeValue", label="Bound radius")
    add_driver(r_w.outputs[0], f"{radius!r} * max(a, b, c)",
               [(n, "TRANSFORMS", obj, w) for n, w in zip("abc", ("SCALE_X", "SCALE_Y",
                                                                  "SCALE_Z"))])
    b.column()
    p = gin.outputs["Position"]
    d = b.vmath("SUBTRACT", gin.outputs["Target"], p)
    length = b.vmath("LENGTH", d)
    u = b.vmath("NORMALIZE", d)
    # the centre from the point, made to depend on the target (by a term far below float32's
    # reach): Cycles merges identical nodes, and one the lamps' groups shared would be
    # evaluated outside their branches, at every point
    q = b.vmath("SUBTRACT", c_w.outputs[0],
                b.vmath("MULTIPLY_ADD", gin.outputs["Target"], (1e-30,) * 3, c=p))
    b.column()
    tc = b.vmath("DOT_PRODUCT", q, u)                     # the centre's foot on the ray
    h2 = b.math("MULTIPLY_ADD", tc, b.math("MULTIPLY", tc, -1.0), b.vmath("DOT_PRODUCT", q, q))
    r = r_w.outputs[0]
    half = b.math("SQRT", b.math("MAXIMUM", b.math("MULTIPLY_ADD", r, r,
                                                     b.math("MULTIPLY", h2, -1.0)), 0.0))
    eps = b.math("MULTIPLY", r, START)
    b.column()
    t0 = b.math("MAXIMUM", b.math("SUBTRACT", tc, half), eps)
    t1 = b.math("MINIMUM", b.math("ADD", tc, half), b.math("SUBTRACT", length, eps))
    span = b.math("SUBTRACT", t1, t0)
    b.column()
    ray = b.node("ShaderNodeRaycast")
    b.link(b.vmath("ADD", p, b.vmath("SCALE", u, scale=t0)), ray.inputs["Position"])
    b.link(u, ray.inputs["Direction"])
    b.link(b.math("MAXIMUM", span, 0.0), ray.inputs["Length"])
    b.column()
    met = b.math("MULTIPLY", ray.outputs["Is Hit"], b.math("GREATER_THAN", span, 0.0))
    ng.links.new(b.math("SUBTRACT", 1.0, met), gout.inputs["Visibility"])
    return ng


def remove_group(ng):
    """Remove a ray group and what it alone uses (a line table's images)."""
    from . import line_nodes
    name, key = ng.get(RAY_OBJECT_KEY), ng.get(ids.SCENE_KEY)
    bpy.data.node_groups.remove(ng)
    if name is not None:
        line_nodes.remove_images(name, key)


def target_group(key):
    """The shared group drawing a point of a lamp's disk: inputs Position, Lamp (centre), Lamp
    Radius, Seed (the lamp's index); output Target.  The disk faces the shading point; its
    points are uniform (radius sqrt of a uniform draw, angle uniform round the axis)."""
    for ng in bpy.data.node_groups:
        if ng.get(TARGET_KEY) == TARGET_VERSION and ng.get(ids.SCENE_KEY) == key:
            return ng
    vec, flt = "NodeSocketVector", "NodeSocketFloat"
    ng, gin, gout = new_group(TARGET_GROUP, [("Position", vec), ("Lamp", vec),
                                             ("Lamp Radius", flt), ("Seed", flt)],
                              [("Target", vec)], key)
    ng[TARGET_KEY] = TARGET_VERSION
    ng.use_fake_user = True
    b = Builder(ng)
    i = gin.outputs
    noise = b.node("ShaderNodeTexWhiteNoise", noise_dimensions="4D")
    b.link(i["Position"], noise.inputs["Vector"])
    b.link(i["Seed"], noise.inputs["W"])
    sep = b.node("ShaderNodeSeparateColor")
    b.link(noise.outputs["Color"], sep.inputs[0])
    r1, r2, r3 = sep.outputs[0], sep.outputs[1], sep.outputs[2]
    b.column()
    # a uniform direction g (z = 2 r1 - 1, azimuth 2 pi r2), made perpendicular to the axis:
    # its azimuth round the axis is uniform
    z = b.math("MULTIPLY_ADD", r1, 2.0, -1.0)
    s = b.math("SQRT", b.math("MAXIMUM", b.math("MULTIPLY_ADD", z, b.math("MULTIPLY", z, -1.0),
                                                 1.0), 0.0))
    phi = b.math("MULTIPLY", r2, 2.0 * np.pi)
    g = b.node("ShaderNodeCombineXYZ")
    b.link(b.math("MULTIPLY", s, b.math("COSINE", phi)), g.inputs[0])
    b.link(b.math("MULTIPLY", s, b.math("SINE", phi)), g.inputs[1])
    b.link(z, g.inputs[2])
    b.column()
    axis = b.vmath("NORMALIZE", b.vmath("SUBTRACT", i["Lamp"], i["Position"]))
    along = b.vmath("SCALE", axis, scale=b.vmath("DOT_PRODUCT", g.outputs[0], axis))
    e = b.vmath("NORMALIZE", b.vmath("SUBTRACT", g.outputs[0], along))
    b.column()
    rho = b.math("MULTIPLY", i["Lamp Radius"], b.math("SQRT", r3))
    ng.links.new(b.vmath("ADD", i["Lamp"], b.vmath("SCALE", e, scale=rho)),
                 gout.inputs["Target"])
    return ng
