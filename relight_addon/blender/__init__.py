"""The bridge between Blender data and the core (imports bpy and mathutils)."""

from . import bvhtree  # noqa: F401  (registers the mathutils ray-casting fallback)
