"""Float images that Relight writes and packs into the .blend (maps, textures, settled shadows).

Maps are half-float OpenEXR (ZIP) through ``Image.save_render`` with a temporary scene whose
output settings are EXR / 16 bit / ZIP (``Image.save`` + ``use_half_precision`` writes 32-bit
float in Blender 5.0.1: measured from the EXR channel list).  The file is loaded, packed and
deleted; the image keeps the relative path ``//relight/<name>.exr`` for unpacking.  Linear EXR
output gets no view transform (values above 1 round-trip unchanged).

Half floats end at 65504: an image with larger values (photos in absolute units) is written as
32-bit float instead, and the writer says so (``full_float``), never clipping in silence.
"""
from __future__ import annotations

import os
import shutil
import tempfile

import bpy
import numpy as np

from . import ids

HALF_MAX = 65504.0


def pixels(img) -> np.ndarray:
    """(H, W, channels) float32 pixels of ``img`` (bottom row first, as Blender stores them)."""
    buf = np.empty(len(img.pixels), np.float32)
    img.pixels.foreach_get(buf)
    return buf.reshape(img.size[1], img.size[0], -1)


def float_image(name, rgb, alpha=None):
    """A new RGBA float image (Non-Color, alpha as data) holding ``rgb`` and ``alpha``."""
    hh, ww = rgb.shape[:2]
    img = bpy.data.images.new(name, ww, hh, alpha=True, float_buffer=True)
    img.colorspace_settings.name = "Non-Color"
    img.alpha_mode = "CHANNEL_PACKED"        # alpha is data (the direct fraction), not coverage
    rgba = np.ones((hh, ww, 4), np.float32)
    rgba[..., :3] = rgb
    if alpha is not None:
        rgba[..., 3] = alpha
    img.pixels.foreach_set(rgba.reshape(-1))
    return img


CONTENT = "relight_content"     # on an image written here: a hash of what it holds


def content_hash(rgb, alpha=None) -> str:
    import hashlib
    h = hashlib.sha1(np.ascontiguousarray(rgb, np.float32).tobytes())
    h.update(str(np.shape(rgb)).encode())
    if alpha is not None:
        h.update(np.ascontiguousarray(alpha, np.float32).tobytes())
    return h.hexdigest()


class MapWriter:
    """Writes packed float images tagged for the scene with ``key``; ``close()`` when done.
    ``reuse``: {name: image} written before, taken again when it holds the same content (an
    Update that adds a lamp writes that lamp's maps only); ``full_float``: names of the images
    written as 32-bit float (values beyond half floats); ``non_finite``: names of the images
    whose NaN or infinite values were written as 0."""

    def __init__(self, key, reuse=None):
        self.key = key
        self.reuse = dict(reuse or {})
        self.reused = []
        self.full_float, self.non_finite = [], []
        self.dir = tempfile.mkdtemp(prefix="relight_")
        self.scene = bpy.data.scenes.new("relight_tmp_exr_settings")
        s = self.scene.render.image_settings
        s.file_format = "OPEN_EXR"
        s.color_mode = "RGBA"
        s.color_depth = "16"
        s.exr_codec = "ZIP"

    def write(self, name, rgb, alpha=None):
        rgb = np.asarray(rgb, np.float32)
        digest = content_hash(rgb, alpha)
        old = self.reuse.pop(name, None)
        if old is not None:
            if old.get(CONTENT) == digest:
                self.reused.append(old)
                return old
            bpy.data.images.remove(old)              # the new one takes its name
        if not np.isfinite(rgb).all():
            self.non_finite.append(name)
            rgb = np.nan_to_num(rgb, nan=0.0, posinf=0.0, neginf=0.0)
        if alpha is not None:
            alpha = np.clip(np.nan_to_num(alpha, nan=1.0), 0.0, 1.0)
        if float(np.abs(rgb).max(initial=0.0)) > HALF_MAX:
            self.full_float.append(name)
            img = None
        else:
            img = self._half(name, rgb, alpha)
        if img is None:                  # 32-bit float, packed
            img = float_image(name, rgb, alpha)
            img.file_format = "OPEN_EXR"
            img.pack()
        ids.tag(img, self.key)
        img[CONTENT] = digest
        return img

    def _half(self, name, rgb, alpha):
        tmp = float_image("relight_tmp_image", rgb, alpha)
        path = os.path.join(self.dir, "image.exr")
        img = None
        try:
            tmp.save_render(path, scene=self.scene)
            img = bpy.data.images.load(path, check_existing=False)
            img.colorspace_settings.name = "Non-Color"
            img.alpha_mode = "CHANNEL_PACKED"
            img.pack()
            img.name = name
            img.filepath_raw = f"//relight/{bpy.path.clean_name(name)}.exr"
        except Exception:       # the caller falls back to a packed 32-bit float image
            if img is not None:
                bpy.data.images.remove(img)
            img = None
        finally:
            bpy.data.images.remove(tmp)
            if os.path.exists(path):
                os.remove(path)
        return img

    def close(self):
        bpy.data.scenes.remove(self.scene)
        shutil.rmtree(self.dir, ignore_errors=True)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
