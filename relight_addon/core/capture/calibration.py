# SPDX-License-Identifier: GPL-3.0-or-later
"""Camera calibration from ChArUco detections, its OpenCV FileStorage file, and the pinhole
matrix K of a Blender camera (both ways).

Calibration: ``cv2.calibrateCameraExtended`` on the re-refined corners (board.py) of every
usable view; views with too few corners, collinear corners, blurred edges or a reprojection
error far above the others are rejected (with the reason), and the fit is redone without them.

FileStorage (YAML or XML by the file's extension, the seed 002 node names):
``Camera_Matrix`` 3x3, ``Distortion_Coefficients`` 1xN in OpenCV's order (k1 k2 p1 p2 k3 ...),
``Image_Size`` [width, height], ``Root_Mean_Square`` (px).

Blender's camera (``BKE_camera_params_compute_viewplane``): with the render size W x H
(percentage applied), pixel aspect ax, ay (ycor = ay / ax), the sensor fit resolved as Blender
does (AUTO: horizontal when ax W >= ay H, and the sensor size is then always sensor_width),
``viewfac = W`` (horizontal fit) or ``ycor H`` (vertical fit):

    fx = lens viewfac / sensor          fy = fx / ycor
    cx = W / 2 - 0.5 - shift_x viewfac  cy = H / 2 - 0.5 + shift_y viewfac / ycor

in OpenCV pixel coordinates (the centre of the top-left pixel is (0, 0), y down): Cycles puts
pixel centres at half-integers from the image's edge, hence the 0.5 (measured: corners of a
rendered board land within 0.01 px of their projection through this K).  Skew is zero.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from . import CaptureError

MIN_VIEWS = 4            # views with a board needed to calibrate (OpenCV needs 3 for K alone)
MIN_CORNERS = 6          # corners a view needs (a homography plus some redundancy)
MAX_BLUR_SIGMA = 2.5     # px: a board whose edges are blurred more than this is rejected
# A view whose RMS error exceeds both this factor times the median view and OUTLIER_FLOOR_PX
# is rejected as an outlier (a misdetection, motion blur, a board that moved).
OUTLIER_FACTOR = 3.0
OUTLIER_FLOOR_PX = 0.5
CALIB_CRITERIA = (3, 200, 1e-12)  # TERM_CRITERIA_COUNT | EPS, iterations, epsilon
IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".exr", ".webp")


def _cv2():
    import cv2  # noqa: PLC0415
    return cv2


def list_images(directory: str) -> list:
    """Image files of a folder (sorted by name), hidden files left out."""
    if not directory or not os.path.isdir(directory):
        raise CaptureError(f"'{directory}' is not a folder")
    names = sorted(n for n in os.listdir(directory) if not n.startswith(".")
                   and os.path.splitext(n)[1].lower() in IMAGE_EXTENSIONS)
    if not names:
        raise CaptureError(f"No images (PNG, JPEG, TIFF, EXR ...) in '{directory}'")
    return [os.path.join(directory, n) for n in names]


def read_image(path: str, flags=None) -> np.ndarray:
    """cv2.imread that says which file it could not read (unicode paths included)."""
    cv2 = _cv2()
    try:
        data = np.fromfile(path, np.uint8)
    except OSError as ex:
        raise CaptureError(f"Cannot read '{path}': {ex.strerror or ex}") from None
    img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED if flags is None else flags)
    if img is None:
        raise CaptureError(f"'{os.path.basename(path)}' is not an image OpenCV can read")
    return img


@dataclass
class Calibration:
    """Intrinsics K (3x3), distortion (OpenCV order), image size (w, h), RMS (px), and how the
    views were used."""

    camera_matrix: np.ndarray
    dist_coeffs: np.ndarray
    image_size: tuple
    rms: float
    std: np.ndarray = field(default_factory=lambda: np.zeros(0))   # fx fy cx cy k1 k2 p1 p2 k3
    view_rms: dict = field(default_factory=dict)                   # name -> px
    rejected: dict = field(default_factory=dict)                   # name -> reason
    rvecs: list = field(default_factory=list)
    tvecs: list = field(default_factory=list)

    @property
    def used(self) -> list:
        return list(self.view_rms)

    def summary(self) -> str:
        k = self.camera_matrix
        rej = ""
        if self.rejected:
            rej = f", {len(self.rejected)} rejected (" + "; ".join(
                f"{n}: {r}" for n, r in list(self.rejected.items())[:3]) + \
                (" ..." if len(self.rejected) > 3 else "") + ")"
        return (f"{len(self.view_rms)} views used{rej}; RMS {self.rms:.3f} px, "
                f"f = {k[0, 0]:.1f} x {k[1, 1]:.1f} px, centre ({k[0, 2]:.1f}, {k[1, 2]:.1f})")


def board_points(board, detection):
    """(object points (n, 3) float32, image points (n, 2) float32) of a detection."""
    obj, img = board.matchImagePoints(np.asarray(detection.corners, np.float32).reshape(-1, 1, 2),
                                      np.asarray(detection.ids, np.int32).reshape(-1, 1))
    return (np.asarray(obj, np.float32).reshape(-1, 3), np.asarray(img, np.float32).reshape(-1, 2))


def view_problem(board, detection, min_corners=MIN_CORNERS, max_blur=MAX_BLUR_SIGMA):
    """Why a detection cannot serve the calibration (one phrase), or None."""
    cv2 = _cv2()
    n = len(detection)
    if len(detection.foreign_ids):
        return (f"markers {detection.foreign_ids[:4].tolist()} are not on this board "
                f"(check squares_x / squares_y and the dictionary)")
    blurred = np.isfinite(max_blur) and detection.blur > max_blur
    if n == 0:
        if len(detection.marker_ids):
            return "markers found but no corners (check squares_x / squares_y)"
        return f"blurred (edges {detection.blur:.1f} px wide)" if blurred else "no board found"
    if n < min_corners:
        return f"only {n} corners"
    if cv2.aruco.testCharucoCornersCollinear(board, np.asarray(detection.ids, np.int32).reshape(-1, 1)):
        return "corners on one line"
    if blurred:
        return f"blurred (edges {detection.blur:.1f} px wide)"
    return None


def calibrate(detections: dict, image_size, spec, flags: int = 0, min_views: int = MIN_VIEWS,
              reject_outliers: bool = True, min_corners: int = MIN_CORNERS,
              max_blur: float = MAX_BLUR_SIGMA) -> Calibration:
    """Calibrate from ``{view name: Detection}`` of images of ``image_size`` (w, h)."""
    cv2 = _cv2()
    board = spec.board()
    rejected, views = {}, {}
    for name, det in detections.items():
        problem = view_problem(board, det, min_corners, max_blur)
        if problem:
            rejected[name] = problem
        else:
            views[name] = board_points(board, det)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS,) + CALIB_CRITERIA[1:]
    size = (int(image_size[0]), int(image_size[1]))
    while True:
        if len(views) < min_views:
            raise CaptureError(_too_few(len(detections), len(views), min_views, rejected))
        names = list(views)
        obj = [views[n][0] for n in names]
        img = [views[n][1] for n in names]
        rms, k, dist, rvecs, tvecs, std, _, per_view = cv2.calibrateCameraExtended(
            obj, img, size, None, None, flags=flags, criteria=crit)
        per_view = np.asarray(per_view, np.float64).ravel()
        if not (np.isfinite(rms) and np.all(np.isfinite(k))):
            raise CaptureError("The calibration did not converge: the views may show the board "
                               "from too similar directions")
        limit = max(OUTLIER_FACTOR * float(np.median(per_view)), OUTLIER_FLOOR_PX)
        worst = int(np.argmax(per_view))
        if reject_outliers and per_view[worst] > limit and len(views) > min_views:
            rejected[names[worst]] = f"reprojection error {per_view[worst]:.2f} px (outlier)"
            del views[names[worst]]
            continue
        break
    return Calibration(np.asarray(k, np.float64), np.asarray(dist, np.float64).ravel(), size,
                       float(rms), np.asarray(std, np.float64).ravel(),
                       dict(zip(names, per_view.tolist())), rejected,
                       [np.asarray(r).ravel() for r in rvecs], [np.asarray(t).ravel() for t in tvecs])


def _reason_kind(reason: str) -> str:
    """A rejection reason without its per-view figures (to count them)."""
    if "not on this board" in reason:
        return "show markers that are not on this board (check squares_x / squares_y and the dictionary)"
    if reason.startswith("only "):
        return "with too few corners"
    if reason.startswith("blurred"):
        return "blurred"
    if reason.startswith("reprojection error"):
        return "outliers"
    return reason


def _too_few(n_images, n_views, min_views, rejected) -> str:
    reasons = {}
    for r in rejected.values():
        key = _reason_kind(r)
        reasons[key] = reasons.get(key, 0) + 1
    why = ", ".join(f"{c} {r}" for r, c in sorted(reasons.items(), key=lambda x: -x[1]))
    if n_views == 0 and rejected and all(r == "no board found" for r in rejected.values()):
        return f"No board found in any of the {n_images} images"
    return (f"Too few usable views of the board: {n_views} of {n_images} images "
            f"(at least {min_views} needed){'; ' + why if why else ''}")


# ------------------------------------------------------------------------------------------
# FileStorage
# ------------------------------------------------------------------------------------------

def _storage_format(path):
    ext = os.path.splitext(path)[1].lower()
    if ext not in {".yml", ".yaml", ".xml", ".json"}:
        raise CaptureError(f"'{os.path.basename(path)}': the calibration file must end in .yml, "
                           f".yaml, .xml or .json (OpenCV FileStorage)")
    return ext


def write_calibration(path: str, calib: Calibration):
    """The seed's nodes (plus the std deviations and the views used, for the record)."""
    cv2 = _cv2()
    _storage_format(path)
    fs = cv2.FileStorage(path, cv2.FILE_STORAGE_WRITE)
    if not fs.isOpened():
        raise CaptureError(f"Cannot write '{path}'")
    try:
        fs.write("Camera_Matrix", np.asarray(calib.camera_matrix, np.float64))
        fs.write("Distortion_Coefficients", np.asarray(calib.dist_coeffs, np.float64).reshape(1, -1))
        fs.startWriteStruct("Image_Size", cv2.FileNode_SEQ | cv2.FileNode_FLOW)
        fs.write("", int(calib.image_size[0]))
        fs.write("", int(calib.image_size[1]))
        fs.endWriteStruct()
        fs.write("Root_Mean_Square", float(calib.rms))
        if len(calib.std):
            fs.write("Intrinsics_Standard_Deviations", np.asarray(calib.std, np.float64).reshape(1, -1))
        fs.write("Views_Used", int(len(calib.view_rms)))
    finally:
        fs.release()


