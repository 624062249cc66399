# SPDX-License-Identifier: GPL-3.0-or-later
"""Capture operators: the printable ChArUco board, camera calibration, the camera's pose from
the board, HDR merges and environments, photos projected onto the model.

Thin: each reads its inputs, calls the bpy-free core (``relight_addon.core.capture``) through
the bridge (``relight_addon.blender.capture``), and reports one sentence.  Every check that can
fail runs before anything in the scene is changed, so bad input (``CaptureError``) is reported
as an ERROR and leaves the scene as it was.
"""

import os
import threading

import bpy
from bpy.props import (BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty,
                       StringProperty)

from .base import RelightOperator
from .precompute import JobRunner

# cv2.aruco's predefined dictionaries (OpenCV 4.11), listed here so that registering the
# add-on does not import OpenCV; tests check the list against cv2.aruco.
DICTIONARIES = (
    "DICT_4X4_50", "DICT_4X4_100", "DICT_4X4_250", "DICT_4X4_1000",
    "DICT_5X5_50", "DICT_5X5_100", "DICT_5X5_250", "DICT_5X5_1000",
    "DICT_6X6_50", "DICT_6X6_100", "DICT_6X6_250", "DICT_6X6_1000",
    "DICT_7X7_50", "DICT_7X7_100", "DICT_7X7_250", "DICT_7X7_1000",
    "DICT_ARUCO_ORIGINAL", "DICT_ARUCO_MIP_36h12",
    "DICT_APRILTAG_16h5", "DICT_APRILTAG_25h9", "DICT_APRILTAG_36h10", "DICT_APRILTAG_36h11",
)
DICTIONARY_ITEMS = tuple((d, d, f"cv2.aruco.{d}") for d in DICTIONARIES)
PAPER_ITEMS = tuple((p, p.title() if len(p) > 2 else p, f"{p} paper")
                    for p in ("A5", "A4", "A3", "A2", "A1", "A0", "LETTER", "LEGAL", "TABLOID"))


def _core():
    from ..relight_addon.core import capture
    from ..relight_addon.core.capture import board, calibration, pose
    return capture, board, calibration, pose


def _bridge():
    from ..relight_addon.blender import capture as bridge
    return bridge


def _abs(path):
    return os.path.abspath(bpy.path.abspath(path)) if path else ""


class _BoardOperator(RelightOperator):
    """Shared: the board's arguments, its spec, and failure reports."""

    squares_x: IntProperty(name="Squares X", default=7, min=2, max=100,
                           description="Squares across the board")
    squares_y: IntProperty(name="Squares Y", default=5, min=2, max=100,
                           description="Squares down the board")
    square_length: FloatProperty(name="Square", default=0.035, min=1e-4, max=10.0,
                                 subtype="DISTANCE", unit="LENGTH", precision=4,
                                 description="Side of a chessboard square (metres)")
    marker_length: FloatProperty(name="Marker", default=0.026, min=1e-4, max=10.0,
                                 subtype="DISTANCE", unit="LENGTH", precision=4,
                                 description="Side of an ArUco marker (metres)")
    dictionary: EnumProperty(name="Dictionary", items=DICTIONARY_ITEMS, default="DICT_5X5_100",
                             description="cv2.aruco predefined dictionary of the markers")

    def spec(self):
        _, board, _, _ = _core()
        return board.BoardSpec(int(self.squares_x), int(self.squares_y), float(self.square_length),
                               float(self.marker_length), str(self.dictionary)).validate()

    def fail(self, message):
        self.report({'ERROR'}, message)
        return {'CANCELLED'}


# ------------------------------------------------------------------------------------------
# calibration_board
# ------------------------------------------------------------------------------------------

class RELIGHT_OT_calibration_board(_BoardOperator, bpy.types.Operator):
    """Write a printable ChArUco board: a PNG of the board alone (its print resolution makes a
    square its size; import it with "Images as Planes" for the board object) and a PDF page
    with the board at scale 1 and its sizes printed under it"""

    bl_idname = "relight.calibration_board"
    bl_label = "Calibration Board"
    bl_options = {'REGISTER'}

    filepath: StringProperty(name="File", subtype="FILE_PATH",
                             description="PNG (and PDF beside it, same name) to write")
    paper: EnumProperty(name="Paper", items=PAPER_ITEMS, default="A4",
                        description="Paper size of the PDF page")
    filter_glob: StringProperty(default="*.png;*.pdf", options={'HIDDEN'})

    def invoke(self, context, event):
        if not self.filepath:
            self.filepath = "charuco_board.png"
        context.window_manager.fileselect_add(self)
        return {'RUNNING_MODAL'}

    def execute(self, context):
        capture, board, _, _ = _core()
        path = _abs(self.filepath)
        if not path:
            return self.fail("No file given for the board")
        stem, ext = os.path.splitext(path)
        if ext.lower() not in (".png", ".pdf", ""):
            return self.fail(f"The board file must be a .png or .pdf, not '{ext}'")
        png, pdf = stem + ".png", stem + ".pdf"
        if not os.path.isdir(os.path.dirname(png)):
            return self.fail(f"The folder '{os.path.dirname(png)}' does not exist")
        try:
            spec = self.spec()
            layout = board.page_layout(spec, self.paper)      # fails before writing anything
            info = board.write_png(spec, png)
            try:
                board.write_pdf(spec, pdf, self.paper)
            except Exception:
                os.remove(png)                              # both files or neither
                raise
        except capture.CaptureError as ex:
            return self.fail(str(ex))
        except OSError as ex:
            return self.fail(f"Cannot write the board: {ex.strerror or ex}")
        w, h = (1000 * s for s in spec.size)
        self.report({'INFO'}, f"Wrote the {spec.describe()} ({w:.0f} x {h:.0f} mm) to "
                              f"{os.path.basename(png)} ({info['dpi']:.0f} dpi) and "
                              f"{os.path.basename(pdf)} ({layout['paper']}"
                              f"{' landscape' if layout['landscape'] else ''})")
        return {'FINISHED'}


