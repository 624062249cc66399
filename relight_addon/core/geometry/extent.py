"""A scene's size, for the tolerances that scale with it (ray offsets, matching grids)."""
import numpy as np


def _box(points):
    p = np.asarray(points, float).reshape(-1, 3)
    return p.max(axis=0) - p.min(axis=0) if len(p) else np.zeros(3)


def bounding_diagonal(points) -> float:
    """The diagonal of the points' axis-aligned bounding box (``points``: any shape ending in
    3); 1.0 when it is 0 (no points, or one), so that a tolerance scaled by it stays > 0."""
    return float(np.linalg.norm(_box(points))) or 1.0


def longest_side(points) -> float:
    """The longest side of the points' axis-aligned bounding box; 1.0 when it is 0."""
    return float(_box(points).max()) or 1.0
