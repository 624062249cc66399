"""Capture benchmark (issue 46): calibration, corners, pose, path smoothing, HDR, environment
maps, photo projection, relighting from projected textures, speeds.  Writes
results/capture.md and results/capture.png.

Every figure is measured once by this script on Blender renders (scenes/capture.py, cached);
the speeds are wall-clock medians of 3 runs of a whole process timed by farm-bench where it
is installed (else by this script's own clock, said in the table).

Usage: python benchmarks/bench_capture.py [--only calibration,pose,path,hdr,env,projection,relight,speed]
       python benchmarks/bench_capture.py speed-calibration DIR     (the timed commands)
       python benchmarks/bench_capture.py speed-projection DIR
"""
from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, ROOT)
RESULTS = os.path.join(HERE, "results")
SECTIONS = ("calibration", "pose", "path", "hdr", "env", "projection", "relight", "speed")


def _cv2():
    import cv2  # noqa: PLC0415
    return cv2


# ------------------------------------------------------------------------------------------
# Calibration and corners
# ------------------------------------------------------------------------------------------


def _calib_errors(calib, K):
    k = calib.camera_matrix
    return dict(rms=calib.rms, fx=100 * (k[0, 0] / K[0, 0] - 1), fy=100 * (k[1, 1] / K[1, 1] - 1),
                cx=k[0, 2] - K[0, 2], cy=k[1, 2] - K[1, 2],
                std_c=float(np.max(calib.std[2:4])) if len(calib.std) >= 4 else float("nan"),
                views=len(calib.view_rms))


def calibration():
    cv2 = _cv2()
    from relight_addon.core.capture import board as bd
    from relight_addon.core.capture import calibration as cal
    from scenes import capture as sc
    spec = sc.board_spec(sc.CALIBRATION_BOARD)
    det = bd.Detector(spec)
    rows, corners = [], {}
    degradation = []
    for model in ("A", "B", "C", "D"):
        truth = sc.calibration_set(model)
        K = np.array(truth["K"][0])
        imgs = truth.get("images") or [cv2.imread(p, cv2.IMREAD_GRAYSCALE) for p in truth["paths"]]
        dets = {os.path.basename(p): det.detect(im) for p, im in zip(truth["paths"], imgs)}
        for label, dd in (("ours (re-refined)", dets),
                          ("plain OpenCV", sc.plain_detections(dets))):
            c = cal.calibrate(dd, (640, 480), spec, flags=cv2.CALIB_FIX_K3)
            row = dict(model=model, method=label, **_calib_errors(c, K))
            if model == "D":
                row["k1"], row["k2"] = c.dist_coeffs[:2]
            rows.append(row)
        if model != "D":
            ours, raw = [], []
            for i, d in enumerate(dets.values()):
                uv = _truth_corners(truth, i, spec)[d.ids]
                ours.append(d.corners - uv)
                raw.append(d.raw - uv)
            corners[model] = (np.concatenate(ours), np.concatenate(raw))
        if model == "B":        # sensor noise and mild blur added to the renders
            rng = np.random.default_rng(0)
            for noise, blur in ((0, 0), (2, 0), (4, 0), (0, 0.7), (0, 1.2), (4, 1.2)):
                out = {}
                for p, im in zip(truth["paths"], imgs):
                    x = im.astype(np.float32)
                    if blur:
                        x = cv2.GaussianBlur(x, (0, 0), blur)
                    if noise:
                        x = x + rng.normal(0, noise, x.shape)
                    out[os.path.basename(p)] = np.clip(np.rint(x), 0, 255).astype(np.uint8)
                dd = {k: det.detect(v) for k, v in out.items()}
                for label, d2 in (("ours", dd), ("plain", sc.plain_detections(dd))):
                    c = cal.calibrate(d2, (640, 480), spec, flags=cv2.CALIB_FIX_K3)
                    e = [d.corners - _truth_corners(truth, i, spec)[d.ids]
                         for i, d in enumerate(d2.values())]
                    e = np.concatenate(e)
                    degradation.append(dict(noise=noise, blur=blur, method=label,
                                            corner_rms=float(np.sqrt((e ** 2).mean())),
                                            **_calib_errors(c, K)))
        print("calibration", model, flush=True)
    return {"rows": rows, "corners": {m: dict(
        ours_mean=o.mean(axis=0).tolist(), ours_rms=float(np.sqrt((o ** 2).mean())),
        raw_mean=r.mean(axis=0).tolist(), raw_rms=float(np.sqrt(((r - r.mean(0)) ** 2).mean())),
        n=len(o)) for m, (o, r) in corners.items()}, "degradation": degradation}


def _truth_corners(truth, i, spec):
    from scenes import capture as sc
    K = np.array(truth["K"][i])
    frame = sc.board_frame_world(np.array(truth["board_matrix_world"]), spec.size)
    T = sc.cv_pose(np.array(truth["matrix_world"][i]), frame)
    pc = spec.corner_points() @ T[:3, :3].T + T[:3, 3]
    uv = pc @ K.T
    return uv[:, :2] / uv[:, 2:]


