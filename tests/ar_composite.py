"""The AR composite against Cycles with the object really in the scene: renders cached on disk
(scenes/bake.py's convention: ``$RELIGHT_BAKE_CACHE`` or ``.cache/bakes``, keyed by the inputs,
the settings, bpy's version and, for our composite, the add-on's code), each in a fresh bpy
process (tests/ar_composite_job.py), and the scores.

* ``photo(scene, obj, hdri, res, samples)``: the set without the object (Cycles, seed 0,
  denoised), a 16-bit PNG (its path) and its linear pixels, and the object's coverage mask;
* ``reference(kind, ...)``: ``truth`` (the object really there, same samples and seed as the
  photo: paths that never meet the object give the same pixels) or ``catcher`` (the user's
  alternative: Cycles' shadow catcher composite over the photo);
* ``ours(...)``: ``bpy.ops.relight.ar_setup()`` on the user's scene made of the photo, then
  the scene's render (Cycles or EEVEE);
* ``scores(photo, image, truth, mask)``: mean CIEDE2000 over the image, inside the object's
  shadow (truth / photo luminance < SHADOW outside the object) and on the object (coverage >
  1/2).
"""
from __future__ import annotations

import glob
import hashlib
import json
import os
import subprocess
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
SHADOW = 0.9            # truth / photo luminance below it (outside the object): its shadow
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
CODE = ("relight_addon/**/*.py", "relight_addon/blender/shaders/*", "operators/*.py",
        "panels/*.py", "__init__.py")


def cache_dir():
    return os.environ.get("RELIGHT_BAKE_CACHE") or os.path.join(ROOT, ".cache", "bakes")


def _bpy_version():
    import importlib.metadata
    try:
        return importlib.metadata.version("bpy")
    except importlib.metadata.PackageNotFoundError:
        return "none"


def _files_hash(patterns):
    h = hashlib.sha256()
    for pat in patterns:
        for f in sorted(glob.glob(os.path.join(ROOT, pat), recursive=True)):
            with open(f, "rb") as fh:
                h.update(os.path.relpath(f, ROOT).encode() + fh.read())
    return h.hexdigest()[:16]


def _hdri_hash(path):
    with open(path, "rb") as f:
        return hashlib.sha256(f.read()).hexdigest()[:16]


def _run(args, key_parts, timeout=3600):
    h = hashlib.sha256(json.dumps(key_parts, sort_keys=True).encode()).hexdigest()[:24]
    base = os.path.join(cache_dir(), f"ar_comp_{args['kind']}_{h}")
    if not os.path.exists(base + ".npz"):
        os.makedirs(cache_dir(), exist_ok=True)
        args = dict(args, out=base + f".{os.getpid()}.tmp")
        run = subprocess.run([sys.executable, os.path.join(HERE, "ar_composite_job.py"),
                              json.dumps(args)], capture_output=True, text=True,
                             timeout=timeout)
        if run.returncode != 0 or not os.path.exists(args["out"] + ".npz"):
            raise RuntimeError(f"ar_composite_job {args['kind']} failed:\n{run.stdout[-3000:]}"
                               f"\n{run.stderr[-3000:]}")
        os.replace(args["out"] + ".npz", base + ".npz")
    return base


def _scene_key(scene, obj, hdri, res, samples):
    return {"scene": scene, "object": obj, "hdri": _hdri_hash(hdri), "res": list(res),
            "samples": samples, "bpy": _bpy_version(), "denoise": True,
            "set": _files_hash(("tests/ar_composite_scenes.py", "tests/ar_scenes.py",
                                "tests/data/ar_suzanne.npz"))}


def load_png(path):
    """(H, W, 3) linear float64 pixels of an sRGB PNG (8 or 16 bit), top row first."""
    import cv2
    im = cv2.imread(path, cv2.IMREAD_UNCHANGED)
    scale = 65535.0 if im.dtype == np.uint16 else 255.0
    im = im[..., :3][..., ::-1].astype(np.float64) / scale
    return np.where(im <= 0.04045, im / 12.92, ((im + 0.055) / 1.055) ** 2.4)


def photo(scene, obj, hdri, res=(400, 300), samples=256):
    """{"path": the 16-bit PNG, "image": its linear pixels, "mask": the object's coverage}."""
    key = dict(_scene_key(scene, obj, hdri, res, samples), kind="photo")
    h = hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()[:24]
    png = os.path.join(cache_dir(), f"ar_comp_photo_{h}.png")
    base = _run({"kind": "photo", "scene": scene, "object": obj, "hdri": hdri,
                 "res": list(res), "samples": samples, "photo": png}, key)
    d = np.load(base + ".npz")
    return {"path": png, "image": load_png(png), "mask": d["mask"]}


