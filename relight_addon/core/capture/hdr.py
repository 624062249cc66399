# SPDX-License-Identifier: GPL-3.0-or-later
"""HDR: bracketed 8-bit photos merged into linear radiance, and environment maps (equirect, in
Blender's World convention) from a mirror-ball photo or from posed frames.

Merge: the camera response is recovered by OpenCV (``CalibrateDebevec`` on 200 samples, or
``CalibrateRobertson``); the merge itself is ours: per pixel and channel the mean of
``g(z_k) - ln t_k`` (g = ln of the inverse response) weighted by the inverse variance of the
8-bit quantisation in that domain, ``1 / g'(z)^2``, over the brackets where z is neither
black nor saturated (z in [2, 253]).  A pixel saturated in every bracket gets the lower bound
``g(253) - ln t_min``, one black in every bracket the upper bound ``g(2) - ln t_max``.
Measured on brackets of a Cycles render through a known response (tests/test_capture_hdr.py):
log2 error 0.004 mean / 0.009 p95 against OpenCV's MergeDebevec with the same response
0.019 / 0.085.

Exposure times: EXIF ExposureTime where present, else the sidecar ``exposures.json`` =
``{"format": "relight-capture-brackets/1", "images": [{"file": NAME, "exposure_time": s}]}``.

Equirect (Blender's Environment Texture): direction d -> u = 0.5 - atan2(d_y, d_x) / (2 pi),
v = 0.5 + asin(d_z) / pi; image row 0 (top) is v = 1.  The image centre looks along +X.
"""
from __future__ import annotations

import json
import os

import numpy as np

from . import CaptureError
from .calibration import list_images, read_image

SIDECAR = "exposures.json"
SIDECAR_FORMAT = "relight-capture-brackets/1"
EXIF_IFD = 0x8769
EXPOSURE_TIME = 0x829A
RESPONSE_SAMPLES = 200       # CalibrateDebevec's samples (OpenCV's default, 70, is noisier)
Z_LOW, Z_HIGH = 2, 253       # 8-bit values trusted in a merge (black and saturated excluded)
SLOPE_FLOOR = 1e-4           # g' floor (ln units per level): no infinite weights at flat ends
# Mirror ball: reflected directions within this angle of straight behind the ball come from
# its rim, where one pixel spans many degrees; they are filled from their neighbours.
BALL_BACK_DEG = 20.0


def _cv2():
    import cv2  # noqa: PLC0415
    return cv2


# ------------------------------------------------------------------------------------------
# Brackets
# ------------------------------------------------------------------------------------------

def exif_exposure(path) -> float | None:
    """EXIF ExposureTime (seconds) of an image file, or None."""
    try:
        from PIL import Image  # noqa: PLC0415
        with Image.open(path) as im:
            exif = im.getexif()
            value = exif.get_ifd(EXIF_IFD).get(EXPOSURE_TIME, exif.get(EXPOSURE_TIME))
    except Exception:       # not an image Pillow reads, or broken EXIF: no time from it
        return None
    try:
        t = float(value)
    except (TypeError, ValueError, ZeroDivisionError):
        return None
    return t if np.isfinite(t) and t > 0 else None


def sidecar_exposures(directory) -> dict:
    """{file name: seconds} from the folder's exposures.json ({} when there is none)."""
    path = os.path.join(directory, SIDECAR)
    if not os.path.exists(path):
        return {}
    try:
        with open(path, encoding="utf-8") as fh:
            data = json.load(fh)
    except (OSError, ValueError) as ex:
        raise CaptureError(f"{SIDECAR} cannot be read: {ex}") from None
    if not isinstance(data, dict) or data.get("format") != SIDECAR_FORMAT:
        raise CaptureError(f"{SIDECAR} is not in the format '{SIDECAR_FORMAT}'")
    out = {}
    for entry in data.get("images", []):
        try:
            out[str(entry["file"])] = float(entry["exposure_time"])
        except (KeyError, TypeError, ValueError):
            raise CaptureError(f"{SIDECAR}: every image needs a 'file' and an 'exposure_time' "
                               f"in seconds") from None
    return out