def read_calibration(path: str) -> Calibration:
    cv2 = _cv2()
    _storage_format(path)
    if not os.path.isfile(path):
        raise CaptureError(f"Calibration file '{path}' not found")
    fs = cv2.FileStorage(path, cv2.FILE_STORAGE_READ)
    try:
        if not fs.isOpened():
            raise CaptureError(f"'{os.path.basename(path)}' is not an OpenCV FileStorage file")
        k = fs.getNode("Camera_Matrix").mat()
        d = fs.getNode("Distortion_Coefficients").mat()
        node = fs.getNode("Image_Size")
        if node.isSeq():
            size = tuple(int(node.at(i).real()) for i in range(node.size()))
        elif not node.empty():
            size = tuple(int(x) for x in np.asarray(node.mat()).ravel())
        else:
            size = ()
        rms_node = fs.getNode("Root_Mean_Square")
        rms = float(rms_node.real()) if not rms_node.empty() else float("nan")
    finally:
        fs.release()
    if k is None or np.shape(k) != (3, 3) or len(size) != 2:
        raise CaptureError(f"'{os.path.basename(path)}' lacks Camera_Matrix (3x3) or Image_Size")
    dist = np.zeros(5) if d is None else np.asarray(d, np.float64).ravel()
    return Calibration(np.asarray(k, np.float64), dist, size, rms)


