"""Renders with known cameras for the capture tests and benchmark (bpy, Cycles).

* ``render_board_views(spec, views, samples, name)``: a ChArUco board (the PNG the add-on
  writes, on an emission-only plane of the board's size W x H centred at the world origin,
  printed face +Z, image top +Y) photographed by Blender cameras of known intrinsics and
  poses; 8-bit grey PNGs (Standard view transform: the board's white is 255, its black 0, the
  grey world 188).  Returns the paths and the truth: each camera's matrix_world and its K
  derived from Blender's own projection matrix (``Object.calc_matrix_camera``), not from the
  add-on's formula.
* ``look_at``, ``orbit_views``: camera matrices looking at the board.
* ``distort``: a known OpenCV distortion applied to a rendered image (after rendering).

Cycles, not Workbench: Workbench's corners are offset by about (+0.04, -0.11) px (measured on
a 640 x 480 board; its texture sampling is not the issue: the offset is the same for 50-400
texels a square and for Linear or Closest), Cycles' are unbiased (mean offset < 0.01 px, RMS
0.025 px at 64 samples, 0.06 px at 16).

Cache: ``<RELIGHT_BAKE_CACHE or .cache/bakes>/capture/<key>/`` with key = sha256 of (this
harness's version, the board, the views, samples, seed, bpy version); ``truth.json`` beside
the images.
"""
from __future__ import annotations

import copy
import hashlib
import json
import os
import time

import numpy as np

from scenes.bake import default_cache_dir

VERSION = "relight-capture-render-v2"
TEXELS_PER_SQUARE = 128      # board texture resolution (the render's squares are 20-100 px)
BACKGROUND = 0.5             # linear grey of the world behind the board


def cache_dir() -> str:
    return os.path.join(default_cache_dir(), "capture")


def _bpy():
    import bpy  # noqa: PLC0415
    return bpy


def look_at(eye, target, up=(0.0, 0.0, 1.0), roll_deg=0.0) -> np.ndarray:
    """Blender camera matrix_world at ``eye`` looking at ``target`` (-Z forward, +Y up),
    rolled about its view axis."""
    eye, target, up = (np.asarray(x, np.float64) for x in (eye, target, up))
    back = eye - target
    back /= np.linalg.norm(back)
    if abs(np.dot(back, up)) > 0.999:
        up = np.array([0.0, 1.0, 0.0])
    x = np.cross(up, back)
    x /= np.linalg.norm(x)
    y = np.cross(back, x)
    r = np.radians(roll_deg)
    xr = np.cos(r) * x + np.sin(r) * y
    yr = -np.sin(r) * x + np.cos(r) * y
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = xr, yr, back, eye
    return m


def orbit_views(n, board_size, camera: dict, seed=0, tilt_deg=(15.0, 50.0), fill=(0.55, 0.9),
                distance=None, jitter=0.3):
    """``n`` views of a board at the origin: directions tilted ``tilt_deg`` (uniform) from its
    normal at any azimuth, distance so that the board's width fills a ``fill`` fraction of the
    frame's width (or a fixed ``distance``), aim jittered by ``jitter`` of the board's size,
    roll +-25 degrees.  ``camera`` holds the intrinsics (lens, sensor_width, shift_x, shift_y,
    width, height) copied into every view."""
    rng = np.random.default_rng(seed)
    w, h = board_size
    fov = 2 * np.arctan(0.5 * camera.get("sensor_width", 36.0) / camera["lens"])
    views = []
    for i in range(n):
        tilt = np.radians(rng.uniform(*tilt_deg))
        az = rng.uniform(0, 2 * np.pi)
        d = np.array([np.sin(tilt) * np.cos(az), np.sin(tilt) * np.sin(az), np.cos(tilt)])
        if distance is None:
            dist = w / rng.uniform(*fill) / (2 * np.tan(fov / 2))
        else:
            dist = float(distance)
        aim = np.array([rng.uniform(-jitter, jitter) * w, rng.uniform(-jitter, jitter) * h, 0.0])
        m = look_at(aim + dist * d, aim, roll_deg=rng.uniform(-25, 25))
        views.append(dict(camera, matrix_world=m.tolist()))
    return views


def blender_K(cam_obj, scene) -> np.ndarray:
    """K from Blender's own projection matrix (OpenGL clip space -> OpenCV pixels)."""
    r = scene.render
    w = int(r.resolution_x * r.resolution_percentage / 100)
    h = int(r.resolution_y * r.resolution_percentage / 100)
    dg = _bpy().context.evaluated_depsgraph_get()
    p = np.array(cam_obj.calc_matrix_camera(dg, x=w, y=h, scale_x=r.pixel_aspect_x,
                                            scale_y=r.pixel_aspect_y))
    # x_ndc = (p00 X + p02 Z) / -Z with Z < 0 in front: u = (x_ndc + 1) w / 2 - 0.5;
    # OpenCV (x, y, z) = (X, -Y, -Z), v from the top = (1 - y_ndc) h / 2 - 0.5
    fx = p[0, 0] * w / 2
    fy = p[1, 1] * h / 2
    cx = (1 - p[0, 2]) * w / 2 - 0.5
    cy = (1 + p[1, 2]) * h / 2 - 0.5
    return np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1]])