class _CaptureRunner(JobRunner):
    """An operator whose work is a capture job (``job_class(op, context)``: every check and
    what must be written before the work, ``compute(progress)`` bpy-free, ``finish(context,
    result)`` writing and returning the report, ``abandon()`` undoing what ``__init__`` wrote)
    run by JobRunner: synchronously from a script, in a worker thread with Esc in the UI."""

    job_class = None

    def _prepare(self, context, *args):
        capture = _core()[0]
        try:
            return self.job_class(self, context)
        except capture.CaptureError as ex:
            self.report({'ERROR'}, str(ex))
        except ImportError as ex:            # xatlas for an unwrap, OpenCV for the rest
            self.report({'ERROR'}, f"{ex.name or 'A library'} is not available: check the "
                                   "Relight dependencies")
        return None

    def _abandon(self, context, job):
        job.abandon()

    def _finish(self, context, job, result):
        self.report({'INFO'}, job.finish(context, result))
        return {'FINISHED'}


# ------------------------------------------------------------------------------------------
# calibrate_camera
# ------------------------------------------------------------------------------------------

DISTORTION_ITEMS = (
    ("K1K2P1P2", "k1 k2 p1 p2", "Radial k1, k2 and tangential p1, p2 (k3 fixed at 0): most lenses"),
    ("K1K2P1P2K3", "k1 k2 p1 p2 k3", "Radial k1, k2, k3 and tangential p1, p2 (wide lenses)"),
    ("K1K2", "k1 k2", "Radial k1, k2 only"),
    ("NONE", "None", "A pinhole camera without distortion"),
)


def _distortion_flags(cv2, model):
    fix_k3 = cv2.CALIB_FIX_K3
    return {"K1K2P1P2": fix_k3, "K1K2P1P2K3": 0,
            "K1K2": fix_k3 | cv2.CALIB_ZERO_TANGENT_DIST,
            "NONE": fix_k3 | cv2.CALIB_FIX_K1 | cv2.CALIB_FIX_K2 | cv2.CALIB_ZERO_TANGENT_DIST}[model]


def detect_folder(directory, spec, report_progress=None):
    """{photo path: Detection} of every image of a folder, and their common size (w, h).
    ``report_progress(fraction, photos done, photos)`` after each photo."""
    capture, board, calibration, _ = _core()
    paths = calibration.list_images(directory)
    det = board.Detector(spec)
    out, size = {}, None
    for i, path in enumerate(paths):
        img = calibration.read_image(path)
        s = (img.shape[1], img.shape[0])
        if size is None:
            size = s
        elif s != size:
            raise capture.CaptureError(
                f"The photos have different sizes: {os.path.basename(paths[0])} is "
                f"{size[0]} x {size[1]}, {os.path.basename(path)} is {s[0]} x {s[1]}")
        out[path] = det.detect(img)
        if report_progress:
            report_progress((i + 1) / len(paths), i + 1, len(paths))
    return out, size


class RELIGHT_OT_calibrate_camera(_CaptureRunner, _BoardOperator, bpy.types.Operator):
    """Calibrate the camera from photos of the ChArUco board in a folder: write the intrinsics
    and distortion as an OpenCV FileStorage file (YAML or XML) and set the active camera's
    lens, sensor fit and shift and the scene's resolution so that its K is the one measured.
    Blender renders without distortion: use undistorted photos (written on request) as
    backgrounds, or the distortion in the file for movie-clip tracking (interactively in a
    worker thread, with progress in the status bar and Esc to cancel)"""

    bl_idname = "relight.calibrate_camera"
    bl_label = "Calibrate Camera"
    bl_options = {'REGISTER', 'UNDO'}
    _kind = "camera calibration"

    directory: StringProperty(name="Photos", subtype="DIR_PATH",
                              description="Folder of photos of the board")
    output: StringProperty(name="Calibration File", subtype="FILE_PATH",
                           description="FileStorage file to write (.yml, .yaml, .xml)")
    distortion: EnumProperty(name="Distortion", items=DISTORTION_ITEMS, default="K1K2P1P2",
                             description="Distortion coefficients to fit")
    undistorted_directory: StringProperty(
        name="Undistorted Photos", subtype="DIR_PATH", default="",
        description="If set, write the photos without their distortion here (what the "
                    "Blender camera sees: use them as background images)")
    set_camera: BoolProperty(name="Set Active Camera", default=True,
                             description="Give the active camera the calibrated K")

    @property
    def job_class(self):
        return CalibrationJob