# ------------------------------------------------------------------------------------------
# K <-> Blender camera
# ------------------------------------------------------------------------------------------

@dataclass
class BlenderCamera:
    """What of a Blender camera and render settings makes its K (lengths in mm)."""

    lens: float
    sensor_width: float
    sensor_height: float
    sensor_fit: str            # 'AUTO', 'HORIZONTAL', 'VERTICAL'
    shift_x: float
    shift_y: float
    width: int                 # render pixels, percentage applied
    height: int
    pixel_aspect_x: float = 1.0
    pixel_aspect_y: float = 1.0


def _fit(cam: BlenderCamera):
    """(horizontal?, sensor size, viewfac, ycor) as BKE_camera_params_compute_viewplane."""
    ycor = cam.pixel_aspect_y / cam.pixel_aspect_x
    fit = cam.sensor_fit
    if fit == "AUTO":
        horizontal = cam.pixel_aspect_x * cam.width >= cam.pixel_aspect_y * cam.height
        sensor = cam.sensor_width
    else:
        horizontal = fit == "HORIZONTAL"
        sensor = cam.sensor_width if horizontal else cam.sensor_height
    viewfac = cam.width if horizontal else ycor * cam.height
    return horizontal, sensor, viewfac, ycor


def camera_matrix(cam: BlenderCamera) -> np.ndarray:
    """K (OpenCV pixel convention) of a perspective Blender camera."""
    _, sensor, viewfac, ycor = _fit(cam)
    fx = cam.lens * viewfac / sensor
    return np.array([[fx, 0.0, cam.width / 2 - 0.5 - cam.shift_x * viewfac],
                     [0.0, fx / ycor, cam.height / 2 - 0.5 + cam.shift_y * viewfac / ycor],
                     [0.0, 0.0, 1.0]])


