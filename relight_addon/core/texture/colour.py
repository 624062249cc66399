"""Colour spaces: sRGB transfer function, linear RGB -> CIE LAB, colour distances.

* Photographs are sRGB-encoded; all light maths is done on linear RGB (Rec. 709 primaries).
* CIE LAB is used only for distances (seed 000 eq 4.4, texture refinement).

White point and scaling
-----------------------
Linear RGB reflectances/radiosities in [0, 1] are converted with the sRGB colourspace of
colour-science (primaries Rec. 709, white point D65, CIE 1931 2 degree observer) to CIE XYZ
with Y in [0, 1], then to LAB relative to the *same* D65 white (xy = 0.3127, 0.3290, Y = 1),
so no chromatic adaptation happens and RGB (1, 1, 1) maps to L = 100, a = b = 0 (to ~1e-3:
colour-science's sRGB matrix is the 4-decimal IEC one).  Callers comparing *radiosities*
(unbounded) should divide by a common reference first (e.g. the brightest value or the
display white), since L is only meaningful for Y <= 1.

colour-science is imported lazily: it is slow to import and only needed for LAB.
"""
from __future__ import annotations

import numpy as np

# IEC 61966-2-1 constants.
_SRGB_DECODE_THRESHOLD = 0.04045
_SRGB_ENCODE_THRESHOLD = 0.0031308
_SRGB_SLOPE = 12.92
_SRGB_GAMMA = 2.4
_SRGB_A = 0.055

D65_XY = np.array([0.3127, 0.3290])
# Rec. 709 luminance weights: a linear RGB value's "intensity" (seed 000 eq 4.1 and 4.2).
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


def luminance(rgb):
    """Rec. 709 luminance of linear RGB values (..., 3) -> (...)."""
    return np.asarray(rgb) @ LUMINANCE


def _float(x):
    x = np.asarray(x)
    if not np.issubdtype(x.dtype, np.floating):
        x = x.astype(np.float64)
    return x


def srgb_to_linear(x):
    """Exact IEC 61966-2-1 decoding of sRGB values in [0, 1] (dtype kept for float32/64).

    Values below 0 follow the linear segment; values above 1 the power law.
    """
    x = _float(x)
    power = ((np.maximum(x, _SRGB_DECODE_THRESHOLD) + _SRGB_A) / (1 + _SRGB_A)) ** _SRGB_GAMMA
    return np.where(x <= _SRGB_DECODE_THRESHOLD, x / _SRGB_SLOPE, power).astype(x.dtype, copy=False)


def linear_to_srgb(x):
    """Exact IEC 61966-2-1 encoding of linear values (dtype kept for float32/64)."""
    x = _float(x)
    power = (1 + _SRGB_A) * np.maximum(x, _SRGB_ENCODE_THRESHOLD) ** (1 / _SRGB_GAMMA) - _SRGB_A
    return np.where(x <= _SRGB_ENCODE_THRESHOLD, x * _SRGB_SLOPE, power).astype(x.dtype, copy=False)


def _colour():
    import colour  # noqa: PLC0415  (lazy: heavy import)
    return colour


def linear_rgb_to_xyz(rgb):
    """Linear sRGB (Rec. 709, D65) -> CIE XYZ (Y = 1 for RGB white)."""
    c = _colour()
    rgb = np.asarray(rgb, np.float64)
    return c.RGB_to_XYZ(rgb, c.RGB_COLOURSPACES["sRGB"], illuminant=D65_XY,
                        chromatic_adaptation_transform=None, apply_cctf_decoding=False)


def linear_rgb_to_lab(rgb):
    """Linear sRGB (..., 3) in [0, 1] -> CIE LAB (..., 3), D65, L in [0, 100]."""
    c = _colour()
    return np.asarray(c.XYZ_to_Lab(linear_rgb_to_xyz(rgb), illuminant=D65_XY))


def srgb_to_lab(srgb):
    """sRGB-encoded values (e.g. photo texels in [0, 1]) -> CIE LAB."""
    return linear_rgb_to_lab(srgb_to_linear(np.asarray(srgb, np.float64)))


def lab_distance(lab1, lab2):
    """Euclidean distance in CIE LAB (Delta E 1976, seed 000 eq 4.4), over the last axis."""
    d = np.asarray(lab1, np.float64) - np.asarray(lab2, np.float64)
    return np.sqrt(np.einsum("...i,...i->...", d, d))


def delta_e_2000(lab1, lab2):
    """CIEDE2000 colour difference (colour-science ``delta_E(..., method="CIE 2000")``)."""
    return np.asarray(_colour().delta_E(np.asarray(lab1, np.float64), np.asarray(lab2, np.float64),
                                        method="CIE 2000"))


def rgb_lab_distance(rgb1, rgb2, method: str = "CIE 1976"):
    """Distance between linear RGB colours measured in LAB (``"CIE 1976"`` or ``"CIE 2000"``)."""
    l1, l2 = linear_rgb_to_lab(rgb1), linear_rgb_to_lab(rgb2)
    return lab_distance(l1, l2) if method == "CIE 1976" else delta_e_2000(l1, l2)
