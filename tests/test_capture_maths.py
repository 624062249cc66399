"""Capture maths against independent truth, no renders (quick).

* K of a Blender camera: ``calibration.camera_matrix`` against Blender's own projection matrix
  (``Object.calc_matrix_camera``) over sensor fits, orientations, pixel aspects and shifts; and
  the inverse (``blender_camera`` applied to a camera) read back through Blender.
* The FileStorage file: written by us, read by plain ``cv2.FileStorage``; the seed 002 file
  (appendix A.1, XML) read by us.
* Board corners: a board image box-filtered down by 8 has its corners at known positions; the
  re-refined corners land on them, CharucoDetector's own are offset by +0.5 px (opencv#25539).
* Pose conventions: board corners projected by Blender (``world_to_camera_view``) of a plane
  placed as the issue says give back the camera's matrix_world.
* Slerp against scipy's ``Slerp``; the path smoother on a noisy synthetic path with outliers.
"""

import numpy as np
import pytest

cv2 = pytest.importorskip("cv2")

from relight_addon.core.capture import CaptureError  # noqa: E402
from relight_addon.core.capture import board as bd  # noqa: E402
from relight_addon.core.capture import calibration as cal  # noqa: E402
from relight_addon.core.capture import pose as ps  # noqa: E402

SEED_XML = """<?xml version="1.0"?>
<opencv_storage>
<Camera_Matrix type_id="opencv-matrix">
<rows>3</rows>
<cols>3</cols>
<dt>f</dt>
<data>
  5.35921936e+02 0. 3.2000000e+02
  0. 5.59243896e+02 2.4000000e+02
  0. 0. 1.</data></Camera_Matrix>
<Distortion_Coefficients type_id="opencv-matrix">
<rows>1</rows>
<cols>5</cols>
<dt>d</dt>
<data>
  1.2795843004319202e-01 -1.2722157813678139e-01
  -5.3120929078121173e-02 -3.1157837204309542e-02
  4.5978051085070831e-01</data></Distortion_Coefficients>
<Image_Size>
  640 480</Image_Size>
<Root_Mean_Square>3.8408414491248599e-01</Root_Mean_Square>
</opencv_storage>
"""


@pytest.fixture(scope="module")
def blender():
    bpy = pytest.importorskip("bpy")
    from scenes.addon import register_repo_addon
    register_repo_addon()
    return bpy


# -- board -----------------------------------------------------------------------------------

def test_dictionary_list_matches_opencv(blender):
    import importlib
    ops = importlib.import_module("relight_ext.operators.capture")
    # every predefined dictionary once (cv2.aruco also spells the AprilTag ones upper-case)
    values = {getattr(cv2.aruco, n) for n in bd.dictionary_names()}
    assert sorted(getattr(cv2.aruco, n) for n in ops.DICTIONARIES) == sorted(values)


def test_board_files(tmp_path):
    from PIL import Image
    spec = bd.BoardSpec(7, 5, 0.03, 0.022)
    info = bd.write_png(spec, str(tmp_path / "b.png"))
    im = Image.open(tmp_path / "b.png")
    # the print resolution makes one square 30 mm: squares x pixels / dpi * 25.4
    px_per_mm = im.info["dpi"][0] / 25.4
    assert im.size == (7 * info["pixels_per_square"], 5 * info["pixels_per_square"])
    assert im.size[0] / px_per_mm == pytest.approx(210.0, abs=1e-6)
    assert "30 mm squares" in im.info["Description"]
    page = bd.write_pdf(spec, str(tmp_path / "b.pdf"), "A4")
    raw = (tmp_path / "b.pdf").read_bytes()
    import re
    box = [float(x) for x in re.search(rb"/MediaBox \[ ?([^\]]*)\]", raw).group(1).split()]
    # A4 landscape in points (1/72 inch): 297 x 210 mm, to a pixel of 300 dpi
    assert box[2] * 25.4 / 72 == pytest.approx(297.0, abs=0.1)
    assert box[3] * 25.4 / 72 == pytest.approx(210.0, abs=0.1)
    assert page["landscape"] and "square 30 mm" in page["label"]
    with pytest.raises(CaptureError, match="does not fit on A4"):
        bd.page_layout(bd.BoardSpec(9, 6, 0.04, 0.03), "A4")
    with pytest.raises(CaptureError, match="smaller than the square"):
        bd.BoardSpec(5, 4, 0.03, 0.03).validate()
    with pytest.raises(CaptureError, match="markers"):
        bd.BoardSpec(20, 20, 0.01, 0.008, "DICT_4X4_50").validate()
    with pytest.raises(CaptureError, match="predefined dictionary"):
        bd.BoardSpec(5, 4, 0.03, 0.02, "DICT_NOPE").validate()