# ------------------------------------------------------------------------------------------
# Pose and path
# ------------------------------------------------------------------------------------------

def _pose_error(frame, pose, m):
    from relight_addon.core.capture import pose as ps
    got = ps.camera_world_matrix(frame, pose)
    return _matrix_error(got, m)


def _matrix_error(got, m):
    r = got[:3, :3].T @ m[:3, :3]
    angle = np.degrees(np.arccos(np.clip((np.trace(r) - 1) / 2, -1, 1)))
    return float(angle), float(1000 * np.linalg.norm(got[:3, 3] - m[:3, 3]))


def pose():
    cv2 = _cv2()
    from relight_addon.core.capture import board as bd
    from relight_addon.core.capture import pose as ps
    from scenes import capture as sc
    spec = sc.board_spec(sc.POSE_BOARD)
    truth = sc.pose_set()
    det = bd.Detector(spec)
    frame = sc.board_frame_world(np.array(truth["board_matrix_world"]), spec.size)
    out = {}
    for i, path in enumerate(truth["paths"]):
        d = det.detect(cv2.imread(path, cv2.IMREAD_GRAYSCALE))
        K = np.array(truth["K"][i])
        m = np.array(truth["matrix_world"][i])
        for label, dd in (("ours", d), ("plain", sc.plain_detections({0: d})[0])):
            err = _pose_error(frame, ps.board_pose(dd, spec, K, np.zeros(5)), m)
            out.setdefault((truth["distance"][i], label), []).append(err)
    rows = []
    for (dist, label), errs in sorted(out.items()):
        e = np.array(errs)
        rows.append(dict(distance=dist, method=label, rot_mean=float(e[:, 0].mean()),
                         rot_max=float(e[:, 0].max()), pos_mean=float(e[:, 1].mean()),
                         pos_max=float(e[:, 1].max()), views=len(e)))
    print("pose", flush=True)
    return {"rows": rows}