def _key(spec, views, samples, seed, extra):
    bpy = _bpy()
    h = hashlib.sha256()
    h.update(repr((VERSION, tuple(bpy.app.version), spec.squares_x, spec.squares_y,
                   spec.square_length, spec.marker_length, spec.dictionary, samples, seed,
                   TEXELS_PER_SQUARE, BACKGROUND, extra)).encode())
    h.update(json.dumps(views, sort_keys=True).encode())
    return h.hexdigest()[:32]


def board_scene(spec, background=BACKGROUND):
    """A factory-empty scene with the board plane "Board" (emission, its PNG as texture)."""
    bpy = _bpy()
    from relight_addon.core.capture.board import board_image  # noqa: PLC0415
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    w, h = spec.size
    me = bpy.data.meshes.new("Board")
    me.from_pydata([(-w / 2, -h / 2, 0), (w / 2, -h / 2, 0), (w / 2, h / 2, 0), (-w / 2, h / 2, 0)],
                   [], [(0, 1, 2, 3)])
    uv = me.uv_layers.new(name="UVMap")
    uv.data.foreach_set("uv", [0, 0, 1, 0, 1, 1, 0, 1])
    obj = bpy.data.objects.new("Board", me)
    scene.collection.objects.link(obj)
    pix = board_image(spec, TEXELS_PER_SQUARE)[::-1].astype(np.float32) / 255.0  # row 0 = bottom
    img = bpy.data.images.new("BoardTexture", pix.shape[1], pix.shape[0], alpha=False)
    rgba = np.ones(pix.shape + (4,), np.float32)
    rgba[..., :3] = pix[..., None]
    img.pixels.foreach_set(rgba.ravel())
    img.pack()
    mat = bpy.data.materials.new("Board")
    if mat.node_tree is None:
        mat.use_nodes = True
    nt = mat.node_tree
    for n in list(nt.nodes):
        nt.nodes.remove(n)
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    em = nt.nodes.new("ShaderNodeEmission")
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = img
    tex.interpolation = "Linear"
    nt.links.new(tex.outputs["Color"], em.inputs["Color"])
    nt.links.new(em.outputs["Emission"], out.inputs["Surface"])
    me.materials.append(mat)
    world = bpy.data.worlds.new("World")
    world.color = (background,) * 3
    if world.node_tree is None:              # Blender before 5.0: no node tree by default
        world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (background,) * 3 + (1.0,)
    scene.world = world
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(cam)
    scene.camera = cam
    return scene, obj, cam


def apply_camera(cam, scene, view: dict):
    c = cam.data
    c.lens = view["lens"]
    c.sensor_width = view.get("sensor_width", 36.0)
    c.sensor_height = view.get("sensor_height", 24.0)
    c.sensor_fit = view.get("sensor_fit", "AUTO")
    c.shift_x = view.get("shift_x", 0.0)
    c.shift_y = view.get("shift_y", 0.0)
    c.clip_start = 0.01
    c.clip_end = 100.0
    r = scene.render
    r.resolution_x, r.resolution_y = view["width"], view["height"]
    r.resolution_percentage = 100
    r.pixel_aspect_x = view.get("pixel_aspect_x", 1.0)
    r.pixel_aspect_y = view.get("pixel_aspect_y", 1.0)
    import mathutils  # noqa: PLC0415
    # (a plain list of rows would be read as columns)
    cam.matrix_world = mathutils.Matrix(np.asarray(view["matrix_world"], np.float64).tolist())
    _bpy().context.view_layer.update()


def _cycles(scene, samples, seed):
    scene.render.engine = "CYCLES"
    cy = scene.cycles
    cy.device = "CPU"
    cy.samples = int(samples)
    cy.seed = int(seed)
    cy.use_adaptive_sampling = False
    cy.use_denoising = False
    cy.max_bounces = 0
    scene.render.image_settings.file_format = "PNG"
    scene.render.image_settings.color_mode = "BW"
    scene.render.image_settings.color_depth = "8"