class CalibrationJob:
    """Calibrate Camera's inputs checked (``__init__``, main thread), the board found in every
    photo, the calibration solved and its files written (``compute``, bpy-free, any thread:
    the undistorted photos first, the calibration file last, so that a cancelled or failed run
    leaves no file of its own), the camera set (``finish``, main thread)."""

    label = "camera calibration"
    action = "calibrate"

    def __init__(self, op, context):
        import cv2
        capture, _, calibration, _ = _core()
        self.directory, self.output = _abs(op.directory), _abs(op.output)
        if not self.output:
            raise capture.CaptureError("No calibration file given (output)")
        calibration._storage_format(self.output)
        if not os.path.isdir(os.path.dirname(self.output)):
            raise capture.CaptureError(f"The folder of '{self.output}' does not exist")
        self.undistorted = _abs(op.undistorted_directory)
        if self.undistorted and not os.path.isdir(self.undistorted):
            raise capture.CaptureError(
                f"The folder '{self.undistorted}' for undistorted photos does not exist")
        self.spec = op.spec()
        self.flags = _distortion_flags(cv2, op.distortion)
        self.set_camera = op.set_camera
        self._lock = threading.Lock()
        self._written, self._abandoned = [], False

    def _wrote(self, path):
        """Keep ``path`` for abandon; remove it at once when abandon came first."""
        with self._lock:
            if self._abandoned:
                os.remove(path)
            else:
                self._written.append(path)

    def compute(self, progress=None):
        """{calib, size}; raises CaptureError when the photos cannot calibrate."""
        import cv2
        _, _, calibration, _ = _core()
        report = progress or (lambda f, m: None)
        dets, size = detect_folder(self.directory, self.spec, lambda f, i, n: report(
            0.8 * f, f"Finding the board in photo {i} of {n}"))
        report(0.8, f"Calibrating from {len(dets)} photos")
        calib = calibration.calibrate(dets, size, self.spec, flags=self.flags)
        calib.view_rms = {os.path.basename(k): v for k, v in calib.view_rms.items()}
        calib.rejected = {os.path.basename(k): v for k, v in calib.rejected.items()}
        if self.undistorted:
            for i, path in enumerate(dets):
                report(0.9 + 0.1 * i / len(dets), f"Writing undistorted photo {i + 1} of "
                                                  f"{len(dets)}")
                out = os.path.join(self.undistorted, os.path.basename(path))
                cv2.imwrite(out, calibration.undistort(calibration.read_image(path), calib))
                self._wrote(out)
        report(1.0, "Writing the calibration")
        calibration.write_calibration(self.output, calib)
        return dict(calib=calib, size=size)

    def abandon(self):
        """Remove the undistorted photos this run wrote (the calibration file comes last)."""
        with self._lock:
            self._abandoned = True
            written, self._written = self._written, []
        for path in written:
            if os.path.exists(path):
                os.remove(path)

    def finish(self, context, out):
        """Set the active camera; the report."""
        _, _, calibration, _ = _core()
        calib, size = out["calib"], out["size"]
        camera = context.scene.camera
        cam_text = "no active camera to set"
        if self.set_camera and camera is not None and camera.type == "CAMERA":
            cam = _bridge().set_intrinsics(camera, context.scene, calib.camera_matrix, size)
            cam_text = (f"'{camera.name}' set to {cam.lens:.2f} mm on {cam.sensor_width:g} mm, "
                        f"shift ({cam.shift_x:.4f}, {cam.shift_y:.4f}), {size[0]} x {size[1]}")
        elif not self.set_camera:
            cam_text = "camera left alone"
        d = calib.dist_coeffs
        shift = calibration.max_distortion_px(calib)
        if self.undistorted:
            dist_text = f"the photos without it ({shift:.1f} px at most) written for backgrounds"
        elif shift > 0.5:
            dist_text = (f"Blender renders without it ({shift:.1f} px at most): set Undistorted "
                         f"Photos for backgrounds")
        else:
            dist_text = f"under {shift:.1f} px"
        return (f"Calibrated from {calib.summary()}; distortion k1 {d[0]:.4f}, k2 {d[1]:.4f}, "
                f"{dist_text}; wrote {os.path.basename(self.output)}; {cam_text}")


# ------------------------------------------------------------------------------------------
# camera_from_marker
# ------------------------------------------------------------------------------------------

MOVIE_EXTENSIONS = (".mp4", ".mov", ".avi", ".mkv", ".webm", ".m4v", ".mpg", ".mpeg")


