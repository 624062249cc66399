# SPDX-License-Identifier: GPL-3.0-or-later
"""AR mode (seed 002): environment lighting, ambient occlusion, glossy reflection and the sphere
soft shadows of a virtual object under an environment map.  bpy-free."""
