# SPDX-License-Identifier: GPL-3.0-or-later
"""The camera's pose from a ChArUco board, and the smoothing of a sequence of poses.

Frames (seed 002 §2.3.3, eq 2.3.3.1):

* OpenCV camera: X right, Y down, Z forward; Blender camera: X right, Y up, looking down -Z;
  so ``camera_blender = camera_cv @ diag(1, -1, -1)``.
* Board (OpenCV's): origin at the printed image's top-left corner, X right, Y down the image,
  Z into the board.  The board object in Blender is a plane of the board's size W x H centred
  on its origin, printed face towards local +Z, image top towards local +Y (what "Images as
  Planes" makes of the board PNG): the board frame sits at plane-local (-W/2, +H/2, 0) with
  X = +X, Y = -Y, Z = -Z.

``solvePnP`` gives ``T_cv_board`` (board -> OpenCV camera); the camera's ``matrix_world`` is

    M_camera = M_board_frame @ inverse(T_cv_board) @ diag(1, -1, -1, 1)

The pose: IPPE (the planar solver, both of its solutions tried), then Levenberg-Marquardt
refinement of the better one on all corners.

Sequences: poses far from what their neighbours predict (slerp / lerp between the frames on
either side, far above the sequence's typical error) are rejected, rejected and missing frames
are filled by slerp between the nearest kept frames, and the path is
smoothed by a zero-phase exponential filter made of slerps (seed 003's quaternion
interpolation): a forward pass ``q_i <- slerp(q_{i-1}, q_i, a)`` then the same pass backward.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import CaptureError
from .calibration import MAX_BLUR_SIGMA, board_points

BLENDER_FROM_CV = np.diag([1.0, -1.0, -1.0, 1.0])
# A board object may differ from the board's size by this fraction (print scaling, rounding).
SIZE_TOLERANCE = 0.01
MIN_POSE_CORNERS = 4
# Outlier rejection: a pose is rejected when it lies further (rotation angle or position) from
# what its neighbours predict (slerp / lerp between them) than REJECT_FACTOR times the
# sequence's median of that error and the floors below (a smooth, noise-free path keeps all).
REJECT_FACTOR = 5.0
REJECT_FLOOR_DEG = 0.5
REJECT_FLOOR_REL = 0.01    # of the path's spread (its poses around their mean, plus a step)


def _cv2():
    import cv2  # noqa: PLC0415
    return cv2


@dataclass
class Pose:
    """Board -> OpenCV camera: x_cam = R x_board + t; RMS reprojection error (px)."""

    R: np.ndarray
    t: np.ndarray
    rms: float
    n: int

    @property
    def matrix(self) -> np.ndarray:
        m = np.eye(4)
        m[:3, :3] = self.R
        m[:3, 3] = self.t
        return m


def board_pose(detection, spec, camera_matrix, dist_coeffs) -> Pose:
    """The board's pose in the camera of a detection (distortion handled by OpenCV)."""
    cv2 = _cv2()
    if len(detection) < MIN_POSE_CORNERS:
        if len(detection):
            raise CaptureError(f"only {len(detection)} board corners found")
        blurred = detection.blur > MAX_BLUR_SIGMA        # NaN (nothing to measure) is not
        raise CaptureError("no board found" + (f" (the photo is blurred: edges "
                                               f"{detection.blur:.1f} px wide)" if blurred else ""))
    board = spec.board()
    obj, img = board_points(board, detection)
    k = np.asarray(camera_matrix, np.float64)
    d = np.asarray(dist_coeffs, np.float64).ravel()
    n, rvecs, tvecs, errs = cv2.solvePnPGeneric(obj, img, k, d, flags=cv2.SOLVEPNP_IPPE)
    if not n:
        raise CaptureError("the board's pose could not be solved")
    best, best_err = None, np.inf
    for r, t in zip(rvecs, tvecs):
        r, t = cv2.solvePnPRefineLM(obj, img, k, d, r.copy(), t.copy())
        proj, _ = cv2.projectPoints(obj, r, t, k, d)
        err = float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - img) ** 2, axis=1))))
        if err < best_err and float(np.ravel(t)[2]) > 0:
            best, best_err = (r, t), err
    if best is None:
        raise CaptureError("the board's pose puts it behind the camera")
    R, _ = cv2.Rodrigues(best[0])
    return Pose(R, np.asarray(best[1], np.float64).ravel(), best_err, len(obj))