def _frames(path):
    """(names, images) of a photo, a folder of photos or a movie (images as read by OpenCV)."""
    import cv2
    capture, _, calibration, _ = _core()
    if os.path.isdir(path):
        paths = calibration.list_images(path)
        return [os.path.basename(p) for p in paths], (calibration.read_image(p) for p in paths), \
            len(paths), paths
    if not os.path.isfile(path):
        raise capture.CaptureError(f"'{path}' is neither a photo, a folder nor a movie")
    if os.path.splitext(path)[1].lower() in MOVIE_EXTENSIONS:
        cap = cv2.VideoCapture(path)
        if not cap.isOpened():
            raise capture.CaptureError(f"OpenCV cannot open the movie '{os.path.basename(path)}'")
        n = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))

        def gen():
            try:
                while True:
                    ok, frame = cap.read()
                    if not ok:
                        return
                    yield frame
            finally:
                cap.release()
        return None, gen(), n, None
    return [os.path.basename(path)], iter([calibration.read_image(path)]), 1, [path]


class RELIGHT_OT_camera_from_marker(_CaptureRunner, _BoardOperator, bpy.types.Operator):
    """Pose the active camera so that the board object is seen as in the photo (the board's
    pose from its ChArUco corners and the calibration).  On a folder or a movie, one key per
    frame, outliers rejected and the path smoothed by quaternion slerp (interactively in a
    worker thread, with progress in the status bar and Esc to cancel)"""

    bl_idname = "relight.camera_from_marker"
    bl_label = "Camera from Marker"
    bl_options = {'REGISTER', 'UNDO'}
    _kind = "camera pose"

    filepath: StringProperty(name="Photo", subtype="FILE_PATH",
                             description="A photo, a folder of frames or a movie")
    calibration: StringProperty(name="Calibration", subtype="FILE_PATH",
                                description="FileStorage file of calibrate_camera")
    board_object: StringProperty(name="Board Object",
                                 description="Plane of the board's size (Images as Planes "
                                             "of the board PNG)")
    set_intrinsics: BoolProperty(name="Set Intrinsics", default=True,
                                 description="Also give the camera the calibration's K")
    background: BoolProperty(name="Photo as Background", default=True,
                             description="A single photo becomes the camera's background "
                                         "image")
    smoothing: FloatProperty(name="Smoothing", default=0.25, min=0.0, max=0.95,
                             description="Sequence smoothing by slerp (0: none; outliers are "
                                         "rejected either way).  It lags on fast moves: on a "
                                         "path of 3 cm a frame, 0.3 cut the rotation noise by a "
                                         "tenth and cost 0.7 mm")
    frame_start: IntProperty(name="First Frame", default=-1,
                             description="Frame of the sequence's first image (-1: the "
                                         "scene's start)")

    @classmethod
    def disabled_reason(cls, context):
        reason = super().disabled_reason(context)
        if reason:
            return reason
        cam = context.scene.camera
        if cam is None or cam.type != "CAMERA":
            return "The scene has no active camera"
        return None

    @property
    def job_class(self):
        return MarkerJob