def render_board_views(spec, views, samples=16, seed=0, name="views", use_cache=True) -> dict:
    """Render (or read from the cache) one PNG per view.  Returns {"paths": [...], "K": [3x3],
    "matrix_world": [4x4], "board_matrix_world": 4x4, "seconds": render time (cold)}."""
    key = _key(spec, views, samples, seed, name)
    folder = os.path.join(cache_dir(), key)
    truth_path = os.path.join(folder, "truth.json")
    if use_cache and os.path.exists(truth_path):
        with open(truth_path) as fh:
            truth = json.load(fh)
        paths = [os.path.join(folder, p) for p in truth["files"]]
        if all(os.path.exists(p) for p in paths):
            truth["paths"] = paths
            truth["cached"] = True
            return truth
    bpy = _bpy()
    os.makedirs(folder, exist_ok=True)
    scene, board, cam = board_scene(spec)
    _cycles(scene, samples, seed)
    files, ks, mws = [], [], []
    t0 = time.perf_counter()
    for i, view in enumerate(views):
        apply_camera(cam, scene, view)
        fname = f"{name}_{i:03d}.png"
        scene.render.filepath = os.path.join(folder, fname)
        bpy.ops.render.render(write_still=True)
        files.append(fname)
        ks.append(blender_K(cam, scene).tolist())
        mws.append(np.array(cam.matrix_world).tolist())
    truth = {"files": files, "K": ks, "matrix_world": mws,
             "board_matrix_world": np.array(board.matrix_world).tolist(),
             "seconds": time.perf_counter() - t0, "samples": samples}
    tmp = truth_path + f".{os.getpid()}.tmp"
    with open(tmp, "w") as fh:
        json.dump(truth, fh)
    os.replace(tmp, truth_path)
    truth["paths"] = [os.path.join(folder, f) for f in files]
    truth["cached"] = False
    return truth


def distort(image, K, dist, fill=None) -> np.ndarray:
    """What a lens with OpenCV distortion ``dist`` and matrix K would have imaged: every
    output (distorted) pixel samples the undistorted render at its undistorted position
    (cv2.undistortPointsIter, converged to 1e-10 px), bilinearly; pixels that fall outside
    the render get ``fill`` (default: the background grey)."""
    import cv2  # noqa: PLC0415
    h, w = image.shape[:2]
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    pts = np.stack([xx.ravel(), yy.ravel()], 1).reshape(-1, 1, 2)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    und = cv2.undistortPointsIter(pts, K, np.asarray(dist, np.float64), None, K, crit)
    mx = und[:, 0, 0].reshape(h, w).astype(np.float32)
    my = und[:, 0, 1].reshape(h, w).astype(np.float32)
    if fill is None:
        fill = int(round(255 * _srgb(BACKGROUND)))
    return cv2.remap(image, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                     borderValue=fill)


def _srgb(x):
    return 12.92 * x if x <= 0.0031308 else 1.055 * x ** (1 / 2.4) - 0.055


def warp_board_view(spec, K, T_cv_board, size, pixels_per_square=96, supersample=4,
                    background=None):
    """A distortion-free photo of the board without Blender: the board image mapped by the
    homography ``K [r1 r2 t]`` of the pose ``T_cv_board`` (board -> OpenCV camera, 4x4) onto a
    ``supersample``-times larger canvas (bilinear), then box-filtered down (INTER_AREA) to
    ``size`` (w, h).  uint8 grey; the background is the renders' grey."""
    import cv2  # noqa: PLC0415
    from relight_addon.core.capture.board import board_image  # noqa: PLC0415
    p, s = int(pixels_per_square), int(supersample)
    img = board_image(spec, p)
    sq = spec.square_length
    # board image pixel centres -> board metres
    A = np.array([[sq / p, 0, 0.5 * sq / p], [0, sq / p, 0.5 * sq / p], [0, 0, 1]])
    T = np.asarray(T_cv_board, np.float64)
    Rt = np.column_stack([T[:3, 0], T[:3, 1], T[:3, 3]])
    # final OpenCV pixel coordinates -> supersampled canvas coordinates
    B = np.array([[s, 0, 0.5 * s - 0.5], [0, s, 0.5 * s - 0.5], [0, 0, 1]])
    H = B @ np.asarray(K, np.float64) @ Rt @ A
    if background is None:
        background = int(round(255 * _srgb(BACKGROUND)))
    big = cv2.warpPerspective(img, H, (size[0] * s, size[1] * s), flags=cv2.INTER_LINEAR,
                              borderMode=cv2.BORDER_CONSTANT, borderValue=int(background))
    return cv2.resize(big, (size[0], size[1]), interpolation=cv2.INTER_AREA)


def cv_pose(camera_world, board_frame_world) -> np.ndarray:
    """T_cv_board (board -> OpenCV camera) from a Blender camera matrix_world and the board
    frame's world matrix (the truth side of the tests: written out, not the add-on's)."""
    cam = np.asarray(camera_world, np.float64) @ np.diag([1.0, -1.0, -1.0, 1.0])
    return np.linalg.inv(cam) @ np.asarray(board_frame_world, np.float64)


