"""One builder for every node graph Relight makes (relit materials, lamp, sphere and settled
groups): nodes placed in columns as they are made, so no module spells layout offsets."""
from __future__ import annotations

import bpy
import numpy as np

from . import ids
from .drivers import add_driver

COLUMN = 220         # x step between the builder's columns
ROW = 180            # y step between the rows of a column


class Builder:
    """Adds nodes to ``tree``: ``node(kind)`` in the current column (top to bottom), ``column()``
    starts the next one; ``math`` / ``vmath`` / ``smoothstep`` make and link maths nodes."""

    def __init__(self, tree, x=0.0, y=0.0):
        self.tree, self.x0, self.y0 = tree, float(x), float(y)
        self.col, self.row = 0, 0

    def at(self, col=None, row=None):
        """Move the cursor to column ``col`` and row ``row`` (None: keep)."""
        if col is not None:
            self.col = col
        if row is not None:
            self.row = row
        return self

    def column(self, step=1):
        self.col += step
        self.row = 0
        return self

    def location(self):
        return (self.x0 + COLUMN * self.col, self.y0 - ROW * self.row)

    def node(self, kind, name=None, label=None, **props):
        n = self.tree.nodes.new(kind)
        n.location = self.location()
        self.row += 1
        if name is not None:
            n.name = name
            n.label = name if label is None else label
        elif label is not None:
            n.label = label
        for key, value in props.items():
            setattr(n, key, value)
        return n

    def link(self, out, inp):
        return self.tree.links.new(out, inp)

    def _inputs(self, n, values):
        for i, v in enumerate(values):
            if v is None:
                continue
            if isinstance(v, (int, float)):
                n.inputs[i].default_value = float(v)
            elif isinstance(v, (tuple, list, np.ndarray)):
                n.inputs[i].default_value = [float(c) for c in v]
            else:
                self.link(v, n.inputs[i])

    def math(self, op, a, b=None, c=None):
        n = self.node("ShaderNodeMath", operation=op)
        self._inputs(n, (a, b, c))
        return n.outputs[0]

    def vmath(self, op, a, b=None, scale=None, c=None):
        n = self.node("ShaderNodeVectorMath", operation=op)
        self._inputs(n, (a, b, c))
        if scale is not None:
            if isinstance(scale, (int, float)):
                n.inputs["Scale"].default_value = float(scale)
            else:
                self.link(scale, n.inputs["Scale"])
        return n.outputs["Value"] if op in ("LENGTH", "DOT_PRODUCT") else n.outputs["Vector"]

    def smoothstep(self, x):
        n = self.node("ShaderNodeMapRange", data_type="FLOAT", interpolation_type="SMOOTHSTEP",
                      clamp=True)
        for name, value in (("From Min", 0.0), ("From Max", 1.0), ("To Min", 0.0),
                            ("To Max", 1.0)):
            n.inputs[name].default_value = value
        self.link(x, n.inputs["Value"])
        return n.outputs["Result"]

    def one_minus_cos(self, s):
        """1 - cos(asin s) without its cancellation for small caps (as sphere_shadow.blocked_part's
        s tan(asin(s) / 2))."""
        sq = self.math("MULTIPLY", s, s)
        root = self.math("SQRT", self.math("SUBTRACT", 1.0, sq))
        return self.math("DIVIDE", sq, self.math("ADD", 1.0, root))


def new_group(name, inputs, outputs, key, tree_type="ShaderNodeTree"):
    """A node group (shader, or ``tree_type``: "CompositorNodeTree") tagged for the scene with
    ``key``: (group, its input node, its output node); ``inputs`` / ``outputs``: (socket name,
    socket type) pairs."""
    ng = bpy.data.node_groups.new(name, tree_type)
    for sock_name, kind in inputs:
        ng.interface.new_socket(sock_name, in_out="INPUT", socket_type=kind)
    for sock_name, kind in outputs:
        ng.interface.new_socket(sock_name, in_out="OUTPUT", socket_type=kind)
    gin = ng.nodes.new("NodeGroupInput")
    gout = ng.nodes.new("NodeGroupOutput")
    ids.tag(ng, key)
    return ng, gin, gout


def local_frame(b, obj):
    """A function making, with Builder ``b``, the nodes that bring a world point into ``obj``'s
    own frame: R^T (v - loc) / scale (``point=False``: a vector, R^T v / scale), the world
    transform driven (location, the quaternion's conjugate, 1 / scale)."""
    tree = b.tree.nodes
    loc = tree.new("ShaderNodeCombineXYZ")
    for i, w in enumerate(("LOC_X", "LOC_Y", "LOC_Z")):
        add_driver(loc.inputs[i], "v", [("v", "TRANSFORMS", obj, w)])
    u = tree.new("ShaderNodeCombineXYZ")
    for i, w in enumerate(("ROT_X", "ROT_Y", "ROT_Z")):
        add_driver(u.inputs[i], "-v", [("v", "TRANSFORMS", obj, w)])
    w = tree.new("ShaderNodeValue")
    add_driver(w.outputs[0], "v", [("v", "TRANSFORMS", obj, "ROT_W")])
    inv = tree.new("ShaderNodeCombineXYZ")
    for i, s in enumerate(("SCALE_X", "SCALE_Y", "SCALE_Z")):
        add_driver(inv.inputs[i], "1 / max(v, 1e-9)", [("v", "TRANSFORMS", obj, s)])

    def local(v, point=True):   # the quaternion's conjugate rotates back (a vector: no move)
        d = b.vmath("SUBTRACT", v, loc.outputs[0]) if point else v
        t = b.vmath("SCALE", b.vmath("CROSS_PRODUCT", u.outputs[0], d), scale=2.0)
        r = b.vmath("ADD", b.vmath("ADD", d, b.vmath("SCALE", t, scale=w.outputs[0])),
                    b.vmath("CROSS_PRODUCT", u.outputs[0], t))
        return b.vmath("MULTIPLY", r, inv.outputs[0])
    return local
