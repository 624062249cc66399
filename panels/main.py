# SPDX-License-Identifier: GPL-3.0-or-later
"""The sidebar "Relight" tab of the 3D viewport: the main panel (quality, Precompute, Update,
Restore) and its sub-panels Lamps, Virtual and Diagnostics.

Lines are short enough for a sidebar and wrapped to its width where they can be long (the
warnings); every figure says what it is.
"""

import math
import textwrap

import bpy

from ..relight_addon.version import addon_version

# Warnings listed in the panel (all of them are in the Info editor and the status dict).
PANEL_WARNINGS = 8
GEOMETRY_TYPES = {'MESH', 'CURVE', 'SURFACE', 'FONT', 'META'}


def _state():
    from ..relight_addon.blender import state
    return state


def _relit_draw():
    from ..relight_addon.blender import relit_draw
    return relit_draw


def _wrap(layout, text, width, icon='NONE'):
    """``text`` as lines of at most ``width`` characters, the first with ``icon``."""
    col = layout.column(align=True)
    for i, line in enumerate(textwrap.wrap(text, max(width, 16)) or [""]):
        col.label(text=line, icon=icon if i == 0 else 'BLANK1')


def _width(context):
    """Characters a line of the sidebar holds."""
    region = getattr(context, "region", None)
    scale = context.preferences.view.ui_scale if getattr(context, "preferences", None) else 1.0
    return int((region.width if region is not None else 300) / (7.0 * scale)) - 4


def status_lines(scene):
    """(text, icon) lines describing the last precompute (empty before the first)."""
    st = _state().status(scene)
    if not st:
        return []
    action = st.get("action", "")
    what = {"quick": "Updated", "rewrite": "Written again", "reuse": "Solved again (photos)"}
    lines = [(f"{what.get(action, 'Solved')} in {st['seconds']:.1f} s ({st['preset']})",
              'TIME'),
             (f"{st['elements']:,} light elements, {st['links']:,} links", 'MESH_GRID')]
    if st.get("proxy_faces", 0):
        lines.append((f"{st['input_faces']:,} faces solved on {st['proxy_faces']:,} "
                      f"(within {1000 * st['proxy_deviation']:.1f} mm)", 'MOD_DECIM'))
    if math.isfinite(st.get("misfit", float("nan"))):
        lines.append((f"Explains the photo to {100 * st['misfit']:.1f} % (RMS)", 'INFO'))
    if st.get("rho_mean", -1) > 0:
        rho, sigma = st["rho_mean"], st.get("rho_sigma", -1)
        lines.append((f"Mean reflectance {rho:.2f} \u00b1 {rho * sigma:.2f}" if sigma >= 0 else
                      f"Mean reflectance {rho:.2f} (guessed)", 'INFO'))
    kept = st.get("kept_mb", 0.0)
    if kept > 0:
        lines.append((f"Solution kept in the file: {kept:.1f} MB", 'FILE_BLEND'))
    elif kept < 0:
        lines.append((f"Solution not kept ({-kept:.0f} MB: over the limit)", 'FILE_BLEND'))
    return lines


def lamp_lines(scene):
    """Per lamp of the maps: (its line, the photo's view of it, icon)."""
    state = _state()
    st = state.status(scene)
    if not st:
        return []
    records = state.lamp_records(scene)
    n = len(st["lamps"])
    out = []
    for j, name in enumerate(st["lamps"]):
        record = records[j] if j < len(records) else {}
        obj = state.find_light(scene, record) if record.get("uid") else None
        strength = record.get("strength") or {}
        if record.get("kind") == "emissive" and strength.get("node"):
            mat = bpy.data.materials.get(record.get("material") or "")
            node = mat.node_tree.nodes.get(strength["node"]) if mat and mat.node_tree else None
            sock = node.inputs.get(strength["input"]) if node is not None else None
            s0 = float(strength.get("value", 0.0))
            now = f"now at {sock.default_value / s0:.2f}x" if sock is not None and s0 > 0 \
                else "fixed"
        elif record.get("kind", "light") == "light" and obj is None and record:
            now = "deleted: off"
        elif obj is not None and float(record.get("p0", 0.0)) > 0:
            now = f"now at {obj.data.energy / float(record['p0']):.2f}x"
            if obj.name != name:
                now += f" ('{obj.name}')"
        else:
            now = "fixed"
        head = f"{name}: {now}"
        if record.get("virtual"):
            out.append((head, "virtual (not in the photo)", 'LIGHT_POINT'))
            continue
        ratio = st.get("photo_ratio", [-1] * n)[j]
        sigma = st.get("photo_sigma", [-1] * n)[j]
        used = st.get("photo_used", [False] * n)[j]
        weight = st.get("photo_weight", [1.0] * n)[j] if used else 0.0
        if n == 1 or sum(not r.get("virtual") for r in records) == 1:
            view = "set power used (one lamp)"
        elif ratio <= 0 or sigma < 0 or not math.isfinite(sigma):
            view = "set power used (the photo cannot tell)"
        else:
            taken = ("set power used" if not used else "photo used" if weight >= 1.0 else
                     "photo used in part")
            view = f"photo says {ratio:.2f}x \u00b1 {100 * sigma:.0f} %; {taken}"
        out.append((head, view, 'LIGHT_AREA'))
    return out


def warning_lines(scene, limit=PANEL_WARNINGS):
    st = _state().status(scene) or {}
    warnings = list(st.get("warnings", ()))
    lines = warnings[:limit]
    if len(warnings) > limit:
        lines.append(f"... and {len(warnings) - limit} more (Info editor)")
    return lines