def board_frame_world(board_matrix_world, board_size) -> np.ndarray:
    """World matrix of the board's OpenCV frame for a W x H plane centred on its origin
    (the issue's contract: plane-local (-W/2, +H/2, 0), X = +X, Y = -Y, Z = -Z)."""
    w, h = board_size
    local = np.array([[1.0, 0, 0, -w / 2], [0, -1.0, 0, h / 2], [0, 0, -1.0, 0], [0, 0, 0, 1]])
    return np.asarray(board_matrix_world, np.float64) @ local


# ------------------------------------------------------------------------------------------
# The render sets of the tests and the benchmark
# ------------------------------------------------------------------------------------------

CALIBRATION_BOARD = dict(squares_x=9, squares_y=6, square_length=0.04, marker_length=0.03)
# camera models: 640 x 480 on a 36 mm sensor; B and C off-centre through the shift
CALIBRATION_MODELS = {
    "A": dict(lens=24.0, shift_x=0.0, shift_y=0.0),
    "B": dict(lens=40.0, shift_x=0.05, shift_y=-0.04),
    "C": dict(lens=60.0, shift_x=-0.03, shift_y=0.025),
}
# model D: model A's renders with this radial distortion applied after rendering
DISTORTION = (-0.12, 0.03, 0.0, 0.0, 0.0)
CALIBRATION_VIEWS = 24
POSE_BOARD = dict(squares_x=7, squares_y=5, square_length=0.12, marker_length=0.09)
POSE_CAMERA = dict(lens=35.0, sensor_width=36.0, width=1280, height=960)
POSE_DISTANCES = (1.0, 2.0, 3.0)
POSE_VIEWS = 4


def board_spec(args):
    from relight_addon.core.capture.board import BoardSpec  # noqa: PLC0415
    return BoardSpec(args["squares_x"], args["squares_y"], args["square_length"],
                     args["marker_length"])


def calibration_set(model: str, samples=16):
    """The 24 renders of a camera model ("A", "B", "C"; "D" is A distorted, returned as the
    images themselves under "images").  Returns the render truth dict of render_board_views."""
    import cv2  # noqa: PLC0415
    spec = board_spec(CALIBRATION_BOARD)
    base = "A" if model == "D" else model
    cam = dict(CALIBRATION_MODELS[base], sensor_width=36.0, width=640, height=480)
    views = orbit_views(CALIBRATION_VIEWS, spec.size, cam, seed=ord(base), tilt_deg=(20, 55))
    truth = render_board_views(spec, views, samples=samples, name="cal" + base)
    if model == "D":
        K = np.array(truth["K"][0])
        truth = dict(truth, dist=list(DISTORTION))
        truth["images"] = [distort(cv2.imread(p, cv2.IMREAD_GRAYSCALE), K, DISTORTION)
                           for p in truth["paths"]]
    return truth


def pose_set(samples=64):
    """Renders of the large pose board (7 x 5 squares of 12 cm) from 1, 2 and 3 m, 4 views
    each, 1280 x 960 (f = 1244 px).  64 samples: the issue's truth is noise-free renders, and
    at 16 the render noise alone put a 3 m pose 3.13 mm off on bpy 5.2.3 (1.66 on 5.0.1; 0.91
    at 64)."""
    spec = board_spec(POSE_BOARD)
    views = []
    for i, d in enumerate(POSE_DISTANCES):
        views += orbit_views(POSE_VIEWS, spec.size, POSE_CAMERA, seed=100 + i,
                             tilt_deg=(10, 40), distance=d, jitter=0.1)
    truth = render_board_views(spec, views, samples=samples, name="pose")
    truth["distance"] = [d for d in POSE_DISTANCES for _ in range(POSE_VIEWS)]
    return truth


# ------------------------------------------------------------------------------------------
# HDR: radiance renders, brackets, mirror balls
# ------------------------------------------------------------------------------------------

def hdri_path(name="courtyard.exr"):
    """One of the HDRIs shipped in the bpy wheel."""
    path = os.path.join(_bpy().utils.system_resource("DATAFILES"), "studiolights", "world", name)
    if not os.path.exists(path):
        raise FileNotFoundError(path)
    return path


def _world_scene(hdri, strength=1.0):
    bpy = _bpy()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    world = bpy.data.worlds.new("World")
    if world.node_tree is None:
        world.use_nodes = True
    nt = world.node_tree
    env = nt.nodes.new("ShaderNodeTexEnvironment")
    env.image = bpy.data.images.load(hdri)
    bg = nt.nodes["Background"]
    bg.inputs["Strength"].default_value = strength
    nt.links.new(env.outputs["Color"], bg.inputs["Color"])
    scene.world = world
    scene.view_settings.view_transform = "Standard"
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(cam)
    scene.camera = cam
    return scene, cam