def reference(kind, scene, obj, hdri, res=(400, 300), samples=256, photo_samples=256,
              placements=None):
    """{"image", "seconds", "cpu"[, "mask"]}: the ``truth`` or the ``catcher`` composite;
    ``placements``: [{"radius", "centre"}] spheres in place of the scene's object (then
    "mask" is their coverage)."""
    p = photo(scene, obj, hdri, res, photo_samples)
    key = dict(_scene_key(scene, obj, hdri, res, samples), kind=kind,
               photo=photo_samples)
    args = {"kind": kind, "scene": scene, "object": obj, "hdri": hdri, "res": list(res),
            "samples": samples, "photo": p["path"]}
    if placements:
        key["placements"] = args["placements"] = placements
    base = _run(args, key)
    return dict(np.load(base + ".npz"))


def ours(scene, obj, hdri, res=(400, 300), engine="CYCLES", samples=32, photo_samples=256,
         spheres=None, save=None, move=None):
    """{"image", "seconds", "cpu", "setup_seconds"[, "moved"]}: our composite (and, with
    ``move``, the render after moving the object there; ``save``: a path the set-up scene is
    saved to, not part of the cache)."""
    p = photo(scene, obj, hdri, res, photo_samples)
    key = dict(_scene_key(scene, obj, hdri, res, samples), kind="ours", engine=engine,
               photo=photo_samples, spheres=spheres, move=move, code=_files_hash(CODE))
    args = {"kind": "ours", "scene": scene, "object": obj, "hdri": hdri, "res": list(res),
            "samples": samples, "photo": p["path"], "engine": engine, "spheres": spheres,
            "move": move}
    if save:
        key["save"] = save
        args["save"] = save
    base = _run(args, key)
    return dict(np.load(base + ".npz"))


def chain(scene, obj, hdri, move, second, res=(400, 300), samples=32, photo_samples=256):
    """Set up on the photo's scene, move the object by ``move``, render ("moved"), add a second
    object (a sphere ``second``: {"radius", "centre"}), Update, render ("second"), save;
    then the saved file opened in a fresh process and rendered ("reopened"): a dict of the
    three images and the timings."""
    p = photo(scene, obj, hdri, res, photo_samples)
    key = dict(_scene_key(scene, obj, hdri, res, samples), kind="chain", engine="CYCLES",
               photo=photo_samples, move=list(move), second=second, code=_files_hash(CODE))
    h = hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()[:24]
    blend = os.path.join(cache_dir(), f"ar_comp_chain_{h}.blend")
    args = {"kind": "chain", "scene": scene, "object": obj, "hdri": hdri, "res": list(res),
            "samples": samples, "photo": p["path"], "engine": "CYCLES", "move": list(move),
            "second": second, "save": blend}
    out = dict(np.load(_run(args, key) + ".npz"))
    again = _run({"kind": "reopen", "save": blend, "samples": samples, "engine": "CYCLES"},
                 dict(key, kind="reopen"))
    out["reopened"] = np.load(again + ".npz")["image"]
    return out


def lab(rgb):
    import colour
    xyz = colour.RGB_to_XYZ(np.clip(rgb, 0, None), colour.RGB_COLOURSPACES["sRGB"],
                            apply_cctf_decoding=False)
    return colour.XYZ_to_Lab(xyz)


def delta_e(a, b):
    import colour
    return colour.delta_E(lab(a), lab(b), method="CIE 2000")


def regions(photo_img, truth, mask):
    """(shadow, object) boolean masks: the object's shadow (truth / photo luminance < SHADOW
    outside the object) and the object (coverage > 1/2)."""
    ratio = (truth @ LUMINANCE) / np.maximum(photo_img @ LUMINANCE, 1e-6)
    return (ratio < SHADOW) & (mask < 0.01), mask > 0.5


def scores(photo_img, image, truth, mask):
    """Mean CIEDE2000 of ``image`` against ``truth``: over the image, in the shadow, on the
    object (see :func:`regions`), and the pixel counts."""
    d = delta_e(image, truth)
    shadow, obj = regions(photo_img, truth, mask)
    return {"image": float(d.mean()), "shadow": float(d[shadow].mean()) if shadow.any() else 0.0,
            "object": float(d[obj].mean()) if obj.any() else 0.0,
            "shadow_px": int(shadow.sum()), "object_px": int(obj.sum())}


def pasted(photo_img, truth, mask):
    """The object pasted on the photo without its shadow (the truth's pixels on the object):
    what the shadow is worth."""
    m = np.clip(mask, 0, 1)[..., None]
    return truth * m + photo_img * (1 - m)