class MarkerJob:
    """Camera from Marker's inputs (``__init__``, main thread: every check that needs no frame),
    the board found in every frame and the path smoothed (``compute``, bpy-free, any thread),
    the camera written (``finish``, main thread)."""

    label = "camera pose"
    action = "pose"

    def __init__(self, op, context):
        capture, board, calibration, pose = _core()
        bridge = _bridge()
        scene = context.scene
        camera = scene.camera
        if camera is None or camera.type != "CAMERA":
            raise capture.CaptureError("The scene has no active camera")
        self.camera_name = camera.name
        self.spec = op.spec()
        obj = bpy.data.objects.get(op.board_object)
        if obj is None:
            raise capture.CaptureError(f"No object named '{op.board_object}' (the board)")
        lo, hi = bridge.board_bounds(obj)
        self.frame = pose.board_frame(bridge.matrix_of(obj), lo, hi, self.spec.size)
        self.calib = calibration.read_calibration(_abs(op.calibration))
        self.names, self.images, self.count, self.paths = _frames(_abs(op.filepath))
        self.set_intrinsics, self.background = op.set_intrinsics, op.background
        self.smoothing = op.smoothing
        self.start = scene.frame_start if op.frame_start < 0 else op.frame_start

    def compute(self, progress=None):
        """{poses, mats, rejected, size}; raises CaptureError on frames it cannot use."""
        import numpy as np
        capture, board, _, pose = _core()
        det = board.Detector(self.spec)
        calib = self.calib
        poses, problems, size = [], {}, None
        for i, img in enumerate(self.images):
            if progress is not None:
                progress(i / max(self.count, i + 1),
                         f"Finding the board in frame {i + 1} of {max(self.count, i + 1)}")
            s = (img.shape[1], img.shape[0])
            if size is None:
                size = s
            elif s != size:
                raise capture.CaptureError(f"The frames have different sizes ({size[0]} x "
                                           f"{size[1]} and {s[0]} x {s[1]})")
            name = self.names[i] if self.names else f"frame {i}"
            d = det.detect(img)
            try:
                poses.append(pose.board_pose(d, self.spec, calib.camera_matrix,
                                             calib.dist_coeffs))
            except capture.CaptureError as ex:
                poses.append(None)
                problems[name] = str(ex)
        if size is None:
            raise capture.CaptureError("No frame could be read")
        if tuple(size) != tuple(calib.image_size):
            raise capture.CaptureError(
                f"The photo is {size[0]} x {size[1]} but the calibration is for "
                f"{calib.image_size[0]} x {calib.image_size[1]}")
        if len(poses) == 1 and poses[0] is None:
            raise capture.CaptureError(f"No board pose in the photo: {problems.popitem()[1]}")
        valid = [p is not None for p in poses]
        if not any(valid):
            raise capture.CaptureError(f"No board found in any of the {len(poses)} frames")
        mats = np.stack([pose.camera_world_matrix(self.frame, p) if p is not None else np.eye(4)
                         for p in poses])
        rejected = np.zeros(len(poses), bool)
        if len(poses) > 1:
            mats, rejected = pose.smooth_path(mats, np.array(valid), self.smoothing)
        return dict(poses=poses, mats=mats, rejected=rejected, size=size)

    def abandon(self):
        """Nothing is written before :meth:`finish`."""

    def finish(self, context, out):
        """Write the camera (intrinsics, pose or keys, background photo); the report."""
        import numpy as np
        bridge = _bridge()
        scene = context.scene
        camera = bpy.data.objects[self.camera_name]
        poses, mats, rejected = out["poses"], out["mats"], out["rejected"]
        if self.set_intrinsics:
            bridge.set_intrinsics(camera, scene, self.calib.camera_matrix, out["size"])
        if len(poses) == 1:
            bridge.set_matrix_world(camera, mats[0])
            if self.background and self.paths:
                bridge.set_camera_photo(camera, self.paths[0])
            p = poses[0]
            dist = float(np.linalg.norm(p.t))
            return (f"Posed '{camera.name}' from {p.n} board corners (RMS {p.rms:.3f} px, board "
                    f"{dist:.2f} m away)")
        frames = np.arange(len(poses)) + self.start
        bridge.key_path(camera, mats, frames)
        used = [p for p in poses if p is not None]
        rms = float(np.median([p.rms for p in used]))
        return (f"Keyed '{camera.name}' on frames {frames[0]}-{frames[-1]}: "
                f"{len(used) - int(rejected.sum())} poses used, {len(poses) - len(used)} frames "
                f"without a board, {int(rejected.sum())} rejected as outliers, filled by slerp "
                f"(median RMS {rms:.3f} px)")


# ------------------------------------------------------------------------------------------
# merge_hdr
# ------------------------------------------------------------------------------------------

RESPONSE_ITEMS = (
    ("DEBEVEC", "Debevec", "Response by Debevec & Malik (OpenCV CalibrateDebevec), merged by "
                           "inverse quantisation variance"),
    ("ROBERTSON", "Robertson", "Response and merge by Robertson et al. (OpenCV)"),
)
ENVIRONMENT_ITEMS = (
    ("NONE", "Photo", "Merge the brackets into an HDR photo of the same size"),
    ("MIRROR_BALL", "Mirror Ball", "The brackets (or one EXR) show a mirror ball: write the "
                                   "environment it reflects as an equirect"),
    ("FRAMES", "Posed Frames", "The scene's cameras with their photos as background images: "
                               "write the environment they see (at infinity) as an equirect"),
)
FLOAT_EXTENSIONS = (".exr", ".hdr")


class RELIGHT_OT_merge_hdr(_CaptureRunner, bpy.types.Operator):
    """Merge bracketed 8-bit photos (exposure times from EXIF or exposures.json) into a linear
    HDR OpenEXR with the recovered camera response; or write an environment map (equirect
    OpenEXR for the World) from a mirror-ball photo or from the scene's posed frames
    (interactively in a worker thread, with progress in the status bar and Esc to cancel)"""

    bl_idname = "relight.merge_hdr"
    bl_label = "Merge HDR"
    bl_options = {'REGISTER', 'UNDO'}
    _kind = "HDR merge"

    directory: StringProperty(name="Brackets", subtype="DIR_PATH",
                              description="Folder of bracketed photos (and exposures.json)")
    output: StringProperty(name="Output", subtype="FILE_PATH", description="OpenEXR to write")
    method: EnumProperty(name="Response", items=RESPONSE_ITEMS, default="DEBEVEC")
    environment: EnumProperty(name="Result", items=ENVIRONMENT_ITEMS, default="NONE")
    width: IntProperty(name="Equirect Width", default=1024, min=16, max=16384,
                       description="Width of the environment map (height: half)")
    ball_x: FloatProperty(name="Ball X", default=-1.0,
                          description="Ball centre in the photo (px from the left; < 0: the "
                                      "photo's centre)")
    ball_y: FloatProperty(name="Ball Y", default=-1.0,
                          description="Ball centre in the photo (px from the top; < 0: the "
                                      "photo's centre)")
    ball_radius: FloatProperty(name="Ball Radius", default=-1.0,
                               description="Ball radius in the photo (px; <= 0: the photo's "
                                           "inscribed circle)")
    set_world: BoolProperty(name="Set World", default=True,
                            description="An environment becomes the World's Environment "
                                        "Texture")

    @property
    def job_class(self):
        return MergeJob