def _render_float(scene, samples, seed=0, bounces=0):
    """The render as (H, W, 3) float32 linear radiance, top row first (a 32-bit EXR)."""
    bpy = _bpy()
    _cycles(scene, samples, seed)
    scene.cycles.max_bounces = scene.cycles.glossy_bounces = int(bounces)
    import tempfile  # noqa: PLC0415
    s = scene.render.image_settings
    s.file_format, s.color_mode, s.color_depth = "OPEN_EXR", "RGB", "32"
    path = os.path.join(tempfile.mkdtemp(prefix="relight_cap_"), "r.exr")
    scene.render.filepath = path
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(path)
    w, h = img.size
    px = np.empty(w * h * 4, np.float32)
    img.pixels.foreach_get(px)
    bpy.data.images.remove(img)
    os.remove(path)
    return px.reshape(h, w, 4)[::-1, :, :3].copy()


def _cached_npz(key_parts, make):
    bpy = _bpy()
    key = hashlib.sha256(repr((VERSION, tuple(bpy.app.version)) + tuple(key_parts)).encode()
                         ).hexdigest()[:32]
    path = os.path.join(cache_dir(), key + ".npz")
    if os.path.exists(path):
        with np.load(path) as z:
            return {k: z[k] for k in z.files}
    out = make()
    os.makedirs(cache_dir(), exist_ok=True)
    tmp = path + f".{os.getpid()}.tmp.npz"
    np.savez_compressed(tmp, **out)
    os.replace(tmp, path)
    return out


def radiance_render(hdri="courtyard.exr", size=(320, 240), samples=16, lens=20.0):
    """A Cycles render (linear radiance, float32, top row first) of a shipped HDRI seen by a
    20 mm camera looking along +Y and slightly up: the "scene" of the HDR tests."""
    def make():
        scene, cam = _world_scene(hdri_path(hdri))
        apply_camera(cam, scene, dict(lens=lens, width=size[0], height=size[1],
                                      matrix_world=look_at((0, 0, 0), (0, 1, 0.15)).tolist()))
        return {"radiance": _render_float(scene, samples)}
    return _cached_npz(("radiance", hdri, size, samples, lens), make)["radiance"]


def camera_response(x):
    """The known non-linear response of the HDR tests: a shoulder (x (1 + a) / (x + a),
    a = 0.6) then a 1 / 2.2 gamma, on exposures clipped to [0, 1]."""
    x = np.clip(np.asarray(x, np.float64), 0.0, 1.0)
    a = 0.6
    return (x * (1 + a) / (x + a)) ** (1 / 2.2)


def brackets(radiance, times, gain=1.0):
    """8-bit BGR photos of ``radiance`` (RGB) exposed for ``times`` through camera_response."""
    out = []
    for t in times:
        v = np.round(255.0 * camera_response(radiance * gain * t))
        out.append(np.ascontiguousarray(v[..., ::-1].astype(np.uint8)))
    return out


def mirror_ball_render(hdri="courtyard.exr", size=256, samples=32):
    """An orthographic Cycles render of a perfect mirror ball (radius 1, at the origin) under
    a shipped HDRI, the camera on -Y looking along +Y (Blender's front view), the ball filling
    the frame.  Returns {"image": (size, size, 3) float32 linear, top row first}."""
    def make():
        bpy = _bpy()
        scene, cam = _world_scene(hdri_path(hdri))
        bpy.ops.mesh.primitive_uv_sphere_add(segments=128, ring_count=64, radius=1.0)
        ball = bpy.context.active_object
        bpy.ops.object.shade_smooth()
        mat = bpy.data.materials.new("Mirror")
        if mat.node_tree is None:
            mat.use_nodes = True
        nt = mat.node_tree
        for n in list(nt.nodes):
            nt.nodes.remove(n)
        out = nt.nodes.new("ShaderNodeOutputMaterial")
        gl = nt.nodes.new("ShaderNodeBsdfGlossy")
        gl.inputs["Roughness"].default_value = 0.0
        gl.inputs["Color"].default_value = (1, 1, 1, 1)
        nt.links.new(gl.outputs["BSDF"], out.inputs["Surface"])
        ball.data.materials.append(mat)
        cam.data.type = "ORTHO"
        cam.data.ortho_scale = 2.0
        apply_camera(cam, scene, dict(lens=50.0, width=size, height=size,
                                      matrix_world=look_at((0, -10, 0), (0, 0, 0)).tolist()))
        return {"image": _render_float(scene, samples, bounces=1)}
    return _cached_npz(("mirror-ball", hdri, size, samples), make)


CUBE_TARGETS = ((1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1))