def read_brackets(directory):
    """(names, BGR uint8 images, exposure times) of the bracketed photos of a folder, sorted
    by exposure time.  Raises on anything a merge cannot use."""
    paths = list_images(directory)
    side = sidecar_exposures(directory)
    names, images, times = [], [], []
    for path in paths:
        name = os.path.basename(path)
        img = read_image(path)
        if img.dtype != np.uint8:
            raise CaptureError(f"'{name}' is not an 8-bit photo ({img.dtype}): the merge "
                               f"takes 8-bit brackets")
        if img.ndim == 2:
            img = np.repeat(img[..., None], 3, axis=2)
        img = img[..., :3]
        t = exif_exposure(path)
        if t is None:
            t = side.get(name)
        if t is None or not np.isfinite(t) or t <= 0:
            raise CaptureError(f"No exposure time for '{name}': it has no EXIF ExposureTime and "
                               f"is not in {SIDECAR}")
        if images and img.shape != images[0].shape:
            raise CaptureError(f"The brackets have different sizes: '{names[0]}' is "
                               f"{images[0].shape[1]} x {images[0].shape[0]}, '{name}' is "
                               f"{img.shape[1]} x {img.shape[0]}")
        names.append(name)
        images.append(np.ascontiguousarray(img))
        times.append(t)
    if len(images) < 2:
        raise CaptureError(f"An HDR merge needs at least 2 bracketed photos; '{directory}' has "
                           f"{len(images)}")
    times = np.asarray(times, np.float64)
    if len(np.unique(np.round(np.log2(times), 3))) < 2:
        raise CaptureError("The brackets all have the same exposure time")
    order = np.argsort(times, kind="stable")
    return [names[i] for i in order], [images[i] for i in order], times[order]


def recover_response(images, times, method="DEBEVEC") -> np.ndarray:
    """(256, 3) inverse response (relative exposure per 8-bit value, BGR) by OpenCV."""
    cv2 = _cv2()
    t = np.asarray(times, np.float32)
    if method == "DEBEVEC":
        cal = cv2.createCalibrateDebevec(samples=RESPONSE_SAMPLES)
    elif method == "ROBERTSON":
        cal = cv2.createCalibrateRobertson()
    else:
        raise CaptureError(f"Unknown response method '{method}'")
    resp = np.asarray(cal.process(list(images), t), np.float64).reshape(256, 3)
    # 8-bit values no bracket shows can come back non-finite (Robertson): interpolated in log
    # over the values that are known
    z = np.arange(256)
    for c in range(3):
        good = np.isfinite(resp[:, c]) & (resp[:, c] > 0)
        if good.sum() < 16:
            raise CaptureError("The camera response could not be recovered from these brackets")
        if not good.all():
            resp[:, c] = np.exp(np.interp(z, z[good], np.log(resp[good, c])))
    return resp


def merge(images, times, response) -> dict:
    """Linear radiance (H, W, 3) float32 RGB (any global scale) and the fractions of pixels
    saturated / black in every bracket."""
    g = np.log(np.maximum(np.asarray(response, np.float64).reshape(256, 3), 1e-30))
    slope = np.maximum(np.gradient(g, axis=0), SLOPE_FLOOR)
    z = np.arange(256)
    w = ((z >= Z_LOW) & (z <= Z_HIGH))[:, None] / slope ** 2      # (256, 3)
    shape = images[0].shape
    num = np.zeros(shape, np.float64)
    den = np.zeros(shape, np.float64)
    lnt = np.log(np.asarray(times, np.float64))
    for img, lt in zip(images, lnt):        # a few brackets; each step is whole-image numpy
        for c in range(3):
            zz = img[..., c]
            wc = w[zz, c]
            num[..., c] += wc * (g[zz, c] - lt)
            den[..., c] += wc
    with np.errstate(invalid="ignore", divide="ignore"):
        lne = num / den
    short = images[0]
    sat = (den == 0) & (short > Z_HIGH)
    black = (den == 0) & ~sat
    lne[sat] = np.broadcast_to(g[Z_HIGH] - lnt[0], shape)[sat]
    lne[black] = np.broadcast_to(g[Z_LOW] - lnt[-1], shape)[black]
    lne = np.clip(np.nan_to_num(lne, nan=0.0), -80.0, 80.0)   # exp stays finite in float32
    rgb = np.exp(lne)[..., ::-1].astype(np.float32)
    return {"radiance": np.ascontiguousarray(rgb),
            "saturated": float(sat.any(axis=2).mean()), "black": float(black.any(axis=2).mean())}


