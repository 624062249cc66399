"""Moving virtual objects' shadows in Cycles from a table of lines (Blenders without the
Raycast node, before 5.1).

The same group as ray_shadow.make_ray_group (inputs Position and Target in world space, output
Visibility), which the relit materials' Cycles output wires the same way; V comes from the
object's line table (core/relight/line_shadow.py, of which this group is the twin: the same
operations in the same order) instead of a ray.  The table is two packed half-float images,
``"<object>.relight.lines"`` (per texel: meets the object, the middle and half the length
of where it does) and ``"<object>.relight.lines.basis"`` (per tile: its two offset axes in
texels, read at the tile's texel, 'Closest'), written at Update.  Both points are brought into the
object's frame by its driven transform, so a drag or an animation moves the shadow with no
Update; deforming the mesh needs one (the table is traced again).
"""
from __future__ import annotations

import bpy

from ..core.relight import line_shadow
from . import ids
from .images import MapWriter
from .nodes import Builder, local_frame, new_group

LINES_KEY = "relight_lines"            # on a table image: its group's object
TABLE_SUFFIX = ".relight.lines"
BASIS_SUFFIX = ".relight.lines.basis"


def table_images(key):
    return [im for im in bpy.data.images if LINES_KEY in im and ids.ours(im, key)]


def remove_images(obj_name, key):
    for im in table_images(key):
        if im[LINES_KEY] == obj_name:
            bpy.data.images.remove(im)


def make_line_group(obj, tris, key, centre, radius, occluder=None, start=1e-3):
    """The group of ``obj`` (see the module docstring) and its two images, for the object's
    triangles ``tris`` (t, 3, 3, its own frame) inside the bounding sphere (``centre``,
    ``radius``).  Every node depends on the target (a lamp's point): Cycles merges identical
    nodes, and one that two lamps' groups shared (the shading point brought into the object's
    frame) would be evaluated outside both lamps' branches, at every point."""
    nd, no = line_shadow.N_DIR, line_shadow.N_OFF
    table = line_shadow.build_table(tris, centre, radius, occluder, nd, no)
    remove_images(obj.name, key)
    with MapWriter(key) as writer:
        # Blender stores rows bottom first and so does the table: texel (x, y) is read at
        # ((x + 0.5) / W, (y + 0.5) / H)
        img = writer.write(f"{obj.name}{TABLE_SUFFIX}", table)
        bas = writer.write(f"{obj.name}{BASIS_SUFFIX}",
                           line_shadow.basis_image(radius, nd, no))
    for im in (img, bas):
        im[LINES_KEY] = obj.name
    ng, gin, gout = new_group(f"Relight Lines {obj.name}",
                               [("Position", "NodeSocketVector"), ("Target", "NodeSocketVector")],
                               [("Visibility", "NodeSocketFloat")], key)
    b = Builder(ng)
    local = local_frame(b, obj)
    r = float(radius)
    target, position = gin.outputs["Target"], gin.outputs["Position"]
    # the point, made to depend on the target by a term far below float32's reach (a sun's
    # target is 1e5 m away: the point from it would keep few digits)
    p = local(b.vmath("MULTIPLY_ADD", target, (1e-30,) * 3, c=position))
    dv = local(b.vmath("SUBTRACT", target, position), point=False)
    length = b.vmath("LENGTH", dv)
    u = b.vmath("NORMALIZE", dv)
    b.column()
    # the tile of the line's direction (line_shadow.tile_coords)
    flip = b.math("MULTIPLY_ADD", b.math("LESS_THAN", b.vmath("DOT_PRODUCT", u, (0.0, 0.0, 1.0)),
                                         0.0), -2.0, 1.0)
    l1 = b.vmath("DOT_PRODUCT", b.vmath("ABSOLUTE", u), (1.0, 1.0, 1.0))
    v = b.vmath("SCALE", u, scale=b.math("DIVIDE", flip, b.math("MAXIMUM", l1, 1e-30)))
    ab = b.node("ShaderNodeCombineXYZ")
    b.link(b.vmath("DOT_PRODUCT", v, (1.0, 1.0, 0.0)), ab.inputs[0])
    b.link(b.vmath("DOT_PRODUCT", v, (1.0, -1.0, 0.0)), ab.inputs[1])
    b.column()
    tile = b.vmath("MINIMUM", b.vmath("MAXIMUM", b.vmath("FLOOR", b.vmath(
        "MULTIPLY_ADD", ab.outputs[0], (0.5 * nd,) * 3, c=(0.5 * nd,) * 3)), (0.0,) * 3),
        (nd - 1.0,) * 3)
    at1 = b.vmath("MULTIPLY_ADD", tile, (0.5 / nd, 1.0 / nd, 0.0),
                  c=(0.25 / nd, 0.5 / nd, 0.0))
    at2 = b.vmath("ADD", at1, (0.5, 0.0, 0.0))

    def look(at, image, interpolation):
        n = b.node("ShaderNodeTexImage", interpolation=interpolation, extension="EXTEND")
        n.image = image
        b.link(at, n.inputs["Vector"])
        return n.outputs["Color"]

    e1, e2 = look(at1, bas, "Closest"), look(at2, bas, "Closest")
    b.column()
    # the centre's foot on the ray, and the ray's offsets in the tile (texels from its middle)
    w = b.vmath("SUBTRACT", tuple(float(x) for x in centre), p)
    tc = b.vmath("DOT_PRODUCT", w, u)
    o = b.vmath("SUBTRACT", b.vmath("SCALE", u, scale=tc), w)
    st = b.node("ShaderNodeCombineXYZ")
    b.link(b.vmath("DOT_PRODUCT", o, e1), st.inputs[0])
    b.link(b.vmath("DOT_PRODUCT", o, e2), st.inputs[1])
    st = st.outputs[0]
    inside = b.math("LESS_THAN", b.vmath("DOT_PRODUCT", st, st), (0.5 * no) ** 2)
    b.column()
    inner = b.vmath("MINIMUM", b.vmath("MAXIMUM", b.vmath("ADD", st, (0.5 * no,) * 3),
                                       (0.5,) * 3), (no - 0.5,) * 3)
    at = b.vmath("SCALE", b.vmath("MULTIPLY_ADD", tile, (float(no),) * 3, c=inner),
                 scale=1.0 / (nd * no))
    sep = b.node("ShaderNodeSeparateColor")
    b.link(look(at, img, "Linear"), sep.inputs[0])
    hit, mid, half = sep.outputs[0], sep.outputs[1], sep.outputs[2]
    b.column()
    x = b.math("MULTIPLY_ADD", flip, mid, b.math("DIVIDE", tc, r))
    ahead = b.math("GREATER_THAN", b.math("ADD", x, half), start)
    before = b.math("LESS_THAN", b.math("SUBTRACT", x, half),
                    b.math("SUBTRACT", b.math("DIVIDE", length, r), start))
    b.column()
    met = b.math("MULTIPLY", b.math("MULTIPLY", b.math("GREATER_THAN", hit, 0.5), ahead),
                 b.math("MULTIPLY", before, inside))
    ng.links.new(b.math("SUBTRACT", 1.0, met), gout.inputs["Visibility"])
    return ng
