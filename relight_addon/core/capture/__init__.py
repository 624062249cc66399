# SPDX-License-Identifier: GPL-3.0-or-later
"""Capture (bpy-free): ChArUco boards, camera calibration, marker poses, HDR merges and
environment maps, photo projection onto UV atlases.  One idea per module."""


class CaptureError(ValueError):
    """Bad capture input: the message is one sentence for the user (no board found, too few
    views, photos of different sizes ...)."""