def cube_frames(hdri="courtyard.exr", size=128, samples=16):
    """Six 90-degree renders of a shipped HDRI from the origin (the faces of a cube map):
    [(K, camera matrix_world, (size, size, 3) float32 linear, row 0 at the top)]."""
    def make():
        scene, cam = _world_scene(hdri_path(hdri))
        out = {}
        for i, t in enumerate(CUBE_TARGETS):
            up = (0, 1, 0) if abs(t[2]) else (0, 0, 1)
            m = look_at((0, 0, 0), t, up=up)
            apply_camera(cam, scene, dict(lens=18.0, sensor_width=36.0, width=size, height=size,
                                          matrix_world=m.tolist()))
            out[f"image{i}"] = _render_float(scene, samples)
            out[f"K{i}"] = blender_K(cam, scene)
            out[f"M{i}"] = np.array(cam.matrix_world)
        return out
    z = _cached_npz(("cube", hdri, size, samples), make)
    return [(z[f"K{i}"], z[f"M{i}"], z[f"image{i}"]) for i in range(len(CUBE_TARGETS))]


def hdri_pixels(name="courtyard.exr") -> np.ndarray:
    """A shipped HDRI as (H, W, 3) float32 linear, row 0 at the top."""
    bpy = _bpy()
    img = bpy.data.images.load(hdri_path(name), check_existing=False)
    w, h = img.size
    px = np.empty(w * h * 4, np.float32)
    img.pixels.foreach_get(px)
    bpy.data.images.remove(img)
    return px.reshape(h, w, 4)[::-1, :, :3].copy()


# ------------------------------------------------------------------------------------------
# Projection: a small emission-only scene (the photos show the textures exactly)
# ------------------------------------------------------------------------------------------

FLOOR_TEXELS = 96
BOX_RGB = (0.8, 0.08, 0.06)
PROJECTION_CAMERAS = (  # eye, exposure (stops)
    ((2.2, -1.6, 1.9), 0.0), ((-2.0, -1.8, 1.7), 0.0), ((0.3, 2.4, 2.0), 1.0),
)
PROJECTION_SIZE = (320, 240)


def floor_texture(n=FLOOR_TEXELS) -> np.ndarray:
    """The floor's emission colours (n, n, 3) linear, Blender row order: a colour gradient
    under a 6 x 6 checker of two strengths."""
    y, x = np.mgrid[0:n, 0:n] / (n - 1.0)
    base = np.stack([0.15 + 0.6 * x, 0.2 + 0.5 * y, 0.55 - 0.35 * x * y], -1)
    check = ((np.floor(x * 5.999) + np.floor(y * 5.999)) % 2)[..., None]
    return (base * (0.55 + 0.45 * check)).astype(np.float32)


def _emission(bpy, name, image=None, rgb=None):
    mat = bpy.data.materials.new(name)
    if mat.node_tree is None:
        mat.use_nodes = True
    nt = mat.node_tree
    for n in list(nt.nodes):
        nt.nodes.remove(n)
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    em = nt.nodes.new("ShaderNodeEmission")
    nt.links.new(em.outputs["Emission"], out.inputs["Surface"])
    if image is not None:
        tex = nt.nodes.new("ShaderNodeTexImage")
        tex.image = image
        tex.interpolation = "Closest"
        nt.links.new(tex.outputs["Color"], em.inputs["Color"])
    else:
        em.inputs["Color"].default_value = tuple(rgb) + (1.0,)
    return mat


def projection_scene():
    """Factory-empty scene: "Floor" (2 x 2 m, UV [0, 1]^2, emission texture floor_texture),
    "Box" (0.5 m cube on it, emission BOX_RGB, no UVs), three cameras "Cam0".."Cam2"
    looking at the floor (no photos yet).  Returns (scene, floor, box, cameras)."""
    bpy = _bpy()
    import mathutils  # noqa: PLC0415
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    me = bpy.data.meshes.new("Floor")
    me.from_pydata([(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)], [], [(0, 1, 2, 3)])
    me.uv_layers.new(name="UVMap").data.foreach_set("uv", [0, 0, 1, 0, 1, 1, 0, 1])
    floor = bpy.data.objects.new("Floor", me)
    scene.collection.objects.link(floor)
    tex = floor_texture()
    img = bpy.data.images.new("FloorTexture", tex.shape[1], tex.shape[0], alpha=False,
                              float_buffer=True)
    rgba = np.ones(tex.shape[:2] + (4,), np.float32)
    rgba[..., :3] = tex
    img.pixels.foreach_set(rgba.ravel())
    img.pack()
    me.materials.append(_emission(bpy, "Floor", image=img))
    s = 0.25
    v = [(x, y, z) for z in (0, 2 * s) for y in (-s, s) for x in (-s, s)]
    f = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    bm = bpy.data.meshes.new("Box")
    bm.from_pydata(v, [], f)
    bm.materials.append(_emission(bpy, "Box", rgb=BOX_RGB))
    box = bpy.data.objects.new("Box", bm)
    box.location = (0.1, 0.05, 0.0)
    scene.collection.objects.link(box)
    world = bpy.data.worlds.new("World")
    if world.node_tree is None:
        world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0, 0, 0, 1)
    scene.world = world
    scene.view_settings.view_transform = "Standard"
    scene.render.resolution_x, scene.render.resolution_y = PROJECTION_SIZE
    cams = []
    for i, (eye, _) in enumerate(PROJECTION_CAMERAS):
        cam = bpy.data.objects.new(f"Cam{i}", bpy.data.cameras.new(f"Cam{i}"))
        cam.data.lens = 24.0
        scene.collection.objects.link(cam)
        cam.matrix_world = mathutils.Matrix(look_at(eye, (0, 0, 0)).tolist())
        cams.append(cam)
    scene.camera = cams[0]
    bpy.context.view_layer.update()
    return scene, floor, box, cams


