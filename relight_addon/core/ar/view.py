# SPDX-License-Identifier: GPL-3.0-or-later
"""The photo's camera: where a world point falls in the photo, and what the camera sees.

A camera-matching tool (fSpy) gives a Blender perspective camera whose frame is the photo.  A
point p in world space falls in the frame at

    u = 0.5 + a_u x / (-z) - b_u,   v = 0.5 + a_v y / (-z) - b_v

with (x, y, z) = R^T (p - o) in the camera's frame (R, o its rotation and location; it looks
along -z), u right and v up in [0, 1] over the frame.  The factors follow Blender's viewplane
(BKE_camera_params_compute_viewplane): the sensor fit picks the frame side the sensor size
spans (AUTO: the longer one, with the sensor width), k = lens / sensor size, and

    a_u = k F / W,   a_v = k F / (c H),   b_u = shift_x F / W,   b_v = shift_y F / (c H)

with W x H the render resolution, c = pixel aspect y / x, F = W for a horizontal fit and c H
for a vertical one.  The receivers' materials evaluate the same with node maths (the factors
are drivers of the camera's settings: blender/ar_nodes.py); this is their numpy twin.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

NEAR = 1e-6        # metres in front of the camera: a point closer is behind it


@dataclass
class CameraModel:
    """matrix (4, 4) camera to world; lens and sensor sizes in mm; sensor_fit 'AUTO',
    'HORIZONTAL' or 'VERTICAL'; shift_x / shift_y in frame units; resolution (W, H) in pixels;
    pixel_aspect (x, y)."""
    matrix: np.ndarray
    lens: float
    sensor_width: float
    sensor_height: float
    sensor_fit: str
    shift_x: float
    shift_y: float
    resolution: tuple
    pixel_aspect: tuple = (1.0, 1.0)

    def factors(self):
        """(a_u, a_v, b_u, b_v) of the module docstring."""
        w, h = (float(x) for x in self.resolution)
        px, py = (float(x) for x in self.pixel_aspect)
        fit = self.sensor_fit
        horizontal = fit == "HORIZONTAL" or (fit == "AUTO" and px * w >= py * h)
        sensor = self.sensor_height if fit == "VERTICAL" else self.sensor_width
        c = py / px
        f = w if horizontal else c * h
        k = self.lens / sensor
        return k * f / w, k * f / (c * h), self.shift_x * f / w, self.shift_y * f / (c * h)

    def to_camera(self, points):
        """(n, 3) camera-frame coordinates of world ``points`` (n, 3)."""
        m = np.asarray(self.matrix, float)
        r, o = m[:3, :3], m[:3, 3]
        # the rotation part without the camera object's scale (Blender ignores it for views)
        r = r / np.maximum(np.linalg.norm(r, axis=0, keepdims=True), 1e-300)
        return (np.asarray(points, float) - o) @ r

    def project(self, points):
        """(u (n,), v (n,), in_front (n,) bool) of world ``points``: frame coordinates (0..1 over
        the photo, v up) and whether the point is in front of the camera."""
        q = self.to_camera(points)
        depth = -q[:, 2]
        front = depth > NEAR
        d = np.where(front, depth, 1.0)
        a_u, a_v, b_u, b_v = self.factors()
        return 0.5 + a_u * q[:, 0] / d - b_u, 0.5 + a_v * q[:, 1] / d - b_v, front


def triangles_in_view(camera, triangles):
    """(t,) bool: which world ``triangles`` (t, 3, 3) overlap the camera's frame in front of it
    (clipped at the near plane, then a separating-axis test of the projected polygon against
    the frame's square)."""
    tri = np.asarray(triangles, float).reshape(-1, 3, 3)
    if len(tri) == 0:
        return np.zeros(0, bool)
    q = camera.to_camera(tri.reshape(-1, 3)).reshape(-1, 3, 3)
    a_u, a_v, b_u, b_v = camera.factors()
    out = np.zeros(len(tri), bool)
    for i, t in enumerate(q):
        poly = _clip_near(t)
        if len(poly) < 3:
            continue
        d = -poly[:, 2]
        uv = np.stack([0.5 + a_u * poly[:, 0] / d - b_u, 0.5 + a_v * poly[:, 1] / d - b_v], 1)
        out[i] = _overlaps_unit_square(uv)
    return out


def _clip_near(t, near=NEAR):
    """The triangle ``t`` (3, 3) in camera coordinates clipped to depth >= near (a polygon)."""
    out = []
    for a, b in zip(t, np.roll(t, -1, axis=0)):
        da, db = -a[2] - near, -b[2] - near
        if da >= 0:
            out.append(a)
        if (da >= 0) != (db >= 0):
            out.append(a + (b - a) * (da / (da - db)))
    return np.array(out).reshape(-1, 3)


def _overlaps_unit_square(uv):
    """Whether the convex polygon ``uv`` (k, 2) overlaps [0, 1]^2 (separating axes: the
    square's two and the polygon's edge normals)."""
    if uv[:, 0].max() < 0 or uv[:, 0].min() > 1 or uv[:, 1].max() < 0 or uv[:, 1].min() > 1:
        return False
    square = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    for a, b in zip(uv, np.roll(uv, -1, axis=0)):
        n = np.array([b[1] - a[1], a[0] - b[0]])
        if not np.any(n):
            continue
        p, s = uv @ n, square @ n
        if p.max() < s.min() or s.max() < p.min():
            return False
    return True


def seen(camera, triangles):
    """Whether any of the world ``triangles`` (t, 3, 3) is seen in the camera's frame (a quick
    test of the vertices first, then :func:`triangles_in_view`)."""
    tri = np.asarray(triangles, float).reshape(-1, 3, 3)
    if len(tri) == 0:
        return False
    u, v, front = camera.project(tri.reshape(-1, 3))
    if np.any(front & (u >= 0) & (u <= 1) & (v >= 0) & (v <= 1)):
        return True
    return bool(triangles_in_view(camera, tri).any())