def board_frame(matrix_world, local_min, local_max, board_size, tolerance=SIZE_TOLERANCE):
    """World matrix (4x4, rigid) of the board's OpenCV frame for a board plane object.

    ``matrix_world`` the object's, ``local_min / local_max`` its mesh's local bounding box,
    ``board_size`` (W, H) metres.  Raises when the plane's world size is not the board's.
    """
    m = np.asarray(matrix_world, np.float64)
    lin = m[:3, :3]
    u, s, vt = np.linalg.svd(lin)
    rot = u @ vt
    if np.linalg.det(rot) < 0:
        raise CaptureError("The board object is mirrored (negative scale)")
    scale = np.linalg.norm(lin, axis=0)              # per local axis
    if not np.allclose(lin, rot * scale[None, :], atol=1e-6 * max(scale.max(), 1e-12)):
        raise CaptureError("The board object is sheared (its parent's scale is not uniform)")
    lo = np.asarray(local_min, np.float64)
    hi = np.asarray(local_max, np.float64)
    size = (hi - lo)[:2] * scale[:2]
    w, h = board_size
    if not (abs(size[0] - w) <= tolerance * w and abs(size[1] - h) <= tolerance * h):
        raise CaptureError(f"The board object is {size[0]:.3f} x {size[1]:.3f} m but the board "
                           f"is {w:.3f} x {h:.3f} m (squares x square length): check the board "
                           f"size or the object")
    centre = 0.5 * (lo + hi)
    corner_local = np.array([centre[0] - 0.5 * (hi[0] - lo[0]), centre[1] + 0.5 * (hi[1] - lo[1]),
                             centre[2]])
    frame = np.eye(4)
    frame[:3, :3] = rot @ np.diag([1.0, -1.0, -1.0])
    frame[:3, 3] = m[:3, :3] @ corner_local + m[:3, 3]
    return frame


def plane_frame(board_size) -> np.ndarray:
    """Plane-local matrix of the board frame of a W x H plane centred on its origin."""
    w, h = board_size
    f = np.diag([1.0, -1.0, -1.0, 1.0])
    f[:3, 3] = (-w / 2, h / 2, 0.0)
    return f


def camera_world_matrix(board_frame_world, pose: Pose) -> np.ndarray:
    """Blender camera matrix_world from the board frame's world matrix and the pose."""
    return np.asarray(board_frame_world, np.float64) @ np.linalg.inv(pose.matrix) @ BLENDER_FROM_CV


def pose_from_camera_world(board_frame_world, camera_world) -> np.ndarray:
    """The inverse: T_cv_board (4x4) of a Blender camera matrix_world (scale removed)."""
    c = np.asarray(camera_world, np.float64).copy()
    c[:3, :3] /= np.linalg.norm(c[:3, :3], axis=0)
    return np.linalg.inv(c @ BLENDER_FROM_CV) @ np.asarray(board_frame_world, np.float64)


# ------------------------------------------------------------------------------------------
# Quaternions and sequences
# ------------------------------------------------------------------------------------------

def quat_from_matrix(R) -> np.ndarray:
    """(..., 4) unit quaternions (w, x, y, z) of rotation matrices (..., 3, 3)."""
    from scipy.spatial.transform import Rotation  # noqa: PLC0415
    R = np.asarray(R, np.float64)
    q = Rotation.from_matrix(R.reshape(-1, 3, 3)).as_quat()          # x y z w
    return np.concatenate([q[:, 3:], q[:, :3]], axis=1).reshape(R.shape[:-2] + (4,))