class _RelightPanel:
    bl_space_type = 'VIEW_3D'
    bl_region_type = 'UI'
    bl_category = "Relight"


class RELIGHT_PT_main(_RelightPanel, bpy.types.Panel):
    bl_idname = "RELIGHT_PT_main"
    bl_label = "Relight"

    def draw_header_preset(self, context):
        self.layout.label(text=addon_version())

    def draw(self, context):
        layout = self.layout
        settings = getattr(context.scene, "relight", None)
        if settings is None:
            layout.operator("relight.check_dependencies", icon='CHECKMARK')
            return
        col = layout.column(align=True)
        col.prop(settings, "preset")
        col.prop(settings, "correction")
        row = layout.row(align=True)
        row.scale_y = 1.4
        op = row.operator("relight.precompute", icon='LIGHT_AREA')
        op.preset = settings.preset
        op.correction = settings.correction
        row.operator("relight.update", icon='FILE_REFRESH')
        for text, icon in status_lines(context.scene)[:1]:
            layout.label(text=text, icon=icon)
        row = layout.row(align=True)
        row.operator("relight.restore_originals", text="Restore", icon='LOOP_BACK')
        row.operator("relight.show_relit", text="Show Relit", icon='LOOP_FORWARDS')
        row.operator("relight.clear", text="Clear", icon='TRASH')


class RELIGHT_PT_scene(_RelightPanel, bpy.types.Panel):
    bl_idname = "RELIGHT_PT_scene"
    bl_label = "Scene"
    bl_parent_id = "RELIGHT_PT_main"
    bl_options = {'DEFAULT_CLOSED'}

    def draw(self, context):
        layout = self.layout
        layout.operator("relight.unwrap_missing", icon='UV')
        settings = getattr(context.scene, "relight", None)
        if settings is not None:
            layout.prop(settings, "proxy_faces")
        layout.operator("relight.check_dependencies", icon='CHECKMARK')


class RELIGHT_PT_lamps(_RelightPanel, bpy.types.Panel):
    bl_idname = "RELIGHT_PT_lamps"
    bl_label = "Lamps"
    bl_parent_id = "RELIGHT_PT_main"

    def draw(self, context):
        layout = self.layout
        lines = lamp_lines(context.scene)
        if not lines:
            layout.label(text="Precompute first", icon='INFO')
            return
        width = _width(context)
        for head, view, icon in lines:
            col = layout.column(align=True)
            col.label(text=head, icon=icon)
            _wrap(col, view, width, 'BLANK1')
        layout.operator("relight.match_lamp_powers", icon='LIGHT_SUN')


class RELIGHT_PT_virtual(_RelightPanel, bpy.types.Panel):
    bl_idname = "RELIGHT_PT_virtual"
    bl_label = "Virtual"
    bl_parent_id = "RELIGHT_PT_main"

    def draw(self, context):
        layout = self.layout
        obj = context.active_object
        if obj is not None and obj.type in GEOMETRY_TYPES and hasattr(obj, "relight_role"):
            raw = obj.get("relight_role")
            if isinstance(raw, str):          # set as a plain custom property by a script
                layout.label(text=f"{obj.name}: '{raw}' (custom property)", icon='OBJECT_DATA')
            else:
                layout.prop(obj, "relight_role", text="Role")
            if getattr(obj, "relight_role", None) == "virtual" and \
                    hasattr(obj, "relight_shadows"):
                row = layout.row(align=True)
                row.prop(obj, "relight_shadows")
                if obj.relight_shadows == "SPHERES":
                    row.prop(obj, "relight_spheres")
        else:
            _wrap(layout, "Select a mesh to set its role; a light added after Precompute is a "
                          "virtual lamp", _width(context), 'INFO')
        settings = getattr(context.scene, "relight", None)
        if settings is not None:
            layout.prop(settings, "settle")
            layout.prop(settings, "eevee_shadows")
            layout.prop(settings, "cycles_shadows")
            layout.prop(settings, "relit_preview")
            stopped = _relit_draw().failure() if settings.relit_preview else None
            if stopped:
                _wrap(layout, f"The preview stopped ({stopped}); switch it off and on to try "
                              "again", _width(context), 'ERROR')
        layout.operator("relight.eevee_light", icon='LIGHTPROBE_VOLUME')


class RELIGHT_PT_diagnostics(_RelightPanel, bpy.types.Panel):
    bl_idname = "RELIGHT_PT_diagnostics"
    bl_label = "Diagnostics"
    bl_parent_id = "RELIGHT_PT_main"
    bl_options = {'DEFAULT_CLOSED'}

    def draw_header(self, context):
        n = len((_state().status(context.scene) or {}).get("warnings", ()))
        if n:
            self.layout.label(text=str(n), icon='ERROR')

    def draw(self, context):
        layout = self.layout
        settings = getattr(context.scene, "relight", None)
        if settings is not None:
            layout.prop(settings, "overlay")
        for text, icon in status_lines(context.scene)[1:]:
            layout.label(text=text, icon=icon)
        warnings = warning_lines(context.scene)
        if warnings:
            width = _width(context)
            box = layout.box()
            for text in warnings:
                _wrap(box, text, width, 'ERROR')


classes = (RELIGHT_PT_main, RELIGHT_PT_scene, RELIGHT_PT_lamps, RELIGHT_PT_virtual,
           RELIGHT_PT_diagnostics)
