"""HDR merge and environment maps against known radiance.

Truth: a Cycles render (linear radiance, 32-bit EXR) of a shipped HDRI seen by a camera; its
brackets are made by exposing it for known times through a known non-linear response
(``scenes.capture.camera_response``) and quantising to 8 bits.  The merge must match the
render's log2 radiance after one global scale: <= 0.03 mean, <= 0.15 at the 95th percentile
(the issue's targets), and beat OpenCV's own MergeDebevec with the same response.  The
environment maps are compared with the HDRI itself: a rendered mirror ball, and six posed
90-degree renders (a cube map), both slow on a cold cache.
"""
import importlib
import json
import os

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
cv2 = pytest.importorskip("cv2")

from relight_addon.core.capture import CaptureError  # noqa: E402
from relight_addon.core.capture import hdr  # noqa: E402
from scenes import capture as sc  # noqa: E402
from scenes.addon import register_repo_addon  # noqa: E402

TIMES = np.array([2.0 ** k for k in range(-8, 3, 2)])      # 1/256 s .. 4 s, 2 stops apart


@pytest.fixture(scope="module")
def radiance():
    return sc.radiance_render()


@pytest.fixture(scope="module")
def bridge():
    register_repo_addon()
    return importlib.import_module("relight_ext.relight_addon.blender.capture")


def log2_errors(merged, truth, images):
    """|log2 merged - log2 truth| after the median offset, over the pixels some bracket
    exposes well (8-bit value in 6-249)."""
    lm = np.log2(np.maximum(np.asarray(merged, np.float64).mean(-1), 1e-30))
    lt = np.log2(np.asarray(truth, np.float64).mean(-1))
    ok = np.zeros(lt.shape, bool)
    for im in images:
        g = im.mean(-1)
        ok |= (g > 5) & (g < 250)
    e = lm[ok] - lt[ok]
    e = np.abs(e - np.median(e))
    return e.mean(), np.percentile(e, 95), ok.mean()


def test_merge_meets_the_targets(radiance):
    images = sc.brackets(radiance, TIMES)
    response = hdr.recover_response(images, TIMES)
    res = hdr.merge(images, TIMES, response)
    mean, p95, covered = log2_errors(res["radiance"], radiance, images)
    assert covered > 0.99
    assert mean <= 0.03 and p95 <= 0.15, (mean, p95)
    plain = hdr.merge_opencv(images, TIMES, response)
    pm, pp, _ = log2_errors(plain, radiance, images)
    assert mean < pm and p95 < pp, (mean, p95, pm, pp)
    assert np.isfinite(res["radiance"]).all() and res["radiance"].min() > 0


def _write_brackets(folder, images, times, exif_for=(), sidecar_for=None):
    """PNG brackets; EXIF ExposureTime (eXIf chunk) on the indices in ``exif_for``, the others
    in exposures.json (all of them when ``sidecar_for`` is None)."""
    from PIL import Image
    os.makedirs(folder, exist_ok=True)
    entries = []
    for i, (img, t) in enumerate(zip(images, times)):
        name = f"bracket_{i}.png"
        pil = Image.fromarray(img[..., ::-1])
        if i in exif_for:
            exif = Image.Exif()
            exif[hdr.EXIF_IFD] = {hdr.EXPOSURE_TIME: float(t)}   # the Exif sub-IFD
            pil.save(os.path.join(folder, name), exif=exif)
        else:
            pil.save(os.path.join(folder, name))
            if sidecar_for is None or i in sidecar_for:
                entries.append({"file": name, "exposure_time": float(t)})
    if entries:
        with open(os.path.join(folder, hdr.SIDECAR), "w") as fh:
            json.dump({"format": hdr.SIDECAR_FORMAT, "images": entries}, fh)
    return str(folder)


def test_exposure_times_from_exif_and_sidecar(tmp_path, radiance):
    images = sc.brackets(radiance[:40, :50], TIMES[:3])
    folder = _write_brackets(tmp_path / "b", images, TIMES[:3], exif_for=(0, 2))
    assert hdr.exif_exposure(os.path.join(folder, "bracket_0.png")) == pytest.approx(TIMES[0])
    assert hdr.exif_exposure(os.path.join(folder, "bracket_1.png")) is None
    names, _, times = hdr.read_brackets(folder)
    assert names == ["bracket_0.png", "bracket_1.png", "bracket_2.png"]
    np.testing.assert_allclose(times, TIMES[:3])