def matrix_from_quat(q) -> np.ndarray:
    from scipy.spatial.transform import Rotation  # noqa: PLC0415
    q = np.asarray(q, np.float64)
    flat = q.reshape(-1, 4)
    return Rotation.from_quat(np.concatenate([flat[:, 1:], flat[:, :1]], 1)).as_matrix() \
        .reshape(q.shape[:-1] + (3, 3))


def slerp(q0, q1, t) -> np.ndarray:
    """Spherical linear interpolation of unit quaternions (n, 4) (shortest arc), t (n,) or scalar."""
    q0 = np.asarray(q0, np.float64)
    q1 = np.asarray(q1, np.float64)
    t = np.asarray(t, np.float64)[..., None] if np.ndim(t) else float(t)
    dot = np.sum(q0 * q1, axis=-1, keepdims=True)
    q1 = np.where(dot < 0, -q1, q1)
    dot = np.abs(dot)
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    sin = np.sin(theta)
    small = sin < 1e-9                                   # nearly equal: lerp is exact enough
    with np.errstate(invalid="ignore", divide="ignore"):
        a = np.where(small, 1.0 - t, np.sin((1.0 - t) * theta) / np.where(small, 1.0, sin))
        b = np.where(small, t, np.sin(t * theta) / np.where(small, 1.0, sin))
    q = a * q0 + b * q1
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def rotation_angle(q0, q1) -> np.ndarray:
    """Angle (radians) of the rotation between unit quaternions."""
    dot = np.abs(np.sum(np.asarray(q0) * np.asarray(q1), axis=-1))
    return 2.0 * np.arccos(np.clip(dot, 0.0, 1.0))


def _prediction_error(q, p, idx):
    """Per kept frame, how far its pose lies from what its kept neighbours predict: slerp /
    lerp between the frames on either side (one and two kept frames away), or extrapolated
    from the two on one side; the smallest of the predictions' errors, each scaled to the
    noise of a half-way prediction (so that one bad neighbour does not condemn a frame, nor
    its place at an end).  (rotation angles, distances)."""
    n = len(idx)
    ang = np.full(n, np.inf)
    dist = np.full(n, np.inf)
    for j in range(n):       # frames of a sequence (hundreds), not elements
        preds = []
        for k in (1, 2):
            a, b = j - k, j + k
            if a >= 0 and b < n:
                t = (idx[j] - idx[a]) / max(idx[b] - idx[a], 1)
                preds.append((a, b, t))
        for a, b in ((j + 1, j + 2), (j - 1, j - 2)):
            if 0 <= a < n and 0 <= b < n:
                t = (idx[j] - idx[a]) / (idx[b] - idx[a])     # < 0: extrapolated
                preds.append((a, b, t))
        for a, b, t in preds:
            qp = slerp(q[a][None], q[b][None], t)[0]
            pp = (1 - t) * p[a] + t * p[b]
            # in units of a half-way prediction's noise: an extrapolation (t = -1) carries
            # twice the noise of its two poses' (variance 1 + (1-t)^2 + t^2 against 1.5)
            amp = np.sqrt((1.0 + (1.0 - t) ** 2 + t ** 2) / 1.5)
            ang[j] = min(ang[j], float(rotation_angle(q[j], qp)) / amp)
            dist[j] = min(dist[j], float(np.linalg.norm(p[j] - pp)) / amp)
    return ang, dist


def _quat_mul(a, b):
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack([aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw], -1)