def projection_photos(samples=16):
    """8-bit sRGB PNG photos of projection_scene by its three cameras (the third exposed one
    stop brighter), cached.  Returns the paths."""
    bpy = _bpy()
    key = hashlib.sha256(repr((VERSION, tuple(bpy.app.version), "projection", FLOOR_TEXELS,
                               BOX_RGB, PROJECTION_CAMERAS, PROJECTION_SIZE, samples)).encode()
                         ).hexdigest()[:32]
    folder = os.path.join(cache_dir(), key)
    paths = [os.path.join(folder, f"cam{i}.png") for i in range(len(PROJECTION_CAMERAS))]
    if all(os.path.exists(p) for p in paths):
        return paths
    os.makedirs(folder, exist_ok=True)
    scene, floor, box, cams = projection_scene()
    _cycles(scene, samples, 0)
    scene.render.image_settings.color_mode = "RGB"
    for cam, (_, stops), path in zip(cams, PROJECTION_CAMERAS, paths):
        scene.camera = cam
        scene.view_settings.exposure = stops
        tmp = path + ".tmp.png"
        scene.render.filepath = tmp
        bpy.ops.render.render(write_still=True)
        os.replace(tmp, path)
    return paths


# ------------------------------------------------------------------------------------------
# The demo office photographed by posed cameras
# ------------------------------------------------------------------------------------------

OFFICE_CAMERAS = (  # eye, target, exposure (stops): corners, across the room, up at the ceiling
    ((0.3, 0.3, 1.6), (3.5, 3.0, 0.6), 0.0), ((4.7, 0.3, 1.6), (1.5, 3.0, 0.6), 0.0),
    ((4.7, 3.7, 1.6), (1.5, 1.0, 0.6), 0.0), ((0.3, 3.7, 1.6), (3.5, 1.0, 0.6), 0.5),
    ((2.5, 0.25, 2.2), (2.5, 3.5, 0.3), 0.0), ((2.5, 3.75, 2.2), (2.5, 0.5, 0.3), 0.0),
    ((0.25, 2.0, 2.4), (4.5, 2.0, 0.5), 0.0), ((4.75, 2.0, 2.4), (0.5, 2.0, 0.5), -0.5),
    ((1.0, 1.0, 0.5), (3.0, 2.6, 2.8), 0.0), ((4.0, 3.0, 0.5), (2.0, 1.4, 2.8), 0.0),
)
OFFICE_LENS = 16.0
OFFICE_PHOTO = (320, 240)


def office_cameras(bpy, scene, paths=None):
    """The office's photo cameras "Photo 0".. (lens 16 mm, 36 mm sensor), each with its photo
    as background image when ``paths`` are given."""
    import mathutils  # noqa: PLC0415
    cams = []
    for i, (eye, target, _) in enumerate(OFFICE_CAMERAS):
        cam = bpy.data.objects.new(f"Photo {i}", bpy.data.cameras.new(f"Photo {i}"))
        cam.data.lens, cam.data.sensor_width = OFFICE_LENS, 36.0
        cam.data.clip_start = 0.01
        scene.collection.objects.link(cam)
        cam.matrix_world = mathutils.Matrix(look_at(eye, target).tolist())
        if paths is not None:
            bg = cam.data.background_images.new()
            bg.image = bpy.data.images.load(paths[i], check_existing=True)
            cam.data.show_background_images = True
        cams.append(cam)
    scene.render.resolution_x, scene.render.resolution_y = OFFICE_PHOTO
    scene.render.resolution_percentage = 100
    bpy.context.view_layer.update()
    return cams


