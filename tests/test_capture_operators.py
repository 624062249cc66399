"""relight.calibration_board / calibrate_camera / camera_from_marker through ``bpy.ops``
(quick: the photos are the board mapped by the homography of a known K and pose, supersampled
4x and box-filtered, ``scenes.capture.warp_board_view``; the Blender renders are in
test_capture_renders.py).

Truth: the K and the camera poses the photos were made with; the camera's K is read back
through Blender's own projection matrix (``scenes.capture.blender_K``).  Every bad input named
by the issue gives one sentence (bpy.ops raises RuntimeError with the ERROR report) and
changes nothing: the output file is not written, the camera keeps its lens, shift, matrix and
the scene its resolution.
"""
import importlib
import os

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
cv2 = pytest.importorskip("cv2")

from relight_addon.core.capture import board as bd  # noqa: E402
from relight_addon.core.capture import calibration as cal  # noqa: E402
from scenes import capture as sc  # noqa: E402
from scenes.addon import register_repo_addon  # noqa: E402

SPEC = bd.BoardSpec(7, 5, 0.03, 0.022)
ARGS = dict(squares_x=7, squares_y=5, square_length=0.03, marker_length=0.022,
            dictionary="DICT_5X5_100")
SIZE = (640, 480)
K_TRUE = np.array([[800.0, 0, 331.7], [0, 800.0, 228.4], [0, 0, 1]])
# a pose board: 6 x 4 squares of 10 cm
POSE_SPEC = bd.BoardSpec(6, 4, 0.1, 0.075)
POSE_ARGS = dict(squares_x=6, squares_y=4, square_length=0.1, marker_length=0.075,
                 dictionary="DICT_5X5_100")


@pytest.fixture(scope="module", autouse=True)
def addon():
    register_repo_addon()


def _scene():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    bpy.context.scene.collection.objects.link(cam)
    bpy.context.scene.camera = cam
    cam.location = (1.0, -2.0, 0.5)
    bpy.context.view_layer.update()
    return bpy.context.scene, cam


def _camera_state(scene, cam):
    c, r = cam.data, scene.render
    return (round(c.lens, 6), round(c.shift_x, 6), round(c.shift_y, 6), c.sensor_fit,
            r.resolution_x, r.resolution_y, r.pixel_aspect_x, r.pixel_aspect_y,
            tuple(round(x, 6) for row in cam.matrix_world for x in row),
            cam.animation_data is not None)


def _views(spec, n, seed, K=K_TRUE, size=SIZE):
    """(images, camera matrices) of ``n`` views of a board at the origin."""
    lens = K[0, 0] * 36.0 / size[0]
    views = sc.orbit_views(n, spec.size, dict(lens=lens, sensor_width=36.0, width=size[0],
                                              height=size[1]), seed=seed)
    frame = sc.board_frame_world(np.eye(4), spec.size)
    out = []
    for v in views:
        T = sc.cv_pose(np.array(v["matrix_world"]), frame)
        out.append(sc.warp_board_view(spec, K, T, size))
    return out, [np.array(v["matrix_world"]) for v in views]


def _write(folder, images, prefix="view"):
    os.makedirs(folder, exist_ok=True)
    for i, img in enumerate(images):
        cv2.imwrite(os.path.join(folder, f"{prefix}_{i:02d}.png"), img)
    return str(folder)


@pytest.fixture(scope="module")
def calibration_photos(tmp_path_factory):
    images, _ = _views(SPEC, 10, seed=5)
    return _write(tmp_path_factory.mktemp("calib"), images), images


def _raises(match):
    return pytest.raises(RuntimeError, match=match)


# -- calibration_board --------------------------------------------------------------------------

