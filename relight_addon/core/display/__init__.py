"""bpy-free helpers for the viewport overlays (numpy twins of the overlay shaders' maths)."""