def office_photos(samples=32, texture_size=48):
    """8-bit sRGB photos (Standard view transform, the listed exposures) of the demo office
    (seed 0, two lamps, build_office) by OFFICE_CAMERAS, Cycles, cached.  The lamps are hidden
    from camera rays (the ceiling behind them shows, as the bake has it).  Returns the paths;
    the scene is left built, with its cameras."""
    bpy = _bpy()
    from scenes.office import build_office  # noqa: PLC0415
    key = hashlib.sha256(repr((VERSION, tuple(bpy.app.version), "office", OFFICE_CAMERAS,
                               OFFICE_LENS, OFFICE_PHOTO, samples, texture_size)).encode()
                         ).hexdigest()[:32]
    folder = os.path.join(cache_dir(), key)
    paths = [os.path.join(folder, f"photo{i}.png") for i in range(len(OFFICE_CAMERAS))]
    bpy.ops.wm.read_factory_settings(use_empty=True)
    info = build_office(seed=0, n_lamps=2, texture_size=texture_size)
    scene = bpy.context.scene
    if all(os.path.exists(p) for p in paths):
        office_cameras(bpy, scene, paths)
        return paths, info
    os.makedirs(folder, exist_ok=True)
    cams = office_cameras(bpy, scene)
    for name in info.lamps:
        scene.objects[name].visible_camera = False
    cy = scene.cycles
    cy.device, cy.samples, cy.seed = "CPU", int(samples), 0
    cy.use_adaptive_sampling = False
    cy.use_denoising = False
    scene.view_settings.view_transform = "Standard"
    scene.render.image_settings.file_format = "PNG"
    scene.render.image_settings.color_mode = "RGB"
    scene.render.image_settings.color_depth = "8"
    for cam, (_, _, stops), path in zip(cams, OFFICE_CAMERAS, paths):
        scene.camera = cam
        scene.view_settings.exposure = stops
        scene.render.filepath = path + ".tmp.png"
        bpy.ops.render.render(write_still=True)
        os.replace(path + ".tmp.png", path)
    scene.view_settings.exposure = 0.0
    for name in info.lamps:
        scene.objects[name].visible_camera = True
    for cam, path in zip(cams, paths):
        bg = cam.data.background_images.new()
        bg.image = bpy.data.images.load(path, check_existing=True)
        cam.data.show_background_images = True
    return paths, info


PATH_FRAMES = 30
PATH_CAMERA = dict(lens=35.0, sensor_width=36.0, width=640, height=480)


def path_views():
    """A camera path around the pose board: an arc of 60 degrees at 1.6-2.4 m, rising, with a
    slow roll, looking at a point drifting over the board."""
    views = []
    for i in range(PATH_FRAMES):
        s = i / (PATH_FRAMES - 1)
        az = np.radians(-30 + 60 * s)
        d = 1.6 + 0.8 * s
        eye = np.array([d * np.sin(az) * 0.8, -0.3 + 0.4 * s, d * np.cos(az)])
        aim = np.array([0.05 * np.sin(3 * s), 0.04 * s, 0.0])
        # "up" along the board's image top (+Y): the camera looks down at the board
        views.append(dict(PATH_CAMERA, matrix_world=look_at(eye, aim, up=(0, 1, 0),
                                                            roll_deg=10 * s).tolist()))
    return views


def pose_path_set(samples=16):
    """Renders of the pose board along path_views (640 x 480), for the path smoothing."""
    return render_board_views(board_spec(POSE_BOARD), path_views(), samples=samples, name="path")


def plain_detections(dets):
    """The same board detections with CharucoDetector's own corners (plain OpenCV), beside
    ours re-refined: what the benchmark and the tests compare against."""
    out = {}
    for k, d in dets.items():
        p = copy.copy(d)
        p.corners = d.raw
        out[k] = p
    return out


def project_office(texture_size=48):
    """The photos of :func:`office_photos` projected onto the office's UV maps by the core
    (the views as Project Photos reads them): (info, the projection's result, its seconds,
    the views).  The add-on is registered from the checkout."""
    import importlib
    bpy = _bpy()
    from relight_addon.core.capture import projection
    from scenes.addon import register_repo_addon
    register_repo_addon()
    _, info = office_photos(texture_size=texture_size)
    bridge = importlib.import_module("relight_ext.relight_addon.blender.capture")
    views, _ = bridge.posed_views(bpy.context.scene)
    dg = bpy.context.evaluated_depsgraph_get()
    targets = []
    for name in info.objects:
        tris, uvs = bridge.mesh_triangles(bpy.data.objects[name], dg, "UVMap")
        targets.append(projection.Target(name, tris, uvs, (texture_size, texture_size)))
    tris, owners = bridge.scene_triangles(dg)
    t0 = time.perf_counter()
    result = projection.project(targets, views, tris, owners)
    return info, result, time.perf_counter() - t0, views