def test_merge_hdr_operator(tmp_path, radiance, bridge):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    images = sc.brackets(radiance, TIMES)
    folder = _write_brackets(tmp_path / "brackets", images, TIMES, exif_for=(1, 4))
    out = tmp_path / "merged.exr"
    bpy.ops.relight.merge_hdr(directory=folder, output=str(out))
    merged = bridge.read_float_image(str(out))
    assert merged.shape == radiance.shape
    mean, p95, _ = log2_errors(merged, radiance, images)
    assert mean <= 0.03 and p95 <= 0.15, (mean, p95)
    assert bpy.context.scene.world is None                    # a photo does not touch the World


def test_merge_hdr_bad_input(tmp_path, radiance):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    images = sc.brackets(radiance[:60, :80], TIMES[:3])
    out = tmp_path / "out.exr"
    run = lambda d, **kw: bpy.ops.relight.merge_hdr(directory=str(d), output=str(out), **kw)  # noqa: E731
    with pytest.raises(RuntimeError, match="at least 2 bracketed photos"):
        run(_write_brackets(tmp_path / "one", images[:1], TIMES[:1]))
    with pytest.raises(RuntimeError, match="different sizes"):
        run(_write_brackets(tmp_path / "sizes", [images[0], images[1][:50]], TIMES[:2]))
    with pytest.raises(RuntimeError, match="No exposure time for 'bracket_1.png'"):
        run(_write_brackets(tmp_path / "times", images, TIMES[:3], sidecar_for=(0, 2)))
    with pytest.raises(RuntimeError, match="same exposure time"):
        run(_write_brackets(tmp_path / "same", images[:2], [0.1, 0.1]))
    deep = tmp_path / "deep"
    deep.mkdir()
    for i in range(2):
        cv2.imwrite(str(deep / f"b{i}.png"), images[i].astype(np.uint16) * 257)
    with pytest.raises(RuntimeError, match="not an 8-bit photo"):
        run(deep)
    with pytest.raises(RuntimeError, match="must be an OpenEXR"):
        bpy.ops.relight.merge_hdr(directory=str(tmp_path / "one"), output=str(tmp_path / "o.png"))
    with pytest.raises(RuntimeError, match="No camera of the scene has a photo"):
        run(tmp_path, environment="FRAMES")
    assert not out.exists() and bpy.context.scene.world is None