def merge_opencv(images, times, response, method="DEBEVEC") -> np.ndarray:
    """OpenCV's own merge (the benchmark's plain baseline), RGB float32."""
    cv2 = _cv2()
    t = np.asarray(times, np.float32)
    resp = np.asarray(response, np.float32).reshape(256, 1, 3)
    m = (cv2.createMergeDebevec() if method == "DEBEVEC" else cv2.createMergeRobertson())
    out = m.process(list(images), t, resp)
    return np.ascontiguousarray(np.nan_to_num(out[..., ::-1], nan=0.0, posinf=0.0)).astype(np.float32)


def dynamic_range_stops(radiance) -> float:
    """log2 of the 99.9th over the 0.1th percentile of the luminance."""
    lum = np.asarray(radiance, np.float64) @ np.array([0.2126, 0.7152, 0.0722])
    lo, hi = np.percentile(lum[lum > 0], [0.1, 99.9]) if np.any(lum > 0) else (1.0, 1.0)
    return float(np.log2(hi / max(lo, 1e-30)))


# ------------------------------------------------------------------------------------------
# Environment maps
# ------------------------------------------------------------------------------------------

def equirect_directions(width: int) -> np.ndarray:
    """(H, W, 3) unit world directions of the texel centres of a W x W/2 equirect, row 0 at
    the top (Blender's Environment Texture mapping)."""
    h = max(1, int(width) // 2)
    u = (np.arange(width) + 0.5) / width
    v = 1.0 - (np.arange(h) + 0.5) / h
    phi = (0.5 - u) * 2 * np.pi
    lat = (v - 0.5) * np.pi
    cl = np.cos(lat)[:, None]
    return np.stack([cl * np.cos(phi)[None], cl * np.sin(phi)[None],
                     np.broadcast_to(np.sin(lat)[:, None], (h, width))], axis=-1)


def direction_to_equirect(d) -> np.ndarray:
    """(..., 2) equirect (u, v) of world directions (v = 0 at the bottom, as Blender)."""
    d = np.asarray(d, np.float64)
    n = np.linalg.norm(d, axis=-1, keepdims=True)
    d = d / np.maximum(n, 1e-300)
    u = 0.5 - np.arctan2(d[..., 1], d[..., 0]) / (2 * np.pi)
    v = 0.5 + np.arcsin(np.clip(d[..., 2], -1, 1)) / np.pi
    return np.stack([u % 1.0, v], axis=-1)


def sample_equirect(env, d) -> np.ndarray:
    """Bilinear lookup of an equirect (H, W, C), row 0 at the top, in world directions."""
    cv2 = _cv2()
    env = np.asarray(env, np.float32)
    h, w = env.shape[:2]
    uv = direction_to_equirect(d)
    x = (uv[..., 0] * w - 0.5).astype(np.float32)
    y = ((1.0 - uv[..., 1]) * h - 0.5).astype(np.float32)
    wrap = cv2.copyMakeBorder(env, 0, 0, 1, 1, cv2.BORDER_WRAP)      # u wraps around
    return cv2.remap(wrap, x + 1, y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


def _fill_holes(img, valid):
    """Holes filled from their neighbours (repeated 8-neighbour means, coarse to fine)."""
    from ..texture.mapping import dilate_seams  # noqa: PLC0415
    out, cov = dilate_seams(img, valid, pixels=max(img.shape[:2]))
    return out, cov


def mirror_ball_to_equirect(image, width=512, centre=None, radius=None, camera_rotation=None):
    """Equirect (width x width/2, float32) of a mirror-ball photo (linear RGB, row 0 at the
    top) seen from far away (orthographic), the ball's outline the circle ``centre`` (x, y),
    ``radius`` (px; default: the photo's inscribed circle), the camera's world rotation (3x3,
    Blender camera axes: -Z forward, +Y up; default: looking along +Y with +Z up).
    Returns (env, behind): ``behind`` marks directions near straight behind the ball, taken
    from their neighbours."""
    cv2 = _cv2()
    img = np.asarray(image, np.float32)
    h, w = img.shape[:2]
    if centre is None:
        centre = ((w - 1) / 2.0, (h - 1) / 2.0)
    if radius is None or radius <= 0:
        radius = min(w, h) / 2.0
    if camera_rotation is None:       # Blender's front view: camera -Z = world +Y, +Y = +Z
        camera_rotation = np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])
    R = np.asarray(camera_rotation, np.float64)
    d = equirect_directions(width)
    r = d @ R                          # world -> camera: R^T d, written for row vectors
    # the normal bisects the reflected ray and the direction back to the camera (0, 0, 1)
    n = r + np.array([0.0, 0.0, 1.0])
    nn = np.linalg.norm(n, axis=-1, keepdims=True)
    n = n / np.maximum(nn, 1e-12)
    x = (centre[0] + radius * n[..., 0]).astype(np.float32)
    y = (centre[1] - radius * n[..., 1]).astype(np.float32)
    env = cv2.remap(img, x, y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    behind = np.degrees(np.arccos(np.clip(-r[..., 2], -1, 1))) < BALL_BACK_DEG
    env, _ = _fill_holes(env, ~behind)
    return np.ascontiguousarray(env, np.float32), behind


def frames_to_equirect(frames, width=512, feather=0.1, progress=None):
    """Equirect of posed frames, the environment taken as at infinity (the seed's cube map
    from the camera, sampled in world directions).  ``frames``: (K (3x3), R (3x3) world
    rotation of the Blender camera, image (H, W, 3) linear, row 0 at the top).  Each direction
    blends the frames that see it, weighted by a ramp over ``feather`` of the frame's size at
    its borders; directions no frame sees are filled from their neighbours.  Returns
    (env, seen) with ``seen`` the directions some frame saw.  ``progress(fraction, text)``
    before each frame."""
    cv2 = _cv2()
    d = equirect_directions(width)
    h = d.shape[0]
    acc = np.zeros((h, width, 3), np.float64)
    wsum = np.zeros((h, width), np.float64)
    flip = np.diag([1.0, -1.0, -1.0])             # Blender camera -> OpenCV camera axes
    for i, (K, R, img) in enumerate(frames):
        if progress is not None:
            progress(i / len(frames), f"Frame {i + 1} of {len(frames)}")
        img = np.asarray(img, np.float32)
        ih, iw = img.shape[:2]
        c = d @ (np.asarray(R, np.float64) @ flip)   # world -> OpenCV camera (row vectors)
        z = c[..., 2]
        front = z > 1e-6
        with np.errstate(divide="ignore", invalid="ignore"):
            u = K[0, 0] * c[..., 0] / z + K[0, 2]
            v = K[1, 1] * c[..., 1] / z + K[1, 2]
        inside = front & (u > -0.5) & (u < iw - 0.5) & (v > -0.5) & (v < ih - 0.5)
        edge = np.minimum(np.minimum(u + 0.5, iw - 0.5 - u) / iw,
                          np.minimum(v + 0.5, ih - 0.5 - v) / ih)
        wgt = np.where(inside, np.clip(edge / max(feather, 1e-6), 1e-3, 1.0), 0.0)
        sample = cv2.remap(img, np.where(inside, u, -10).astype(np.float32),
                           np.where(inside, v, -10).astype(np.float32), cv2.INTER_LINEAR,
                           borderMode=cv2.BORDER_REPLICATE)
        acc += wgt[..., None] * sample
        wsum += wgt
    seen = wsum > 0
    env = (acc / np.maximum(wsum, 1e-30)[..., None]).astype(np.float32)
    env, _ = _fill_holes(env, seen)
    return np.ascontiguousarray(env, np.float32), seen