def path():
    """The camera path rendered, with sensor noise (sigma 3 and 8 grey levels) and a frame
    whose board is half covered: raw poses against the smoothed ones."""
    cv2 = _cv2()
    from relight_addon.core.capture import board as bd
    from relight_addon.core.capture import pose as ps
    from scenes import capture as sc
    spec = sc.board_spec(sc.POSE_BOARD)
    truth = sc.pose_path_set()
    det = bd.Detector(spec)
    frame = sc.board_frame_world(np.array(truth["board_matrix_world"]), spec.size)
    gt = np.array(truth["matrix_world"])
    rows, missing = [], {}
    for noise in (3.0, 8.0):
        rng = np.random.default_rng(1)
        mats, valid = [], []
        for i, p in enumerate(truth["paths"]):
            im = cv2.imread(p, cv2.IMREAD_GRAYSCALE).astype(np.float32)
            im = np.clip(np.rint(im + rng.normal(0, noise, im.shape)), 0, 255).astype(np.uint8)
            if i == 17:                                  # an occluder over half of the board
                im[:, : im.shape[1] // 2] = 120
            try:
                pose_i = ps.board_pose(det.detect(im), spec, np.array(truth["K"][i]), np.zeros(5))
                mats.append(ps.camera_world_matrix(frame, pose_i))
                valid.append(True)
            except Exception:
                mats.append(np.eye(4))
                valid.append(False)
        mats, valid = np.stack(mats), np.array(valid)
        missing[noise] = int((~valid).sum())
        for label, smoothing, reject in (("raw poses", 0.0, False),
                                         ("outliers rejected", 0.0, True),
                                         ("slerp smoothing 0.3", 0.3, True),
                                         ("slerp smoothing 0.5", 0.5, True),
                                         ("slerp smoothing 0.7", 0.7, True)):
            if smoothing == 0 and not reject:
                sm, rej, ok = mats, np.zeros(len(mats), bool), valid
            else:
                sm, rej = ps.smooth_path(mats, valid, smoothing, reject)
                ok = np.ones(len(mats), bool)
            e = np.array([_matrix_error(sm[i], gt[i]) for i in range(len(gt)) if ok[i]])
            rows.append(dict(noise=noise, method=label, rot_mean=float(e[:, 0].mean()),
                             rot_max=float(e[:, 0].max()), pos_mean=float(e[:, 1].mean()),
                             pos_max=float(e[:, 1].max()), rejected=int(rej.sum()),
                             frames=int(ok.sum())))
    print("path", flush=True)
    return {"rows": rows, "frames": len(gt), "no_board": missing}


# ------------------------------------------------------------------------------------------
# HDR and environments
# ------------------------------------------------------------------------------------------

def _log2_errors(merged, truth, images):
    lm = np.log2(np.maximum(np.asarray(merged, np.float64).mean(-1), 1e-30))
    lt = np.log2(np.asarray(truth, np.float64).mean(-1))
    ok = np.zeros(lt.shape, bool)
    for im in images:
        g = im.mean(-1)
        ok |= (g > 5) & (g < 250)
    e = lm[ok] - lt[ok]
    e = np.abs(e - np.median(e))
    return float(e.mean()), float(np.percentile(e, 95))


def hdr():
    from relight_addon.core.capture import hdr as H
    from scenes import capture as sc
    rad = sc.radiance_render()
    rows = []
    for label, times in (("6 brackets, 2 stops apart (1/256-4 s)", [2.0 ** k for k in range(-8, 3, 2)]),
                         ("4 brackets, 3 stops apart (1/256-2 s)", [2.0 ** k for k in range(-8, 2, 3)]),
                         ("3 brackets, 4 stops apart (1/256-1 s)", [2.0 ** k for k in range(-8, 1, 4)])):
        times = np.array(times)
        imgs = sc.brackets(rad, times)
        resp_d = H.recover_response(imgs, times, "DEBEVEC")
        resp_r = H.recover_response(imgs, times, "ROBERTSON")
        for method, merged in (("ours: Debevec response, inverse-variance merge",
                                H.merge(imgs, times, resp_d)["radiance"]),
                               ("OpenCV Debevec (response + MergeDebevec)",
                                H.merge_opencv(imgs, times, resp_d)),
                               ("OpenCV Robertson (response + MergeRobertson)",
                                H.merge_opencv(imgs, times, resp_r, "ROBERTSON"))):
            m, p = _log2_errors(merged, rad, imgs)
            rows.append(dict(brackets=label, method=method, mean=m, p95=p))
    print("hdr", flush=True)
    return {"rows": rows, "range": H.dynamic_range_stops(rad), "shape": list(rad.shape)}


def _env_errors(env, truth, mask=None, size=64):
    cv2 = _cv2()
    a = cv2.resize(env, (size, size // 2), interpolation=cv2.INTER_AREA)
    b = cv2.resize(truth, (size, size // 2), interpolation=cv2.INTER_AREA)
    ok = np.ones(a.shape[:2], bool)
    if mask is not None:
        ok = cv2.resize(mask.astype(np.float32), (size, size // 2), interpolation=cv2.INTER_AREA) > 0.999
    e = np.log2(np.maximum(a.mean(-1), 1e-6)) - np.log2(np.maximum(b.mean(-1), 1e-6))
    off = float(np.median(e[ok]))
    e = np.abs(e - off)[ok]
    return off, float(e.mean()), float(np.percentile(e, 95))


def env():
    from relight_addon.core.capture import hdr as H
    from scenes import capture as sc
    truth = sc.hdri_pixels()
    rows = []
    ball = sc.mirror_ball_render()["image"]
    e, behind = H.mirror_ball_to_equirect(ball, 256)
    d = H.equirect_directions(256)
    away = np.degrees(np.arccos(np.clip(d[..., 1], -1, 1))) >= 30
    for size in (128, 64, 32):
        off, m, p = _env_errors(e, truth, away, size)
        rows.append(dict(source="mirror ball (256 px render)", size=size, scale=2 ** off,
                         mean=m, p95=p))
    frames = sc.cube_frames()
    e2, seen = H.frames_to_equirect([(K, M[:3, :3], im) for K, M, im in frames], 256)
    for size in (128, 64, 32):
        off, m, p = _env_errors(e2, truth, None, size)
        rows.append(dict(source="6 posed frames (128 px, 90 degrees)", size=size, scale=2 ** off,
                         mean=m, p95=p))
    print("env", flush=True)
    return {"rows": rows}


# ------------------------------------------------------------------------------------------
# Projection and relighting
# ------------------------------------------------------------------------------------------

def projection_section():
    from relight_addon.core.texture.colour import delta_e_2000, linear_rgb_to_lab
    from scenes import bake
    from scenes import capture as sc
    info, res, seconds, views = sc.project_office()
    truth = bake.bake_lighting(dict(info.lamp_powers), samples=256, seed=0, texture_size=48)
    truth2 = bake.bake_lighting(dict(info.lamp_powers), samples=256, seed=1, texture_size=48)
    rows, all_seen, all_hole, floor = [], [], [], []

    def de(a, b):
        return delta_e_2000(linear_rgb_to_lab(np.clip(a, 0, None)), linear_rgb_to_lab(np.clip(b, 0, None)))

    for m in res.meshes:
        d = de(m.texture, truth[m.name])
        n = de(truth2[m.name], truth[m.name])
        holes = m.covered & ~m.seen
        rows.append(dict(object=m.name, seen=float(m.seen.sum() / max(m.covered.sum(), 1)),
                         mean=float(d[m.seen].mean()) if m.seen.any() else float("nan"),
                         p95=float(np.percentile(d[m.seen], 95)) if m.seen.any() else float("nan"),
                         holes=int(holes.sum()),
                         hole_mean=float(d[holes].mean()) if holes.any() else float("nan"),
                         floor=float(n[m.covered].mean()), views=len(m.views)))
        all_seen.append(d[m.seen])
        all_hole.append(d[holes])
        floor.append(n[m.covered])
    s, h, f = np.concatenate(all_seen), np.concatenate(all_hole), np.concatenate(floor)
    total = dict(object="all", seen=float(len(s) / sum(int(m.covered.sum()) for m in res.meshes)),
                 mean=float(s.mean()), p95=float(np.percentile(s, 95)), holes=int(len(h)),
                 hole_mean=float(h.mean()) if len(h) else float("nan"), floor=float(f.mean()),
                 views=len(views))
    gains = {k: [round(float(x), 3) for x in v] for k, v in res.gains.items()}
    print("projection", flush=True)
    return {"rows": rows, "total": total, "gains": gains, "seconds": seconds,
            "textures": {m.name: m.texture for m in res.meshes}}


def relight_section(projected):
    """Precompute (per-texel shadow removal, draft and medium) on the projected textures and on
    baked textures of the same lighting; relit against bakes of each target lighting."""
    import bpy  # noqa: F401
    sys.path.insert(0, HERE)
    import shadowfree_data as sd
    from relight_addon.core.relight.shadowfree import ShadowFreeOptions, shadow_free
    from relight_addon.core.texture.colour import delta_e_2000, linear_rgb_to_lab
    from relight_addon.core.texture.mapping import rasterize_patches
    from scenes.office import office_scene_data
    info = sd.build_scene()
    per = sd.lamp_bakes(info, 256, range(2))
    photo_b, truth_b = sd.halves(per)
    data = info.data
    names = [s.name for s in data.surfaces]
    lamps = [lp.name for lp in data.lamps]
    lightings = {"original": {}}
    for k in lamps:
        lightings[f"{k[-1]} off"] = {k: 0.0}
        lightings[f"{k[-1]} doubled"] = {k: 2.0}
    LUM = np.array([0.2126, 0.7152, 0.0722])
    sources = {"baked textures": sd.combine(photo_b, {}), "projected photos": projected}
    rows = []
    for src, textures in sources.items():
        scene = office_scene_data(data, textures)
        shapes = [im.texels.shape[:2] for im in scene.images]
        tm = rasterize_patches(scene.uv, scene.image, shapes)
        truth = {lab: tm.gather([sd.combine(truth_b, I)[n] for n in names]).astype(np.float64)
                 for lab, I in lightings.items()}
        white = float(np.percentile(truth["original"] @ LUM, 99))
        for preset in ("draft", "medium"):
            t0 = time.perf_counter()
            res = shadow_free(scene, ShadowFreeOptions(mode="texel", preset=preset))
            dt = time.perf_counter() - t0
            for lab, I in lightings.items():
                out = res.relit([I.get(k, 1.0) for k in lamps])
                relit = tm.gather([out[i] for i in range(len(names))]).astype(np.float64)
                d = delta_e_2000(linear_rgb_to_lab(np.clip(relit / white, 0, None)),
                                 linear_rgb_to_lab(np.clip(truth[lab] / white, 0, None)))
                rows.append(dict(source=src, preset=preset, lighting=lab, mean=float(d.mean()),
                                 p95=float(np.percentile(d, 95)), seconds=dt))
        print("relight", src, flush=True)
    return {"rows": rows}


# ------------------------------------------------------------------------------------------
# Speeds
# ------------------------------------------------------------------------------------------

def speed_calibration(folder):
    """The timed command: detect the board in every image of ``folder`` and calibrate."""
    cv2 = _cv2()
    from relight_addon.core.capture import board as bd
    from relight_addon.core.capture import calibration as cal
    with open(os.path.join(folder, "board.json")) as fh:
        spec = bd.BoardSpec(**json.load(fh))
    det = bd.Detector(spec)
    dets, size = {}, None
    for p in cal.list_images(folder):
        im = cal.read_image(p, cv2.IMREAD_GRAYSCALE)
        size = (im.shape[1], im.shape[0])
        dets[p] = det.detect(im)
    c = cal.calibrate(dets, size, spec, flags=cv2.CALIB_FIX_K3)
    print(json.dumps({"views": len(c.view_rms), "rms": c.rms}))


def speed_projection(folder):
    """The timed command: 8 photos of 2048^2 onto a 100k-face model, 2048^2 texture."""
    cv2 = _cv2()
    from relight_addon.core.capture import projection
    from relight_addon.core.texture.colour import srgb_to_linear
    z = np.load(os.path.join(folder, "scene.npz"))
    views = []
    for i in range(int(z["n"])):          # 8-bit sRGB photos, decoded as the operator does
        img = cv2.imread(os.path.join(folder, f"photo{i}.png"))[..., ::-1]
        views.append(projection.View(f"v{i}", z[f"K{i}"], z[f"R{i}"], z[f"t{i}"],
                                     srgb_to_linear(img.astype(np.float32) / 255.0)))
    target = projection.Target("model", z["tris"], z["uvs"], (2048, 2048))
    res = projection.project([target], views, z["tris"], ["model"] * len(z["tris"]))
    print(json.dumps({"seen": float(res.meshes[0].seen.mean()), "faces": int(len(z["tris"]))}))


def _prepare_speed(tmp):
    """Photos and scene for the two timed commands (written once)."""
    cv2 = _cv2()
    from relight_addon.core.capture import board as bd
    from scenes import capture as sc
    cal_dir = os.path.join(tmp, "calibration")
    if not os.path.exists(os.path.join(cal_dir, "board.json")):
        os.makedirs(cal_dir, exist_ok=True)
        spec = bd.BoardSpec(9, 6, 0.04, 0.03)
        K = np.array([[1400.0, 0, 645.3], [0, 1400.0, 478.9], [0, 0, 1]])
        views = sc.orbit_views(25, spec.size, dict(lens=1400 * 36 / 1280, sensor_width=36.0,
                                                   width=1280, height=960), seed=9)
        frame = sc.board_frame_world(np.eye(4), spec.size)
        for i, v in enumerate(views):
            img = sc.warp_board_view(spec, K, sc.cv_pose(np.array(v["matrix_world"]), frame),
                                     (1280, 960))
            cv2.imwrite(os.path.join(cal_dir, f"view_{i:02d}.png"), img)
        with open(os.path.join(cal_dir, "board.json"), "w") as fh:
            json.dump(dict(squares_x=9, squares_y=6, square_length=0.04, marker_length=0.03,
                           dictionary="DICT_5X5_100"), fh)
    proj_dir = os.path.join(tmp, "projection")
    if not os.path.exists(os.path.join(proj_dir, "scene.npz")):
        os.makedirs(proj_dir, exist_ok=True)
        _speed_scene(proj_dir)
    return cal_dir, proj_dir


def _speed_scene(folder):
    """A 100k-triangle height field (1 x 1 m, bumps) with a grid UV atlas, 8 cameras around
    it and 8 random-texture 2048^2 photos (8-bit PNG)."""
    n = 224                                   # (n - 1)^2 * 2 = 99,458 triangles
    y, x = np.mgrid[0:n, 0:n] / (n - 1.0)
    z = 0.05 * np.sin(8 * x) * np.cos(6 * y)
    v = np.stack([x - 0.5, y - 0.5, z], -1).reshape(-1, 3)
    uv = np.stack([x, y], -1).reshape(-1, 2)
    i = np.arange(n - 1)
    a = (i[:, None] * n + i[None, :]).ravel()
    quads = np.stack([a, a + 1, a + n + 1, a + n], 1)
    tri = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    from scenes.capture import look_at
    out = {"tris": v[tri], "uvs": uv[tri], "n": 8}
    rng = np.random.default_rng(0)
    K = np.array([[1800.0, 0, 1023.5], [0, 1800.0, 1023.5], [0, 0, 1]])
    for k in range(8):
        az = 2 * np.pi * k / 8
        eye = (1.2 * np.cos(az), 1.2 * np.sin(az), 1.0)
        m = look_at(eye, (0, 0, 0)) @ np.diag([1.0, -1.0, -1.0, 1.0])
        T = np.linalg.inv(m)
        out[f"K{k}"], out[f"R{k}"], out[f"t{k}"] = K, T[:3, :3], T[:3, 3]
        img = rng.random((64, 64, 3)).astype(np.float32)
        photo = _cv2().resize(img, (2048, 2048), interpolation=_cv2().INTER_CUBIC)
        _cv2().imwrite(os.path.join(folder, f"photo{k}.png"),
                       np.clip(255 * photo, 0, 255).astype(np.uint8))
    np.savez(os.path.join(folder, "scene.npz"), **out)


def _timed(args, runs=3):
    """Median wall seconds of ``runs`` whole-process runs: farm-bench where installed."""
    fb = shutil.which("farm-bench")
    if fb:
        res = subprocess.run([fb, "-n", str(runs), "--warmup", "0", "--timeout", "1200", "--"] + args,
                             capture_output=True, text=True, timeout=1300)
        m = re.search(r"A wall s\s+([\d.]+)\s+([\d.]+)\s+([\d.]+)", res.stdout)
        c = re.search(r"A cpu s\s+([\d.]+)\s+([\d.]+)\s+([\d.]+)", res.stdout)
        if m:
            return (float(m.group(2)), float(c.group(2)) if c else float("nan"),
                    "farm-bench, median of %d" % runs)
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        subprocess.run(args, capture_output=True, check=True)
        times.append(time.perf_counter() - t0)
    return float(np.median(times)), float("nan"), "script clock, median of %d" % runs


def speed():
    tmp = os.path.join(ROOT, ".cache", "bench_capture")
    cal_dir, proj_dir = _prepare_speed(tmp)
    me = [sys.executable, os.path.abspath(__file__)]
    rows = []
    load0 = os.getloadavg()[0]
    t, cpu, how = _timed(me + ["speed-calibration", cal_dir])
    rows.append(dict(task="calibration: 25 views of 1280 x 960 (detect + re-refine + calibrate)",
                     seconds=t, cpu=cpu, how=how))
    t, cpu, how = _timed(me + ["speed-projection", proj_dir])
    rows.append(dict(task="projection: 8 photos of 2048^2 onto 99,458 faces, 2048^2 texture",
                     seconds=t, cpu=cpu, how=how))
    print("speed", flush=True)
    return {"rows": rows, "load": [load0, os.getloadavg()[0]]}


# ------------------------------------------------------------------------------------------
# Report
# ------------------------------------------------------------------------------------------

def write_report(res, path):
    L = ["# Capture: calibration, pose, HDR, environments, photo projection",
         "",
         "Written by `benchmarks/bench_capture.py` (one run; renders by Blender "
         f"{_bpy_version()}, Cycles, cached in `.cache/bakes/capture`).  Truth: the renders' "
         "cameras (K from Blender's own projection matrix, matrix_world), the render's radiance, "
         "the HDRI, Cycles bakes.", ""]
    if "calibration" in res:
        c = res["calibration"]
        L += ["## Calibration per camera model", "",
              "24 views of a 9 x 6 ChArUco board (40 mm squares), 640 x 480, Cycles 16 samples, "
              "8-bit PNG.  A: 24 mm (f = 427 px), B: 40 mm with shift (0.05, -0.04), C: 60 mm with "
              "shift (-0.03, 0.025), D: A's renders with k1 = -0.12, k2 = 0.03 applied after "
              "rendering.  Model k1 k2 p1 p2 (k3 fixed).  Errors against the true K; `std c` is "
              "OpenCV's own standard deviation of the principal point (the larger of cx, cy).", "",
              "| model | corners | RMS px | fx err % | fy err % | cx err px | cy err px | std c px | views |",
              "|---|---|---|---|---|---|---|---|---|"]
        for r in c["rows"]:
            extra = f" (k1 {r['k1']:.4f}, k2 {r['k2']:.4f})" if "k1" in r else ""
            L.append(f"| {r['model']}{extra} | {r['method']} | {r['rms']:.3f} | {r['fx']:+.3f} | "
                     f"{r['fy']:+.3f} | {r['cx']:+.2f} | {r['cy']:+.2f} | {r['std_c']:.2f} | {r['views']} |")
        L += ["", "Targets: RMS <= 0.1 px, focal within 0.1 %, principal point within 1.5 px.", "",
              "### Corners against their exact projection", "",
              "| model | corners | re-refined mean (x, y) px | re-refined RMS per axis px | "
              "CharucoDetector mean (x, y) px | its spread RMS px |", "|---|---|---|---|---|---|"]
        for m, r in c["corners"].items():
            L.append(f"| {m} | {r['n']} | ({r['ours_mean'][0]:+.4f}, {r['ours_mean'][1]:+.4f}) | "
                     f"{r['ours_rms']:.4f} | ({r['raw_mean'][0]:+.3f}, {r['raw_mean'][1]:+.3f}) | "
                     f"{r['raw_rms']:.4f} |")
        L += ["", "### Sensor noise and blur (model B, added to the renders)", "",
              "| noise sigma (grey levels) | blur sigma px | corners | corner RMS px | RMS px | "
              "fx err % | cx err px | cy err px |", "|---|---|---|---|---|---|---|---|"]
        for r in c["degradation"]:
            L.append(f"| {r['noise']} | {r['blur']} | {r['method']} | {r['corner_rms']:.3f} | "
                     f"{r['rms']:.3f} | {r['fx']:+.3f} | {r['cx']:+.2f} | {r['cy']:+.2f} |")
        L.append("")
    if "pose" in res:
        L += ["## Pose from the board per distance", "",
              "7 x 5 squares of 12 cm, 1280 x 960, f = 1244 px, 4 views a distance (tilt 10-40 "
              "degrees), the true K.", "",
              "| distance m | corners | rotation mean deg | rotation max deg | position mean mm | "
              "position max mm |", "|---|---|---|---|---|---|"]
        for r in res["pose"]["rows"]:
            L.append(f"| {r['distance']:.0f} | {r['method']} | {r['rot_mean']:.4f} | {r['rot_max']:.4f} | "
                     f"{r['pos_mean']:.3f} | {r['pos_max']:.3f} |")
        L += ["", "Targets: rotation mean <= 0.05 deg, position <= 2 mm at every distance.", ""]
    if "path" in res:
        p = res["path"]
        L += ["## Camera path smoothing", "",
              f"{p['frames']} frames of 640 x 480 (f = 622 px) along an arc at 1.6-2.4 m (3-4 cm "
              "and about 2 degrees a frame), Gaussian noise added, frame 17 half covered.  Errors "
              "against the rendered path over every frame with a pose (rejected and missing "
              "frames filled by slerp once rejection is on).  Frames without a pose: "
              + ", ".join(f"{v} at sigma {k}" for k, v in p["no_board"].items()) + ".", "",
              "| noise sigma | poses | rotation mean deg | rotation max deg | position mean mm | "
              "position max mm | rejected | frames |", "|---|---|---|---|---|---|---|---|"]
        for r in p["rows"]:
            L.append(f"| {r['noise']:g} | {r['method']} | {r['rot_mean']:.4f} | {r['rot_max']:.4f} | "
                     f"{r['pos_mean']:.2f} | {r['pos_max']:.2f} | {r['rejected']} | {r['frames']} |")
        L.append("")
    if "hdr" in res:
        h = res["hdr"]
        L += ["## HDR merge", "",
              f"A Cycles render ({h['shape'][1]} x {h['shape'][0]}) of the courtyard HDRI, "
              f"{h['range']:.1f} stops (0.1-99.9th percentile), exposed through a known response "
              "(shoulder then gamma 1/2.2) and quantised to 8 bits.  |log2 merged - log2 truth| "
              "after one global scale, over the pixels some bracket exposes (6-249).", "",
              "| brackets | method | mean | p95 |", "|---|---|---|---|"]
        for r in h["rows"]:
            L.append(f"| {r['brackets']} | {r['method']} | {r['mean']:.4f} | {r['p95']:.4f} |")
        L += ["", "Targets: <= 0.03 mean, <= 0.15 p95.", ""]
    if "env" in res:
        L += ["## Environment maps against the HDRI", "",
              "log2 luminance error after box-filtering both to the size given; the mirror ball "
              "away from 30 degrees around straight behind it.", "",
              "| source | compared at | scale | mean | p95 |", "|---|---|---|---|---|"]
        for r in res["env"]["rows"]:
            L.append(f"| {r['source']} | {r['size']} x {r['size'] // 2} | {r['scale']:.3f} | "
                     f"{r['mean']:.3f} | {r['p95']:.3f} |")
        L.append("")
    if "projection" in res:
        p = res["projection"]
        t = p["total"]
        L += ["## Photo projection: the demo office", "",
              f"{t['views']} photos of 320 x 240 (Cycles 32 samples, lens 16 mm, two of them half "
              "a stop off) projected onto the office's 48 x 48 textures; CIEDE2000 against a "
              "Cycles bake of the same lighting (256 samples) on the texels some camera sees; "
              "`noise floor`: two bakes of different seeds on every texel; holes: texels no "
              f"camera sees, filled from their neighbours.  Projection {p['seconds']:.1f} s.", "",
              "| object | seen | mean | p95 | holes | holes mean | noise floor | photos used |",
              "|---|---|---|---|---|---|---|---|"]
        for r in p["rows"] + [t]:
            L.append(f"| {r['object']} | {100 * r['seen']:.1f} % | {r['mean']:.2f} | {r['p95']:.2f} | "
                     f"{r['holes']} | {r['hole_mean']:.2f} | {r['floor']:.2f} | {r['views']} |")
        L += ["", "Target: mean <= 2.0 on the texels seen.  Exposure gains (first photo 1): "
              + ", ".join(f"{k} {v[1]:.3f}" for k, v in p["gains"].items()), ""]
    if "relight" in res:
        L += ["## Relighting from projected textures", "",
              "Per-texel shadow removal (Precompute's default) on the projected textures and on "
              "baked textures of the same lighting (256 samples, seed 0); relit against bakes of "
              "each target lighting (seed 1); CIEDE2000 over every covered texel, values over the "
              "truth's 99th-percentile white.", "",
              "| lighting | preset | from baked textures: mean / p95 | from projected photos: mean / p95 |",
              "|---|---|---|---|"]
        rows = res["relight"]["rows"]
        keys = sorted({(r["lighting"], r["preset"]) for r in rows}, key=lambda k: (k[1], k[0]))
        for lab, pre in keys:
            b = next(r for r in rows if r["source"] == "baked textures" and r["lighting"] == lab and r["preset"] == pre)
            q = next(r for r in rows if r["source"] == "projected photos" and r["lighting"] == lab and r["preset"] == pre)
            L.append(f"| {lab} | {pre} | {b['mean']:.2f} / {b['p95']:.2f} | {q['mean']:.2f} / {q['p95']:.2f} |")
        L.append("")
    if "speed" in res:
        load = res["speed"].get("load", [float("nan")] * 2)
        L += ["## Speed", "", "Whole processes (Python start-up and imports included) on this "
              "machine: 2 cores shared with other jobs, load average "
              f"{load[0]:.1f} at the start and {load[1]:.1f} at the end"
              + (", so the wall times are those of a crowded machine" if max(load) > 2.5 else
                 ", a quiet machine") + "; `cpu` is user + system seconds (both cores).", "",
              "| task | wall s | cpu s | timed by |", "|---|---|---|---|"]
        for r in res["speed"]["rows"]:
            L.append(f"| {r['task']} | {r['seconds']:.1f} | {r.get('cpu', float('nan')):.1f} | "
                     f"{r['how']} |")
        L += ["", "Targets: calibration in seconds, projection under a minute.", ""]
    L += ["![capture](capture.png)", ""]
    with open(path, "w") as fh:
        fh.write("\n".join(L))


def _bpy_version():
    try:
        import bpy
        return bpy.app.version_string.split()[0]
    except ImportError:
        return "?"


def write_plot(res, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 3, figsize=(13, 4))
    if "calibration" in res:
        ax = axes[0]
        rows = res["calibration"]["rows"]
        for label, mk in (("ours (re-refined)", "o"), ("plain OpenCV", "x")):
            xs = [abs(r["fx"]) for r in rows if r["method"] == label]
            ys = [max(abs(r["cx"]), abs(r["cy"])) for r in rows if r["method"] == label]
            ax.scatter(xs, ys, marker=mk, label=label)
            for r, x, y in zip([r for r in rows if r["method"] == label], xs, ys):
                ax.annotate(r["model"], (x, y), fontsize=7, xytext=(3, 3), textcoords="offset points")
        ax.axvline(0.1, ls=":", c="grey")
        ax.axhline(1.5, ls=":", c="grey")
        ax.set_xlabel("|focal length error| (%)")
        ax.set_ylabel("principal point error (px, worse axis)")
        ax.set_title("Calibration per camera model")
        ax.legend(fontsize=7)
    if "pose" in res:
        ax = axes[1]
        for label, mk in (("ours", "o-"), ("plain", "x--")):
            rr = [r for r in res["pose"]["rows"] if r["method"] == label]
            ax.plot([r["distance"] for r in rr], [r["rot_mean"] for r in rr], mk, label=f"{label}: rotation mean (deg)")
            ax.plot([r["distance"] for r in rr], [r["pos_max"] / 40 for r in rr], mk, alpha=0.5,
                    label=f"{label}: position max / 40 (mm)")
        ax.axhline(0.05, ls=":", c="grey")
        ax.set_xlabel("board distance (m)")
        ax.set_title("Pose from the board (target 0.05 deg, 2 mm = 0.05)")
        ax.legend(fontsize=6)
    if "projection" in res:
        ax = axes[2]
        rr = res["projection"]["rows"]
        ax.bar(range(len(rr)), [r["mean"] for r in rr], label="projected vs bake (seen texels)")
        ax.plot(range(len(rr)), [r["floor"] for r in rr], "k_", ms=14, label="bake vs bake noise")
        ax.axhline(2.0, ls=":", c="grey")
        ax.set_xticks(range(len(rr)))
        ax.set_xticklabels([r["object"] for r in rr], rotation=45, fontsize=7)
        ax.set_ylabel("CIEDE2000 mean")
        ax.set_title("Office: projected photos vs Cycles bake")
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    if argv and argv[0] == "speed-calibration":
        return speed_calibration(argv[1])
    if argv and argv[0] == "speed-projection":
        return speed_projection(argv[1])
    ap = argparse.ArgumentParser()
    ap.add_argument("--only", default=",".join(SECTIONS))
    ap.add_argument("--out", default=RESULTS)
    args = ap.parse_args(argv)
    only = args.only.split(",")
    res = {}
    raw_path = os.path.join(args.out, "capture_raw.json")
    if os.path.exists(raw_path):            # sections not rerun keep their last figures
        with open(raw_path) as fh:
            res = json.load(fh)
    for name in only:
        if name == "calibration":
            res["calibration"] = calibration()
        elif name == "pose":
            res["pose"] = pose()
        elif name == "path":
            res["path"] = path()
        elif name == "hdr":
            res["hdr"] = hdr()
        elif name == "env":
            res["env"] = env()
        elif name == "projection":
            p = projection_section()
            textures = p.pop("textures")
            res["projection"] = p
            if "relight" in only:
                res["relight"] = relight_section(textures)
        elif name == "speed":
            res["speed"] = speed()
    os.makedirs(args.out, exist_ok=True)
    with open(raw_path, "w") as fh:
        json.dump(res, fh, indent=1, default=float)
    write_report(res, os.path.join(args.out, "capture.md"))
    write_plot(res, os.path.join(args.out, "capture.png"))


if __name__ == "__main__":
    main()