def _env_errors(env, truth, mask=None, size=64):
    """log2 luminance error of two equirects box-filtered to size x size/2, after the median
    offset (returned too), over ``mask`` (directions fully inside it)."""
    a = cv2.resize(env, (size, size // 2), interpolation=cv2.INTER_AREA)
    b = cv2.resize(truth, (size, size // 2), interpolation=cv2.INTER_AREA)
    ok = np.ones(a.shape[:2], bool)
    if mask is not None:
        ok = cv2.resize(mask.astype(np.float32), (size, size // 2), interpolation=cv2.INTER_AREA) > 0.999
    e = np.log2(np.maximum(a.mean(-1), 1e-6)) - np.log2(np.maximum(b.mean(-1), 1e-6))
    offset = np.median(e[ok])
    e = np.abs(e - offset)[ok]
    return offset, e.mean(), np.percentile(e, 95)


@pytest.mark.slow
def test_mirror_ball_environment(tmp_path, bridge):
    """A 256 px orthographic render of a mirror ball under the courtyard HDRI, through the
    operator (the ball photo is one EXR; the camera is the render's): the equirect it writes
    against the HDRI, away from the directions straight behind the ball."""
    ball = sc.mirror_ball_render()["image"]
    bpy.ops.wm.read_factory_settings(use_empty=True)
    folder = tmp_path / "ball"
    folder.mkdir()
    bridge.write_exr(str(folder / "ball.exr"), ball)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    bpy.context.scene.collection.objects.link(cam)
    bpy.context.scene.camera = cam
    bridge.set_matrix_world(cam, sc.look_at((0, -10, 0), (0, 0, 0)))
    out = tmp_path / "env.exr"
    bpy.ops.relight.merge_hdr(directory=str(folder), output=str(out), environment="MIRROR_BALL",
                              width=256)
    env = bridge.read_float_image(str(out))
    assert env.shape == (128, 256, 3)
    behind = np.degrees(np.arccos(np.clip(hdr.equirect_directions(256)[..., 1], -1, 1))) < 30
    offset, mean, p95 = _env_errors(env, sc.hdri_pixels(), ~behind)
    assert abs(offset) < 0.02 and mean < 0.06 and p95 < 0.2, (offset, mean, p95)
    nodes = bpy.context.scene.world.node_tree.nodes
    assert any(n.bl_idname == "ShaderNodeTexEnvironment" and n.image is not None for n in nodes)


def _posed_cube_frames(tmp_path, bridge):
    """A factory-empty file whose cameras are six 90-degree renders from the origin
    (sc.cube_frames, which renders them first), each with its render as background image."""
    frames = sc.cube_frames()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.resolution_x = scene.render.resolution_y = 128
    for i, (K, M, img) in enumerate(frames):
        cam = bpy.data.objects.new(f"Cam{i}", bpy.data.cameras.new(f"Cam{i}"))
        scene.collection.objects.link(cam)
        cam.data.lens, cam.data.sensor_width = 18.0, 36.0
        bridge.set_matrix_world(cam, M)
        path = str(tmp_path / f"frame{i}.exr")
        bridge.write_exr(path, img)
        bridge.set_camera_photo(cam, path)


@pytest.mark.slow
def test_posed_frames_environment(tmp_path, bridge):
    """Six 90-degree renders from the origin, each a camera of the scene with its render as
    background image: the environment they see against the HDRI."""
    _posed_cube_frames(tmp_path, bridge)
    out = tmp_path / "env.exr"
    bpy.ops.relight.merge_hdr(output=str(out), environment="FRAMES", width=256)
    env = bridge.read_float_image(str(out))
    offset, mean, p95 = _env_errors(env, sc.hdri_pixels())
    assert abs(offset) < 0.02 and mean < 0.05 and p95 < 0.15, (offset, mean, p95)


@pytest.mark.parametrize("environment, at", [("NONE", 0.2), ("FRAMES", 0.3)])
def test_merge_hdr_cancelled_midway_changes_nothing(tmp_path, radiance, bridge, environment, at):
    """Esc while the response is recovered (brackets) or while the posed frames are sampled
    (an equirect): no EXR, the World untouched; the job run to its end writes it."""
    import importlib
    from helpers.blender import run_cancelled_at
    folder = str(tmp_path)
    if environment == "FRAMES":
        _posed_cube_frames(tmp_path, bridge)
    else:
        bpy.ops.wm.read_factory_settings(use_empty=True)
        folder = _write_brackets(tmp_path / "brackets", sc.brackets(radiance, TIMES), TIMES,
                                 exif_for=(1, 4))
    scene = bpy.context.scene
    ops = importlib.import_module("relight_ext.operators.capture")
    precompute = importlib.import_module("relight_ext.operators.precompute")
    out = tmp_path / "out.exr"
    op = type("Op", (), dict(directory=folder, output=str(out), method="DEBEVEC",
                             environment=environment, width=128, ball_x=-1.0, ball_y=-1.0,
                             ball_radius=-1.0, set_world=True))()
    solve = precompute.SolveJob(ops.MergeJob(op, bpy.context))
    seen = run_cancelled_at(solve, at)
    assert solve.state == "cancelled" and solve.result is None and max(seen) < 0.96
    assert not out.exists() and scene.world is None
    job = ops.MergeJob(op, bpy.context)
    assert "EXR out.exr" in job.finish(bpy.context, job.compute())
    assert out.exists()


def test_environment_directions_match_blender():
    """The equirect convention: our direction of a texel, looked up by our own sampler, is
    that texel; and +X is the image centre, +Z the top row, as Blender's Environment Texture
    (checked against Cycles by the posed-frames test)."""
    d = hdr.equirect_directions(64)
    env = np.random.default_rng(0).random((32, 64, 3)).astype(np.float32)
    np.testing.assert_allclose(hdr.sample_equirect(env, d), env, atol=1e-5)
    uv = hdr.direction_to_equirect(np.array([[1.0, 0, 0], [0, 0, 1.0], [0, 1.0, 0]]))
    np.testing.assert_allclose(uv[0], (0.5, 0.5))
    assert uv[1, 1] == pytest.approx(1.0)
    np.testing.assert_allclose(uv[2], (0.25, 0.5))          # +Y left of the centre
    with pytest.raises(CaptureError):
        hdr.read_brackets("/nonexistent/folder")