def _quat_conj(q):
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def _reflect_pad(q, p, pad):
    """The path extended by ``pad`` frames at each end, reflected through its end poses
    (rotation q0 (q_k^-1 q0), position 2 p0 - p_k)."""
    if pad <= 0:
        return q.copy(), p.copy()
    k0 = np.arange(pad, 0, -1)
    k1 = np.arange(len(q) - 2, len(q) - 2 - pad, -1)
    head_q = _quat_mul(q[0][None], _quat_mul(_quat_conj(q[k0]), q[0][None]))
    tail_q = _quat_mul(q[-1][None], _quat_mul(_quat_conj(q[k1]), q[-1][None]))
    qq = np.concatenate([head_q, q, tail_q])
    qq /= np.linalg.norm(qq, axis=1, keepdims=True)
    pp = np.concatenate([2 * p[0] - p[k0], p, 2 * p[-1] - p[k1]])
    return qq, pp


def smooth_path(matrices, valid=None, smoothing: float = 0.5, reject: bool = True):
    """Smoothed camera path.

    ``matrices`` (n, 4, 4) rigid poses (any convention: camera-to-world or board-to-camera),
    ``valid`` (n,) which frames have a measured pose, ``smoothing`` in [0, 1) (0: none; the
    forward/backward slerp factor is 1 - smoothing).  Returns (smoothed (n, 4, 4), rejected
    (n,) bool: measured poses dropped as outliers).  Frames with no kept pose are filled by
    slerp between the nearest kept frames (held at the ends).
    """
    m = np.asarray(matrices, np.float64)
    n = len(m)
    valid = np.ones(n, bool) if valid is None else np.asarray(valid, bool).copy()
    if not 0.0 <= smoothing < 1.0:
        raise ValueError("smoothing must be in [0, 1)")
    rejected = np.zeros(n, bool)
    idx = np.flatnonzero(valid)
    if len(idx) == 0:
        raise CaptureError("No frame has a pose")
    q = quat_from_matrix(m[:, :3, :3])
    p = m[:, :3, 3].copy()
    if reject and len(idx) >= 5:
        ang, dist = _prediction_error(q[idx], p[idx], idx)
        scale = float(np.median(np.linalg.norm(np.diff(p[idx], axis=0), axis=1))) + \
            float(np.mean(np.linalg.norm(p[idx] - p[idx].mean(axis=0), axis=1)))
        lim_a = max(REJECT_FACTOR * np.median(ang), np.radians(REJECT_FLOOR_DEG))
        lim_d = max(REJECT_FACTOR * np.median(dist), REJECT_FLOOR_REL * scale)
        bad = (ang > lim_a) | (dist > lim_d)
        rejected[idx[bad]] = True
        valid &= ~rejected
        idx = np.flatnonzero(valid)
    # fill: slerp / lerp between the nearest kept frames
    frames = np.arange(n)
    nxt = np.searchsorted(idx, frames)                 # first kept frame >= i
    hi = idx[np.minimum(nxt, len(idx) - 1)]
    lo = idx[np.maximum(nxt - 1, 0)]
    lo = np.where(valid, frames, lo)
    hi = np.where(valid, frames, hi)
    span = np.maximum(hi - lo, 1)
    t = np.where(hi > lo, (frames - lo) / span, 0.0)
    t = np.clip(t, 0.0, 1.0)
    qf = slerp(q[lo], q[hi], t)
    pf = (1 - t)[:, None] * p[lo] + t[:, None] * p[hi]
    # zero-phase exponential smoothing by slerp: forward, then backward, over the path
    # extended at both ends by its point reflection (so that the ends do not lag)
    a = 1.0 - float(smoothing)
    if a < 1.0 and n > 1:
        pad = min(n - 1, int(np.ceil(3.0 / a)))
        qf, pf = _reflect_pad(qf, pf, pad)
        for order in (range(1, len(qf)), range(len(qf) - 2, -1, -1)):
            step = order.step
            for i in order:        # frames, sequential by nature
                qf[i] = slerp(qf[i - step][None], qf[i][None], a)[0]
                pf[i] = (1 - a) * pf[i - step] + a * pf[i]
        qf, pf = qf[pad:pad + n], pf[pad:pad + n]
    out = np.repeat(np.eye(4)[None], n, axis=0)
    out[:, :3, :3] = matrix_from_quat(qf)
    out[:, :3, 3] = pf
    return out, rejected