class MergeJob:
    """Merge HDR's inputs (``__init__``, main thread: the checks, and what only Blender reads:
    the posed frames' photos, a mirror ball's EXR, the camera's rotation), the merge and the
    equirect (``compute``, bpy-free, any thread), the EXR written and the World set
    (``finish``, main thread: nothing is written before it)."""

    label = "HDR merge"
    action = "merge"

    def __init__(self, op, context):
        import numpy as np
        capture, _, calibration, _ = _core()
        bridge = _bridge()
        self.output = _abs(op.output)
        if os.path.splitext(self.output)[1].lower() != ".exr":
            raise capture.CaptureError("The output must be an OpenEXR file (.exr)")
        if not os.path.isdir(os.path.dirname(self.output)):
            raise capture.CaptureError(f"The folder of '{self.output}' does not exist")
        self.environment, self.method, self.width = op.environment, op.method, op.width
        self.set_world = op.set_world
        self.ball = (op.ball_x, op.ball_y, op.ball_radius)
        self.directory = _abs(op.directory)
        self.frames = self.skipped = self.float_photo = self.rotation = None
        self.camera_name = None
        if self.environment == "FRAMES":
            self.frames, self.skipped = _posed_frames(context)
            return
        paths = calibration.list_images(self.directory)
        floats = [p for p in paths if os.path.splitext(p)[1].lower() in FLOAT_EXTENSIONS]
        if self.environment == "MIRROR_BALL" and len(paths) == 1 and floats:
            self.float_photo = (bridge.read_float_image(floats[0]), os.path.basename(floats[0]))
        elif floats:
            raise capture.CaptureError(f"'{os.path.basename(floats[0])}' is already HDR: the "
                                       f"merge takes 8-bit brackets")
        cam = context.scene.camera
        if self.environment == "MIRROR_BALL" and cam is not None:
            m = bridge.matrix_of(cam)
            self.rotation = m[:3, :3] / np.linalg.norm(m[:3, :3], axis=0)
            self.camera_name = cam.name

    def _hdr_photo(self, report):
        """(radiance RGB float32, sentence) of the folder: brackets merged, or its one EXR."""
        from ..relight_addon.core.capture import hdr
        if self.float_photo is not None:
            return self.float_photo
        report(0.0, "Reading the brackets")
        names, images, times = hdr.read_brackets(self.directory)
        report(0.2, f"Recovering the camera response from {len(images)} brackets")
        response = hdr.recover_response(images, times, self.method)
        report(0.6, "Merging the brackets")
        if self.method == "DEBEVEC":
            res = hdr.merge(images, times, response)
        else:
            res = {"radiance": hdr.merge_opencv(images, times, response, "ROBERTSON"),
                   "saturated": 0.0}
        rad = res["radiance"]
        text = (f"{len(images)} brackets ({_seconds(times[0])}-{_seconds(times[-1])}, "
                f"{self.method.title()} response), {hdr.dynamic_range_stops(rad):.1f} stops"
                + (f", {100 * res['saturated']:.1f} % saturated in every bracket"
                   if res.get("saturated") else ""))
        return rad, text

    def compute(self, progress=None):
        """(the image to write, the sentence); raises CaptureError."""
        from ..relight_addon.core.capture import hdr
        report = progress or (lambda f, m: None)
        if self.environment == "FRAMES":
            env, seen = hdr.frames_to_equirect(self.frames, self.width, progress=lambda f, m:
                                               report(0.95 * f, f"Equirect: {m}"))
            return env, (f"Wrote the environment seen by {len(self.frames)} posed frames"
                         + (f" ({len(self.skipped)} cameras without a photo skipped)"
                            if self.skipped else "")
                         + f" ({100 * seen.mean():.1f} % of directions seen, the rest filled "
                           f"from neighbours)")
        rad, text = self._hdr_photo(report)
        if self.environment != "MIRROR_BALL":
            return rad, f"Merged {text}"
        report(0.85, "Unwrapping the mirror ball")
        h, w = rad.shape[:2]
        bx, by, br = self.ball
        centre = (bx if bx >= 0 else (w - 1) / 2, by if by >= 0 else (h - 1) / 2)
        env, _ = hdr.mirror_ball_to_equirect(rad, self.width, centre, br if br > 0 else None,
                                             self.rotation)
        return env, (f"Wrote the environment a mirror ball reflects, from {text}"
                     f"{'' if self.camera_name is None else f', oriented by the camera {self.camera_name!r}'}")

    def abandon(self):
        """Nothing is written before :meth:`finish`."""

    def finish(self, context, out):
        """Write the EXR (and set the World); the report."""
        result, text = out
        _bridge().write_exr(self.output, result)
        h, w = result.shape[:2]
        world = ""
        if self.environment != "NONE" and self.set_world:
            _bridge().set_world_environment(context.scene, self.output)
            world = "; set as the World"
        return f"{text}: {w} x {h} EXR {os.path.basename(self.output)}{world}"