def blender_camera(k, width: int, height: int, sensor_width: float = 36.0,
                   sensor_height: float = 24.0) -> BlenderCamera:
    """The Blender camera (horizontal sensor fit, the given sensor width) whose K is ``k`` at
    ``width`` x ``height``; unequal fx, fy become a pixel aspect (Blender's are >= 1)."""
    k = np.asarray(k, np.float64)
    fx, fy, cx, cy = k[0, 0], k[1, 1], k[0, 2], k[1, 2]
    if not (np.isfinite([fx, fy, cx, cy]).all() and fx > 0 and fy > 0):
        raise CaptureError("The camera matrix has no positive focal lengths")
    if abs(k[0, 1]) > 1e-6 * fx:
        raise CaptureError("The camera matrix has a skew, which Blender cameras cannot show")
    ycor = fx / fy                       # fy = fx / ycor
    ax, ay = (1.0, ycor) if ycor >= 1.0 else (1.0 / ycor, 1.0)
    viewfac = float(width)
    return BlenderCamera(lens=fx * sensor_width / viewfac, sensor_width=sensor_width,
                         sensor_height=sensor_height, sensor_fit="HORIZONTAL",
                         shift_x=(width / 2 - 0.5 - cx) / viewfac,
                         shift_y=(cy - height / 2 + 0.5) * ycor / viewfac,
                         width=int(width), height=int(height), pixel_aspect_x=ax, pixel_aspect_y=ay)


def scale_camera_matrix(k, from_size, to_size) -> np.ndarray:
    """K of the same camera for images resized from ``from_size`` to ``to_size`` (w, h)."""
    k = np.asarray(k, np.float64).copy()
    sx = to_size[0] / from_size[0]
    sy = to_size[1] / from_size[1]
    k[0, 0] *= sx
    k[1, 1] *= sy
    k[0, 2] = (k[0, 2] + 0.5) * sx - 0.5
    k[1, 2] = (k[1, 2] + 0.5) * sy - 0.5
    return k


def max_distortion_px(calib: Calibration, grid: int = 16) -> float:
    """The largest shift (px) the distortion gives a point of the frame (a grid of points)."""
    cv2 = _cv2()
    w, h = calib.image_size
    k = np.asarray(calib.camera_matrix, np.float64)
    yy, xx = np.mgrid[0:h - 1:grid * 1j, 0:w - 1:grid * 1j]
    pix = np.stack([xx.ravel(), yy.ravel(), np.ones(xx.size)], 1)
    rays = pix @ np.linalg.inv(k).T
    d, _ = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), k, np.asarray(calib.dist_coeffs))
    return float(np.abs(d.reshape(-1, 2) - pix[:, :2]).max())


def undistort(image, calib: Calibration) -> np.ndarray:
    """The photo as a distortion-free pinhole camera with the same K would have taken it
    (what a Blender camera set from the calibration renders)."""
    cv2 = _cv2()
    h, w = image.shape[:2]
    if (w, h) != tuple(calib.image_size):
        raise CaptureError(f"The photo is {w} x {h}, the calibration is for "
                           f"{calib.image_size[0]} x {calib.image_size[1]}")
    return cv2.undistort(image, calib.camera_matrix, calib.dist_coeffs, None, calib.camera_matrix)
