# SPDX-License-Identifier: GPL-3.0-or-later
"""RELIGHT_PT_capture: the "Capture" sub-panel of the Relight tab (board, calibration, camera
pose from the board, HDR merge / environment, photo projection)."""

import bpy

BOARD_ARGS = ("squares_x", "squares_y", "square_length", "marker_length", "dictionary")


def _board(op, settings):
    for name in BOARD_ARGS:
        setattr(op, name, getattr(settings, name))


class RELIGHT_PT_capture(bpy.types.Panel):
    bl_idname = "RELIGHT_PT_capture"
    bl_label = "Capture"
    bl_space_type = 'VIEW_3D'
    bl_region_type = 'UI'
    bl_category = "Relight"
    bl_parent_id = "RELIGHT_PT_main"
    bl_options = {'DEFAULT_CLOSED'}

    def draw(self, context):
        layout = self.layout
        s = getattr(context.scene, "relight_capture", None)
        if s is None:
            layout.label(text="Capture settings are not registered", icon='ERROR')
            return
        box = layout.box()
        box.label(text="ChArUco Board", icon='TEXTURE')
        row = box.row(align=True)
        row.prop(s, "squares_x", text="X")
        row.prop(s, "squares_y", text="Y")
        row = box.row(align=True)
        row.prop(s, "square_length")
        row.prop(s, "marker_length")
        box.prop(s, "dictionary", text="")
        row = box.row(align=True)
        row.prop(s, "board_file", text="")
        row.prop(s, "paper", text="")
        op = box.operator("relight.calibration_board", text="Write Board (PNG + PDF)",
                          icon='FILE_IMAGE')
        _board(op, s)
        op.filepath = s.board_file
        op.paper = s.paper

        box = layout.box()
        box.label(text="Camera", icon='CAMERA_DATA')
        box.prop(s, "photos")
        box.prop(s, "calibration")
        op = box.operator("relight.calibrate_camera", icon='OUTLINER_OB_CAMERA')
        _board(op, s)
        op.directory = s.photos
        op.output = s.calibration
        box.prop(s, "marker_photo")
        box.prop(s, "board_object")
        op = box.operator("relight.camera_from_marker", icon='ORIENTATION_VIEW')
        _board(op, s)
        op.filepath = s.marker_photo
        op.calibration = s.calibration
        op.board_object = s.board_object.name if s.board_object else ""

        box = layout.box()
        box.label(text="HDR and Environment", icon='WORLD')
        box.prop(s, "brackets")
        box.prop(s, "hdr_output")
        box.prop(s, "environment")
        op = box.operator("relight.merge_hdr", icon='IMAGE_RGB_ALPHA')
        op.directory = s.brackets
        op.output = s.hdr_output
        op.environment = s.environment

        box = layout.box()
        box.label(text="Photo Textures", icon='IMAGE_DATA')
        box.prop(s, "texture_size")
        op = box.operator("relight.project_photos", icon='TEXTURE')
        op.texture_size = s.texture_size


classes = (RELIGHT_PT_capture,)
