# SPDX-License-Identifier: GPL-3.0-or-later
"""The sidebar's "AR" sub-panel: Set Up AR, Update and Clear AR, what the set-up read (the
photo, the receivers, the objects, the environment's lights) and its warnings."""

import bpy

from .main import _RelightPanel, _width, _wrap


def _ar():
    from ..relight_addon.blender import ar
    return ar


def status_lines(scene):
    """(text, icon) lines of the scene's AR set-up (empty before it)."""
    ar = _ar()
    if not ar.is_set_up(scene):
        return []
    st = ar.state(scene)
    lines = [(f"Photo '{st.get('photo', '?')}' seen by '{st.get('camera', '?')}'", 'IMAGE_DATA'),
             (f"{len(st.get('receivers', ()))} receiver(s), {len(st.get('objects', ()))} "
              "virtual object(s)", 'OBJECT_DATA')]
    lights = st.get("lights", [])
    if lights:
        main = max(lights, key=lambda r: r.get("share", 0.0))
        lines.append((f"{len(lights)} light(s) in the environment, the main one "
                      f"{100 * main.get('share', 0.0):.0f} % of its light", 'LIGHT_SUN'))
    return lines


class RELIGHT_PT_ar(_RelightPanel, bpy.types.Panel):
    bl_idname = "RELIGHT_PT_ar"
    bl_label = "AR"
    bl_parent_id = "RELIGHT_PT_main"
    bl_options = {'DEFAULT_CLOSED'}

    def draw(self, context):
        layout = self.layout
        scene = context.scene
        row = layout.row(align=True)
        row.scale_y = 1.2
        row.operator("relight.ar_setup", icon='CAMERA_DATA')
        row.operator("relight.update", icon='FILE_REFRESH')
        settings = getattr(scene, "relight", None)
        if settings is not None:
            layout.prop(settings, "ar_eevee_ground")
        lines = status_lines(scene)
        width = _width(context)
        if not lines:
            _wrap(layout, "The photo is the camera's background image, the World's Environment "
                          "Texture the light; mark the photographed surfaces as receivers and "
                          "the inserted objects as virtual (Virtual panel)", width, 'INFO')
            return
        for text, icon in lines:
            _wrap(layout, text, width, icon)
        warnings = _ar().state(scene).get("warnings", [])
        if warnings:
            box = layout.box()
            for text in warnings:
                _wrap(box, text, width, 'ERROR')
        layout.operator("relight.ar_clear", icon='TRASH')


classes = (RELIGHT_PT_ar,)