def _posed_frames(context):
    """([(K, world rotation, photo RGB)] of the scene's cameras with a background photo, the
    names of those without one)."""
    import numpy as np
    capture, _, _, _ = _core()
    bridge = _bridge()
    scene = context.scene
    frames, skipped = [], []
    for ob in sorted((o for o in scene.objects if o.type == "CAMERA"), key=lambda o: o.name):
        img = bridge.camera_photo(ob)
        if img is None:
            skipped.append(ob.name)
            continue
        rgb = bridge.photo_pixels(img)
        size = (rgb.shape[1], rgb.shape[0])
        if not bridge.frame_matches(scene, size):
            raise capture.CaptureError(f"The photo of '{ob.name}' ({size[0]} x {size[1]}) does "
                                       f"not have the render frame's shape")
        m = bridge.matrix_of(ob)
        rot = m[:3, :3] / np.linalg.norm(m[:3, :3], axis=0)
        frames.append((bridge.camera_K(ob, scene, size), rot, rgb))
    if not frames:
        raise capture.CaptureError("No camera of the scene has a photo as background image")
    return frames, skipped


def _seconds(t):
    return f"1/{1 / t:.0f} s" if t < 0.5 else f"{t:g} s"


# ------------------------------------------------------------------------------------------
# project_photos
# ------------------------------------------------------------------------------------------

class RELIGHT_OT_project_photos(_CaptureRunner, bpy.types.Operator):
    """Texture the selected meshes from the posed photos (the scene's cameras, each with its
    photo as background image; the selected cameras if any are selected): per texel the best
    views by facing, distance and resolution, ray-cast visibility, exposures matched, holes
    filled from their neighbours.  Meshes without UVs get an xatlas atlas ("RelightUV"); each
    gets a new packed image and material (object-linked slots: the mesh keeps its own), which
    Precompute reads as the photo texture.  Interactively it runs in a worker thread with
    progress in the status bar; Esc cancels and leaves the scene as it was"""

    bl_idname = "relight.project_photos"
    bl_label = "Project Photos"
    bl_options = {'REGISTER', 'UNDO'}
    _kind = "projection"

    texture_size: IntProperty(name="Texture Size", default=0, min=0, max=16384,
                              description="Width and height of each mesh's new texture (0: "
                                          "about one texel a photo pixel where the photos see "
                                          "the mesh best, 64-4096)")
    uv_map: StringProperty(name="UV Map", default="",
                           description="UV map to texture (empty: the active render one)")
    match_exposure: BoolProperty(name="Match Exposure", default=True,
                                 description="One gain per photo and channel so that the "
                                             "photos agree where they overlap")
    fill_holes: BoolProperty(name="Fill Holes", default=True,
                             description="Texels no photo sees take the colour of the nearest "
                                         "seen ones")
    supersample: IntProperty(name="Supersample", default=0, min=0, max=4,
                             description="Samples a side per texel (0: from the photo pixels a "
                                         "texel covers)")

    @classmethod
    def disabled_reason(cls, context):
        reason = super().disabled_reason(context)
        if reason:
            return reason
        if not any(o.type == "MESH" for o in (getattr(context, "selected_objects", None) or ())):
            return "Select the meshes to texture"
        return None

    @property
    def job_class(self):
        return ProjectionJob