def test_refined_corners_land_on_known_positions():
    """Board at 256 px a square with a 256 px white margin, box-filtered down by 8 (exact area
    averaging): corner (i, j) lies at ((i + 1) * 32 + 32 - 0.5, ...) in OpenCV pixels."""
    spec = bd.BoardSpec(7, 5, 0.03, 0.022)
    big = bd.board_image(spec, 256)
    big = cv2.copyMakeBorder(big, 256, 256, 256, 256, cv2.BORDER_CONSTANT, value=255)
    small = cv2.resize(big, (big.shape[1] // 8, big.shape[0] // 8), interpolation=cv2.INTER_AREA)
    det = bd.Detector(spec).detect(small)
    assert len(det) == spec.n_corners
    ij = spec.corner_points()[det.ids, :2] / spec.square_length
    truth = ij * 32 + 32 - 0.5
    err = det.corners - truth
    assert np.abs(err).max() < 0.02
    raw = det.raw - truth                       # CharucoDetector's own corners
    assert np.allclose(raw.mean(axis=0), 0.5, atol=0.05)
    assert det.blur < 1.0


# -- K <-> Blender ----------------------------------------------------------------------------

CAMERAS = [  # lens, sensor w, h, fit, shift x, y, res x, y, pixel aspect x, y
    (35, 36, 24, "AUTO", 0.0, 0.0, 640, 480, 1, 1),
    (50, 36, 24, "AUTO", 0.07, -0.03, 640, 480, 1, 1),
    (28, 36, 24, "AUTO", -0.1, 0.05, 480, 640, 1, 1),          # portrait: AUTO fits width
    (24, 23.5, 15.6, "HORIZONTAL", 0.02, 0.04, 1280, 720, 1, 1),
    (80, 36, 24, "VERTICAL", 0.03, -0.06, 800, 600, 1, 1),
    (40, 36, 24, "AUTO", 0.05, 0.02, 720, 576, 16, 15),        # non-square pixels
    (40, 36, 24, "VERTICAL", -0.04, 0.03, 720, 576, 10, 11),
]


def _camera_scene(bpy):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    bpy.context.scene.collection.objects.link(cam)
    bpy.context.scene.camera = cam
    return cam, bpy.context.scene


def _apply(cam, scene, c):
    d = cam.data
    d.lens, d.sensor_width, d.sensor_height, d.sensor_fit, d.shift_x, d.shift_y = c[:6]
    r = scene.render
    r.resolution_x, r.resolution_y = c[6], c[7]
    r.resolution_percentage = 100
    r.pixel_aspect_x, r.pixel_aspect_y = c[8], c[9]


def test_camera_matrix_matches_blender(blender):
    from scenes.capture import blender_K
    import importlib
    bridge = importlib.import_module("relight_ext.relight_addon.blender.capture")
    cam, scene = _camera_scene(blender)
    for c in CAMERAS:
        _apply(cam, scene, c)
        truth = blender_K(cam, scene)
        ours = bridge.camera_K(cam, scene)
        np.testing.assert_allclose(ours, truth, rtol=1e-6, atol=1e-4, err_msg=str(c))


def test_blender_camera_from_K_round_trip(blender):
    """K -> lens, shift, pixel aspect set on a camera -> Blender's projection gives K back."""
    from scenes.capture import blender_K
    import importlib
    bridge = importlib.import_module("relight_ext.relight_addon.blender.capture")
    cam, scene = _camera_scene(blender)
    for K, size in (([[711.1, 0, 287.5], [0, 711.1, 213.9], [0, 0, 1]], (640, 480)),
                    ([[1500.0, 0, 1010.3], [0, 1512.0, 530.7], [0, 0, 1]], (1920, 1080)),
                    ([[800.0, 0, 250.0], [0, 790.0, 330.0], [0, 0, 1]], (480, 640))):
        bridge.set_intrinsics(cam, scene, np.array(K), size)
        assert bridge.render_size(scene) == size
        np.testing.assert_allclose(blender_K(cam, scene), K, rtol=1e-5, atol=1e-3)


# -- FileStorage -------------------------------------------------------------------------------

@pytest.mark.parametrize("ext", [".yml", ".xml"])
def test_filestorage_nodes(tmp_path, ext):
    k = np.array([[711.3, 0, 287.1], [0, 711.9, 213.2], [0, 0, 1]])
    d = np.array([-0.11, 0.05, 1e-4, -2e-4, 0.0])
    path = str(tmp_path / ("calib" + ext))
    cal.write_calibration(path, cal.Calibration(k, d, (640, 480), 0.061))
    fs = cv2.FileStorage(path, cv2.FILE_STORAGE_READ)
    np.testing.assert_allclose(fs.getNode("Camera_Matrix").mat(), k)
    np.testing.assert_allclose(fs.getNode("Distortion_Coefficients").mat().ravel(), d)
    size = fs.getNode("Image_Size")
    assert [int(size.at(i).real()) for i in range(size.size())] == [640, 480]
    assert fs.getNode("Root_Mean_Square").real() == pytest.approx(0.061)
    fs.release()
    back = cal.read_calibration(path)
    np.testing.assert_allclose(back.camera_matrix, k)
    assert back.image_size == (640, 480)


def test_reads_the_seed_calibration_file(tmp_path):
    path = tmp_path / "seed.xml"
    path.write_text(SEED_XML)
    c = cal.read_calibration(str(path))
    assert c.camera_matrix[0, 0] == pytest.approx(535.921936)
    assert c.camera_matrix[1, 2] == pytest.approx(240.0)
    assert c.image_size == (640, 480)
    assert c.dist_coeffs[4] == pytest.approx(0.45978051085070831)
    assert c.rms == pytest.approx(0.38408414491248599)
    with pytest.raises(CaptureError, match="must end in"):
        cal.read_calibration(str(tmp_path / "seed.txt"))
    with pytest.raises(CaptureError, match="not found"):
        cal.read_calibration(str(tmp_path / "missing.yml"))


# -- pose conventions ----------------------------------------------------------------------------

def test_pose_conventions_against_blender_projection(blender):
    """The board plane rotated and moved in the world; its corners (plane-local
    (-W/2 + x, H/2 - y, 0) for board point (x, y)) projected by bpy_extras'
    world_to_camera_view; the pose solved from them gives back the camera."""
    import importlib
    import mathutils
    from bpy_extras.object_utils import world_to_camera_view
    from scenes.capture import blender_K, look_at
    bridge = importlib.import_module("relight_ext.relight_addon.blender.capture")
    bpy = blender
    cam, scene = _camera_scene(bpy)
    _apply(cam, scene, (40, 36, 24, "AUTO", 0.04, -0.02, 800, 600, 1, 1))
    spec = bd.BoardSpec(6, 4, 0.1, 0.075)
    w, h = spec.size
    me = bpy.data.meshes.new("Board")
    me.from_pydata([(-w / 2, -h / 2, 0), (w / 2, -h / 2, 0), (w / 2, h / 2, 0), (-w / 2, h / 2, 0)],
                   [], [(0, 1, 2, 3)])
    board = bpy.data.objects.new("Board", me)
    scene.collection.objects.link(board)
    board.rotation_euler = (1.2, 0.3, -0.7)
    board.location = (0.4, -0.2, 1.1)
    bpy.context.view_layer.update()
    normal = np.array(board.matrix_world)[:3, 2]
    centre = np.array(board.matrix_world)[:3, 3]
    cam.matrix_world = mathutils.Matrix(look_at(centre + 2.0 * normal + [0.3, -0.2, 0.1], centre,
                                                roll_deg=17).tolist())
    bpy.context.view_layer.update()
    pts = spec.corner_points()
    local = np.column_stack([-w / 2 + pts[:, 0], h / 2 - pts[:, 1], np.zeros(len(pts))])
    mw = board.matrix_world
    uv = []
    for p in local:   # a few corners: bpy_extras' per-point function is the truth
        ndc = world_to_camera_view(scene, cam, mw @ mathutils.Vector(p))
        uv.append((ndc.x * 800 - 0.5, (1 - ndc.y) * 600 - 0.5))
    det = bd.Detection(np.array(uv), np.arange(len(pts)), np.array(uv))
    pose = ps.board_pose(det, spec, blender_K(cam, scene), np.zeros(5))
    assert pose.rms < 1e-3
    lo, hi = bridge.board_bounds(board)
    frame = ps.board_frame(bridge.matrix_of(board), lo, hi, spec.size)
    got = ps.camera_world_matrix(frame, pose)
    np.testing.assert_allclose(got, np.array(cam.matrix_world), atol=1e-5)
    board.scale = (1.5, 1.0, 1.0)
    bpy.context.view_layer.update()
    with pytest.raises(CaptureError, match="board object is"):
        ps.board_frame(bridge.matrix_of(board), lo, hi, spec.size)


# -- slerp and smoothing ---------------------------------------------------------------------

def test_slerp_matches_scipy():
    from scipy.spatial.transform import Rotation, Slerp
    rng = np.random.default_rng(3)
    r = Rotation.random(2, random_state=4)
    s = Slerp([0, 1], r)
    for t in rng.uniform(0, 1, 5):
        q = ps.slerp(ps.quat_from_matrix(r[0].as_matrix())[None],
                     ps.quat_from_matrix(r[1].as_matrix())[None], t)[0]
        np.testing.assert_allclose(ps.matrix_from_quat(q), s([t]).as_matrix()[0], atol=1e-9)


def _path(n):
    from scipy.spatial.transform import Rotation
    t = np.linspace(0, 1, n)
    out = np.repeat(np.eye(4)[None], n, axis=0)
    out[:, :3, :3] = Rotation.from_euler("xyz", np.stack([0.4 * t, 0.8 * np.sin(2 * t), 0.3 + 0 * t], 1)).as_matrix()
    out[:, :3, 3] = np.stack([2 * np.cos(t), 2 * np.sin(t), 1.5 + 0.2 * t], 1)
    return out


def test_smoothing_rejects_outliers_and_reduces_noise():
    from scipy.spatial.transform import Rotation
    rng = np.random.default_rng(0)
    truth = _path(60)
    noisy = truth.copy()
    noise_rot = Rotation.from_rotvec(rng.normal(0, np.radians(0.3), (60, 3))).as_matrix()
    noisy[:, :3, :3] = noise_rot @ truth[:, :3, :3]
    noisy[:, :3, 3] += rng.normal(0, 0.004, (60, 3))
    for i in (17, 40):                                   # two wild poses
        noisy[i, :3, :3] = Rotation.from_rotvec([0.3, -0.2, 0.1]).as_matrix() @ noisy[i, :3, :3]
        noisy[i, :3, 3] += (0.2, -0.1, 0.05)
    valid = np.ones(60, bool)
    valid[25] = False                                    # a frame without a board
    smooth, rejected = ps.smooth_path(noisy, valid, smoothing=0.6)
    assert set(np.flatnonzero(rejected)) == {17, 40}

    def errors(m):
        ang = np.degrees(ps.rotation_angle(ps.quat_from_matrix(m[:, :3, :3]),
                                           ps.quat_from_matrix(truth[:, :3, :3])))
        return ang, np.linalg.norm(m[:, :3, 3] - truth[:, :3, 3], axis=1)

    a0, d0 = errors(noisy)
    a1, d1 = errors(smooth)
    keep = np.ones(60, bool)
    keep[[17, 25, 40]] = False
    assert a1[keep].mean() < 0.7 * a0[keep].mean()
    assert d1[keep].mean() < 0.7 * d0[keep].mean()
    assert a1.max() < 1.0 and d1.max() < 0.02          # outliers and the gap filled by slerp
