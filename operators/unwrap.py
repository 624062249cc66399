# SPDX-License-Identifier: GPL-3.0-or-later
"""``relight.unwrap_missing``: give every mesh without a UV map an xatlas atlas "RelightUV".

Bad input fix: Precompute needs a UV map on image-textured objects (``read.py`` warns when one
is missing).  For each selected mesh object (every visible one when nothing is selected) that
has no UV map at all, the loop triangles are parametrised by xatlas in world space (so the
object's scale does not distort the texel density) and the atlas is written per loop into a new
UV map.  Only UV data is added: vertices, edges, faces and objects that already have UV maps
are left alone.  Linked (library) and library-override meshes are read-only here and skipped.
"""

import bpy
import numpy as np

from .base import RelightOperator

UV_NAME = "RelightUV"


def _targets(context):
    objs = list(getattr(context, "selected_objects", None) or ())
    if not objs:
        objs = list(getattr(context, "visible_objects", None) or ())
    return [o for o in objs if o.type == 'MESH']


def atlas_loop_uvs(mesh, matrix_world):
    """(n_loops, 2) float32 UVs in [0, 1] for ``mesh`` and the number of polygons whose
    triangles xatlas put in different charts (mapped from their first triangle's chart)."""
    import xatlas

    mesh.calc_loop_triangles()
    nv, nt = len(mesh.vertices), len(mesh.loop_triangles)
    co = np.empty(nv * 3, np.float32)
    mesh.vertices.foreach_get("co", co)
    co = co.reshape(nv, 3).astype(np.float64)
    m = np.array(matrix_world, np.float64)
    world = (co @ m[:3, :3].T + m[:3, 3]).astype(np.float32)
    tri_verts = np.empty(nt * 3, np.int32)
    mesh.loop_triangles.foreach_get("vertices", tri_verts)
    tri_loops = np.empty(nt * 3, np.int32)
    mesh.loop_triangles.foreach_get("loops", tri_loops)
    vmapping, indices, uvs = xatlas.parametrize(world, tri_verts.reshape(nt, 3).astype(np.uint32))
    indices = np.asarray(indices, np.int64).reshape(nt, 3)
    if not np.array_equal(np.asarray(vmapping)[indices].reshape(-1), tri_verts):
        raise RuntimeError("xatlas changed the triangle corner order")
    corner_uv = np.asarray(uvs, np.float32)[indices.reshape(-1)]
    loop_uv = np.zeros((len(mesh.loops), 2), np.float32)
    loop_uv[tri_loops] = corner_uv
    # xatlas charts triangles, Blender stores one UV per polygon corner: a (non-planar) n-gon
    # whose triangles land in different charts would get torn UVs.  Such polygons take the
    # chart of their first triangle, extended affinely (world -> UV) to their other corners.
    tri_poly = np.empty(nt, np.int32)
    mesh.loop_triangles.foreach_get("polygon_index", tri_poly)
    bad = np.zeros(len(mesh.polygons), bool)
    seen = np.zeros(len(mesh.loops), bool)
    first_uv = np.zeros_like(loop_uv)
    for k in range(3):   # compare every corner with the UV the loop got first
        ls, us = tri_loops.reshape(nt, 3)[:, k], corner_uv.reshape(nt, 3, 2)[:, k]
        new = ~seen[ls]
        first_uv[ls[new]] = us[new]
        seen[ls] = True
    diff = np.any(np.abs(first_uv[tri_loops] - corner_uv) > 1e-6, axis=1).reshape(nt, 3).any(axis=1)
    bad[tri_poly[diff]] = True
    if bad.any():
        loop_start = np.empty(len(mesh.polygons), np.int32)
        loop_total = np.empty(len(mesh.polygons), np.int32)
        mesh.polygons.foreach_get("loop_start", loop_start)
        mesh.polygons.foreach_get("loop_total", loop_total)
        loop_vert = np.empty(len(mesh.loops), np.int32)
        mesh.loops.foreach_get("vertex_index", loop_vert)
        polys, first_tri = np.unique(tri_poly, return_index=True)   # tri_poly is sorted
        tv = tri_verts.reshape(nt, 3)
        for pi in np.flatnonzero(bad):
            t = first_tri[np.searchsorted(polys, pi)]
            p = world[tv[t]].astype(np.float64)
            u = corner_uv.reshape(nt, 3, 2)[t].astype(np.float64)
            basis = np.stack([p[1] - p[0], p[2] - p[0]], axis=1)            # 3 x 2
            loops = np.arange(loop_start[pi], loop_start[pi] + loop_total[pi])
            ab = np.linalg.lstsq(basis, (world[loop_vert[loops]] - p[0]).T, rcond=None)[0]
            loop_uv[loops] = (u[0] + ab.T @ np.stack([u[1] - u[0], u[2] - u[0]])).astype(np.float32)
    return np.clip(loop_uv, 0.0, 1.0), int(bad.sum())


class RELIGHT_OT_unwrap_missing(RelightOperator, bpy.types.Operator):
    """Add an automatic UV atlas ("RelightUV", xatlas) to the selected (or, with nothing
    selected, the visible) mesh objects that have no UV map; other objects are left alone"""

    bl_idname = "relight.unwrap_missing"
    bl_label = "Unwrap Missing UVs"
    bl_options = {'REGISTER', 'UNDO'}

    @classmethod
    def disabled_reason(cls, context):
        if not any(len(o.data.uv_layers) == 0 for o in _targets(context)):
            return "Every mesh (selected, or visible when nothing is selected) has a UV map"
        return None

    def execute(self, context):
        try:
            import xatlas  # noqa: F401
        except ImportError:
            self.report({'ERROR'}, "xatlas is not available: check the Relight dependencies")
            return {'CANCELLED'}
        done, skipped, seen = [], [], set()
        for obj in _targets(context):
            me = obj.data
            if me.name_full in seen or len(me.uv_layers) > 0:
                continue
            seen.add(me.name_full)
            if obj.library is not None or me.library is not None or me.override_library is not None:
                skipped.append(f"'{obj.name}' (linked mesh)")
                continue
            if obj.mode == 'EDIT' or me.is_editmode:
                skipped.append(f"'{obj.name}' (in Edit Mode)")
                continue
            if len(me.polygons) == 0:
                skipped.append(f"'{obj.name}' (no faces)")
                continue
            try:
                uv, conflicts = atlas_loop_uvs(me, obj.matrix_world)
            except Exception as ex:
                skipped.append(f"'{obj.name}' ({type(ex).__name__}: {ex})")
                continue
            layer = me.uv_layers.new(name=UV_NAME)
            if layer is None:
                skipped.append(f"'{obj.name}' (cannot add a UV map)")
                continue
            layer.data.foreach_set("uv", uv.reshape(-1))
            me.update()
            if conflicts:
                self.report({'INFO'}, f"'{obj.name}': {conflicts} non-planar face(s) mapped "
                                      f"from one triangle's chart (may overlap slightly)")
            done.append(obj.name)
        if skipped:
            self.report({'WARNING'}, "Not unwrapped: " + ", ".join(skipped))
        self.report({'INFO'}, f"Relight: unwrapped {len(done)} object(s)"
                              + (f" ({', '.join(done)})" if done else ""))
        return {'FINISHED'}


classes = (RELIGHT_OT_unwrap_missing,)