def test_calibration_board_writes_png_and_pdf(tmp_path):
    _scene()
    path = tmp_path / "board.png"
    bpy.ops.relight.calibration_board(filepath=str(path), paper="A4", **ARGS)
    assert path.exists() and (tmp_path / "board.pdf").exists()
    img = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    img = cv2.resize(img, (img.shape[1] // 4, img.shape[0] // 4), interpolation=cv2.INTER_AREA)
    det = bd.Detector(SPEC).detect(cv2.copyMakeBorder(img, 20, 20, 20, 20, cv2.BORDER_CONSTANT,
                                                      value=255))
    assert len(det) == SPEC.n_corners


def test_calibration_board_bad_input(tmp_path):
    _scene()
    with _raises("does not fit on A4"):
        bpy.ops.relight.calibration_board(filepath=str(tmp_path / "big.png"), paper="A4",
                                          **dict(ARGS, squares_x=12, square_length=0.04))
    with _raises("smaller than the square"):
        bpy.ops.relight.calibration_board(filepath=str(tmp_path / "m.png"),
                                          **dict(ARGS, marker_length=0.03))
    with _raises("does not exist"):
        bpy.ops.relight.calibration_board(filepath=str(tmp_path / "nope" / "b.png"), **ARGS)
    assert not list(tmp_path.iterdir())


# -- calibrate_camera --------------------------------------------------------------------------

def test_calibrate_camera_sets_the_camera(tmp_path, calibration_photos):
    folder, _ = calibration_photos
    scene, cam = _scene()
    out = tmp_path / "calib.yml"
    bpy.ops.relight.calibrate_camera(directory=folder, output=str(out), **ARGS)
    fs = cv2.FileStorage(str(out), cv2.FILE_STORAGE_READ)
    k = fs.getNode("Camera_Matrix").mat()
    size = fs.getNode("Image_Size")
    assert [int(size.at(i).real()) for i in range(2)] == list(SIZE)
    rms = fs.getNode("Root_Mean_Square").real()
    dist = fs.getNode("Distortion_Coefficients").mat().ravel()
    fs.release()
    assert rms < 0.1
    assert abs(k[0, 0] / K_TRUE[0, 0] - 1) < 1e-3 and abs(k[1, 1] / K_TRUE[1, 1] - 1) < 1e-3
    assert np.abs(k[:2, 2] - K_TRUE[:2, 2]).max() < 1.0
    assert np.abs(dist).max() < 0.02
    # the Blender camera's K (Blender's projection matrix) is the file's
    np.testing.assert_allclose(sc.blender_K(cam, scene), k, rtol=1e-5, atol=1e-3)
    assert (scene.render.resolution_x, scene.render.resolution_y) == SIZE


def test_calibrate_camera_bad_input(tmp_path, calibration_photos):
    folder, images = calibration_photos
    scene, cam = _scene()
    state = _camera_state(scene, cam)
    out = tmp_path / "calib.yml"
    run = lambda d, **kw: bpy.ops.relight.calibrate_camera(  # noqa: E731
        directory=str(d), output=str(out), **dict(ARGS, **kw))
    empty = tmp_path / "empty"
    empty.mkdir()
    with _raises("No images"):
        run(empty)
    blank = _write(tmp_path / "blank", [np.full((480, 640), 190, np.uint8)] * 5)
    with _raises("No board found in any of the 5 images"):
        run(blank)
    few = _write(tmp_path / "few", images[:2])
    with _raises("Too few usable views of the board: 2 of 2"):
        run(few)
    mixed = _write(tmp_path / "mixed", images[:5] + [cv2.resize(images[5], (320, 240))])
    with _raises("different sizes"):
        run(mixed)
    blurred = _write(tmp_path / "blurred", [cv2.GaussianBlur(im, (0, 0), 4.0) for im in images[:8]])
    with _raises("blurred"):
        run(blurred)
    with _raises("not on this board"):                         # told 5 x 4, shown 7 x 5
        run(folder, squares_x=5, squares_y=4)
    with _raises("Too few usable views"):                      # told 9 x 6, shown 7 x 5
        run(folder, squares_x=9, squares_y=6)
    with _raises("must end in"):
        bpy.ops.relight.calibrate_camera(directory=folder, output=str(tmp_path / "c.txt"), **ARGS)
    assert not out.exists()
    assert _camera_state(scene, cam) == state


@pytest.mark.parametrize("at", [0.3, 0.95])
def test_calibrate_camera_cancelled_midway_changes_nothing(tmp_path, calibration_photos, at):
    """Esc while the board is found photo by photo (0.3) or while the undistorted photos are
    written (0.95): no calibration file, no undistorted photo left (Esc's abandon removes the
    ones written), the camera as it was; the same job run to its end writes them all."""
    import importlib
    from helpers.blender import run_cancelled_at
    folder, images = calibration_photos
    scene, cam = _scene()
    state = _camera_state(scene, cam)
    ops = importlib.import_module("relight_ext.operators.capture")
    precompute = importlib.import_module("relight_ext.operators.precompute")
    undist = tmp_path / "undistorted"
    undist.mkdir()
    out = tmp_path / "calib.yml"
    op = type("Op", (), dict(directory=folder, output=str(out), distortion="K1K2P1P2",
                             undistorted_directory=str(undist), set_camera=True,
                             spec=lambda self: SPEC))()
    job = ops.CalibrationJob(op, bpy.context)
    solve = precompute.SolveJob(job)
    seen = run_cancelled_at(solve, at)
    job.abandon()                        # what the operator's Esc does
    assert solve.state == "cancelled" and solve.result is None and max(seen) < 1.0
    assert min(f for f in seen if f >= at) < at + 0.05      # it stopped at the next report
    assert not out.exists() and not list(undist.iterdir())
    assert _camera_state(scene, cam) == state
    whole = ops.CalibrationJob(op, bpy.context)
    done = whole.compute()
    assert out.exists() and len(list(undist.iterdir())) == len(images)
    assert "Calibrated from" in whole.finish(bpy.context, done)
    assert _camera_state(scene, cam) != state


# -- camera_from_marker --------------------------------------------------------------------------

def _pose_scene(tmp_path):
    """A board plane rotated and moved in the world, a calibration file of K_TRUE."""
    scene, cam = _scene()
    w, h = POSE_SPEC.size
    me = bpy.data.meshes.new("Board")
    me.from_pydata([(-w / 2, -h / 2, 0), (w / 2, -h / 2, 0), (w / 2, h / 2, 0), (-w / 2, h / 2, 0)],
                   [], [(0, 1, 2, 3)])
    board = bpy.data.objects.new("Board", me)
    scene.collection.objects.link(board)
    board.location = (0.5, 1.0, 0.8)
    board.rotation_euler = (1.3, 0.1, 0.4)
    bpy.context.view_layer.update()
    calib = str(tmp_path / "calib.yml")
    cal.write_calibration(calib, cal.Calibration(K_TRUE, np.zeros(5), SIZE, 0.05))
    return scene, cam, board, calib


def _photo_of(board, camera_world):
    frame = sc.board_frame_world(np.array(board.matrix_world), POSE_SPEC.size)
    return sc.warp_board_view(POSE_SPEC, K_TRUE, sc.cv_pose(camera_world, frame), SIZE)


def _pose_error(a, b):
    r = a[:3, :3].T @ b[:3, :3]
    angle = np.degrees(np.arccos(np.clip((np.trace(r) - 1) / 2, -1, 1)))
    return angle, np.linalg.norm(a[:3, 3] - b[:3, 3])


def test_camera_from_marker_single_photo(tmp_path):
    scene, cam, board, calib = _pose_scene(tmp_path)
    centre = np.array(board.matrix_world)[:3, 3]
    normal = np.array(board.matrix_world)[:3, 2]
    truth = sc.look_at(centre + 1.1 * normal + [0.3, -0.2, 0.2], centre, roll_deg=8)
    photo = str(tmp_path / "photo.png")
    cv2.imwrite(photo, _photo_of(board, truth))
    bpy.ops.relight.camera_from_marker(filepath=photo, calibration=calib, board_object="Board",
                                       **POSE_ARGS)
    angle, dist = _pose_error(np.array(cam.matrix_world), truth)
    assert angle < 0.05 and dist < 0.002
    np.testing.assert_allclose(sc.blender_K(cam, scene), K_TRUE, atol=1e-3)
    assert cam.data.background_images[0].image.filepath.endswith("photo.png")


def test_camera_from_marker_sequence(tmp_path):
    scene, cam, board, calib = _pose_scene(tmp_path)
    centre = np.array(board.matrix_world)[:3, 3]
    normal = np.array(board.matrix_world)[:3, 2]
    side = np.cross(normal, [0, 0, 1.0])
    side /= np.linalg.norm(side)
    truths, frames = [], []
    for i in range(12):
        eye = centre + 2.0 * normal + (i - 6) * 0.05 * side + [0, 0, 0.01 * i]
        truths.append(sc.look_at(eye, centre, roll_deg=i))
        frames.append(_photo_of(board, truths[-1]))
    frames[4] = np.full_like(frames[4], 190)                     # a frame without the board
    folder = _write(tmp_path / "seq", frames, "frame")
    scene.frame_start = 10
    bpy.ops.relight.camera_from_marker(filepath=folder, calibration=calib, board_object="Board",
                                       smoothing=0.3, **POSE_ARGS)
    for i, truth in enumerate(truths):
        scene.frame_set(10 + i)
        angle, dist = _pose_error(np.array(cam.matrix_world), truth)
        assert angle < 0.3 and dist < 0.01, (i, angle, dist)   # frame 4 from its neighbours


def test_camera_from_marker_cancelled_midway_changes_nothing(tmp_path):
    """Esc while the board is found frame by frame (the worker's progress raises): the camera
    keeps its pose, its lens and no keys."""
    import importlib
    from helpers.blender import run_cancelled_at
    scene, cam, board, calib = _pose_scene(tmp_path)
    centre = np.array(board.matrix_world)[:3, 3]
    normal = np.array(board.matrix_world)[:3, 2]
    frames = [_photo_of(board, sc.look_at(centre + 2.0 * normal + [0.05 * i, 0, 0], centre))
              for i in range(8)]
    folder = _write(tmp_path / "seq", frames, "frame")
    state = _camera_state(scene, cam)
    ops = importlib.import_module("relight_ext.operators.capture")
    precompute = importlib.import_module("relight_ext.operators.precompute")
    op = type("Op", (), dict(filepath=folder, calibration=calib, board_object="Board",
                             set_intrinsics=True, background=True, smoothing=0.3,
                             frame_start=-1, spec=lambda self: POSE_SPEC))()
    solve = precompute.SolveJob(ops.MarkerJob(op, bpy.context))
    seen = run_cancelled_at(solve, 0.3)
    assert solve.state == "cancelled" and solve.result is None and max(seen) < 1.0
    assert _camera_state(scene, cam) == state and cam.animation_data is None


def test_camera_from_marker_movie(tmp_path):
    """A movie (MJPG AVI, what OpenCV writes everywhere): one key per frame."""
    scene, cam, board, calib = _pose_scene(tmp_path)
    centre = np.array(board.matrix_world)[:3, 3]
    normal = np.array(board.matrix_world)[:3, 2]
    movie = str(tmp_path / "take.avi")
    out = cv2.VideoWriter(movie, cv2.VideoWriter_fourcc(*"MJPG"), 24, SIZE)
    truths = []
    for i in range(6):
        truths.append(sc.look_at(centre + (1.3 + 0.05 * i) * normal, centre, roll_deg=2 * i))
        out.write(cv2.cvtColor(_photo_of(board, truths[-1]), cv2.COLOR_GRAY2BGR))
    out.release()
    scene.frame_start = 1
    bpy.ops.relight.camera_from_marker(filepath=movie, calibration=calib, board_object="Board",
                                       smoothing=0.0, **POSE_ARGS)
    fcurves = [fc for fc in _fcurves(cam) if fc.data_path == "location"]
    assert [len(fc.keyframe_points) for fc in fcurves] == [6, 6, 6]
    for i, truth in enumerate(truths):
        scene.frame_set(1 + i)
        angle, dist = _pose_error(np.array(cam.matrix_world), truth)
        assert angle < 0.2 and dist < 0.005, (i, angle, dist)          # JPEG frames


def _fcurves(obj):
    bridge = importlib.import_module("relight_ext.relight_addon.blender.capture")
    return bridge.fcurves(obj, obj.animation_data.action)


def test_camera_from_marker_bad_input(tmp_path):
    scene, cam, board, calib = _pose_scene(tmp_path)
    state = _camera_state(scene, cam)
    centre = np.array(board.matrix_world)[:3, 3]
    normal = np.array(board.matrix_world)[:3, 2]
    photo = str(tmp_path / "photo.png")
    cv2.imwrite(photo, _photo_of(board, sc.look_at(centre + 2 * normal, centre)))
    blank = str(tmp_path / "blank.png")
    cv2.imwrite(blank, np.full((480, 640), 190, np.uint8))
    small = str(tmp_path / "small.png")
    cv2.imwrite(small, cv2.resize(cv2.imread(photo), (320, 240)))
    run = lambda **kw: bpy.ops.relight.camera_from_marker(**dict(  # noqa: E731
        dict(filepath=photo, calibration=calib, board_object="Board", **POSE_ARGS), **kw))
    with _raises("No board pose in the photo: no board found"):
        run(filepath=blank)
    with _raises("board object is 0.600 x 0.400 m but the board is 0.700 x 0.400 m"):
        run(squares_x=7, square_length=0.1)
    with _raises("No object named 'Nope'"):
        run(board_object="Nope")
    with _raises("calibration is for 640 x 480"):
        run(filepath=small)
    with _raises("not found"):
        run(calibration=str(tmp_path / "missing.yml"))
    with _raises("neither a photo"):
        run(filepath=str(tmp_path / "missing.png"))
    assert _camera_state(scene, cam) == state
    assert len(cam.data.background_images) == 0


# -- panel -----------------------------------------------------------------------------------

class _Layout:
    """Enough of UILayout to run a panel's draw(): every prop must exist on its data, every
    operator must be registered and every argument set on it must be one of its properties."""

    def __init__(self, log):
        self.log = log

    def box(self):
        return _Layout(self.log)

    row = column = lambda self, **kw: _Layout(self.log)  # noqa: E731

    def label(self, text="", icon="NONE"):
        self.log.append(("label", text))

    def prop(self, data, name, **kw):
        assert hasattr(data, name), name
        self.log.append(("prop", name))

    def operator(self, idname, **kw):
        module, name = idname.split(".")
        op = getattr(getattr(bpy.ops, module), name)
        props = {p.identifier for p in op.get_rna_type().properties}
        log = self.log

        class Args:
            def __setattr__(self, key, value):
                assert key in props, (idname, key)
                log.append(("arg", idname, key))

        log.append(("operator", idname))
        return Args()


def test_capture_panel():
    scene, _ = _scene()
    panel_cls = bpy.types.RELIGHT_PT_capture
    assert panel_cls.bl_parent_id == "RELIGHT_PT_main"
    log = []

    class Context:
        pass

    ctx = Context()
    ctx.scene = scene
    panel = type("P", (), {"layout": _Layout(log)})()
    importlib.import_module("relight_ext.panels.capture").RELIGHT_PT_capture.draw(panel, ctx)
    ops = {x[1] for x in log if x[0] == "operator"}
    assert {"relight.calibration_board", "relight.calibrate_camera",
            "relight.camera_from_marker", "relight.merge_hdr", "relight.project_photos"} <= ops