class ProjectionJob:
    """Project Photos' inputs read from the scene (``__init__``, main thread), the bpy-free
    projection (``compute``, any thread) and its textures written (``finish``, main thread)."""

    label = "projection"
    action = "project"

    def __init__(self, op, context):
        capture = _core()[0]
        from ..relight_addon.core.capture import projection
        from .unwrap import UV_NAME, atlas_loop_uvs
        bridge = _bridge()
        self.uv_map, self.uv_name = op.uv_map, UV_NAME
        self.options = dict(supersample=op.supersample or None, match_exposure=op.match_exposure,
                            fill_holes=op.fill_holes)
        self.meshes = meshes = [o for o in context.selected_objects if o.type == "MESH"]
        if not meshes:
            raise capture.CaptureError("Select the meshes to texture")
        self.views, self.skipped = bridge.posed_views(context.scene, context.selected_objects)
        atlases = {}
        for obj in meshes:
            uv = bridge.uv_layer_name(obj, op.uv_map)
            if op.uv_map and not uv:
                raise capture.CaptureError(f"'{obj.name}' has no UV map '{op.uv_map}'")
            if not uv:
                me = obj.data
                if obj.library or me.library or me.override_library or me.is_editmode:
                    raise capture.CaptureError(f"'{obj.name}' has no UV map and cannot get one "
                                               f"(linked, or in Edit Mode)")
                if not len(me.polygons):
                    raise capture.CaptureError(f"'{obj.name}' has no faces")
                atlases[obj.name] = atlas_loop_uvs(me, obj.matrix_world)[0]
        # -- from here on the scene is written (undone by abandon) --
        self.added = []
        for obj in meshes:
            if obj.name in atlases:
                layer = obj.data.uv_layers.new(name=UV_NAME)
                layer.data.foreach_set("uv", atlases[obj.name].reshape(-1))
                obj.data.update()
                self.added.append((obj.data, layer.name))
        try:
            depsgraph = context.evaluated_depsgraph_get()
            self.targets, self.sizes = [], []
            for obj in meshes:
                tris, uvs = bridge.mesh_triangles(obj, depsgraph, self._uv(obj))
                n = op.texture_size or projection.suggest_texture_size(tris, uvs, self.views)
                self.sizes.append(n)
                self.targets.append(projection.Target(obj.name, tris, uvs, (n, n)))
            self.occluders = bridge.scene_triangles(depsgraph)
        except Exception:
            self.abandon()
            raise

    def _uv(self, obj):
        return _bridge().uv_layer_name(obj, self.uv_map) or self.uv_name

    def abandon(self):
        """Remove the UV maps this job added (a cancelled or failed projection)."""
        for me, name in self.added:
            layer = me.uv_layers.get(name)
            if layer is not None:
                me.uv_layers.remove(layer)
                me.update()
        self.added = []

    def compute(self, progress=None):
        from ..relight_addon.core.capture import projection
        report = None if progress is None else (lambda f: progress(f, "Projecting the photos"))
        return projection.project(self.targets, self.views, *self.occluders, progress=report,
                                  **self.options)

    def finish(self, context, result):
        """Write the textures and materials; the one-sentence report."""
        bridge = _bridge()
        for obj, res in zip(self.meshes, result.meshes):
            img = bridge.image_from_texture(f"{obj.name} Photo", res.texture)
            bridge.photo_material(obj, img, self._uv(obj))
        sizes = self.sizes
        extra = (f"; textures of {min(sizes)}" + (f"-{max(sizes)}" if max(sizes) > min(sizes)
                                                  else "") + " texels a side")
        if self.added:
            extra += f"; {len(self.added)} meshes unwrapped by xatlas"
        if self.skipped:
            extra += f"; {len(self.skipped)} cameras without a photo skipped"
        return result.summary() + extra


# ------------------------------------------------------------------------------------------
# The panel's settings (scene.relight_capture)
# ------------------------------------------------------------------------------------------

def _is_mesh(self, obj):
    return obj.type == "MESH"


class RelightCaptureSettings(bpy.types.PropertyGroup):
    """What the Capture panel passes to the operators (saved with the scene)."""

    squares_x: IntProperty(name="Squares X", default=7, min=2, max=100)
    squares_y: IntProperty(name="Squares Y", default=5, min=2, max=100)
    square_length: FloatProperty(name="Square", default=0.035, min=1e-4, max=10.0,
                                 subtype="DISTANCE", unit="LENGTH", precision=4)
    marker_length: FloatProperty(name="Marker", default=0.026, min=1e-4, max=10.0,
                                 subtype="DISTANCE", unit="LENGTH", precision=4)
    dictionary: EnumProperty(name="Dictionary", items=DICTIONARY_ITEMS, default="DICT_5X5_100")
    paper: EnumProperty(name="Paper", items=PAPER_ITEMS, default="A4")
    board_file: StringProperty(name="Board File", subtype="FILE_PATH", default="//charuco_board.png",
                               description="PNG (and PDF) of the printable board")
    photos: StringProperty(name="Board Photos", subtype="DIR_PATH",
                           description="Folder of photos of the board for the calibration")
    calibration: StringProperty(name="Calibration", subtype="FILE_PATH",
                                default="//camera_calibration.yml",
                                description="OpenCV FileStorage file (.yml or .xml)")
    marker_photo: StringProperty(name="Pose Photo", subtype="FILE_PATH",
                                 description="Photo (or folder, or movie) showing the board")
    board_object: PointerProperty(name="Board Object", type=bpy.types.Object, poll=_is_mesh,
                                  description="The board's plane in the scene")
    brackets: StringProperty(name="Brackets", subtype="DIR_PATH",
                             description="Folder of bracketed photos (and exposures.json)")
    hdr_output: StringProperty(name="HDR Output", subtype="FILE_PATH", default="//merged.exr",
                               description="OpenEXR to write")
    environment: EnumProperty(name="Result", items=ENVIRONMENT_ITEMS, default="NONE")
    texture_size: IntProperty(name="Texture Size", default=0, min=0, max=16384,
                              description="0: about one texel a photo pixel")


BOARD_ARGS = ("squares_x", "squares_y", "square_length", "marker_length", "dictionary")


def attach():
    bpy.types.Scene.relight_capture = PointerProperty(type=RelightCaptureSettings)


def detach():
    if hasattr(bpy.types.Scene, "relight_capture"):
        del bpy.types.Scene.relight_capture


classes = (RelightCaptureSettings, RELIGHT_OT_calibration_board, RELIGHT_OT_calibrate_camera,
           RELIGHT_OT_camera_from_marker, RELIGHT_OT_merge_hdr, RELIGHT_OT_project_photos)
