"""numpy twin of the overlay colour maps in relight_addon/blender/shaders/overlay_frag.glsl.

The constants below must equal the GLSL ``const`` declarations of the same name;
tests/test_overlay_shaders.py parses the shader and checks that they do.

ratio_color (shader mode 0), for a ratio such as B/D, on a log2 scale:
    t = clip(log2(max(value, RATIO_FLOOR)) / LOG2_RANGE, -1, 1)
    t < 0: COLOR_MID + (COLOR_LOW - COLOR_MID) * (-t)    value 1 -> white, <= 1/2 -> blue
    t > 0: COLOR_MID + (COLOR_HIGH - COLOR_MID) * t      value >= 2 -> red
    zero / negative / -Inf -> COLOR_LOW, +Inf -> COLOR_HIGH, NaN -> COLOR_NAN.

visibility_color (shader mode 1): the nearest integer of the value picks the colour of the link
visibility type (core/radiosity/links.py VISIBLE, PARTIAL, INVISIBLE = 0, 1, 2); anything else
-> COLOR_NAN.

Both return float32 arrays of shape value.shape + (3,), always finite, in [0, 1].
"""
import numpy as np

RATIO_FLOOR = 1e-6
LOG2_RANGE = 1.0
COLOR_LOW = (0.05, 0.25, 1.0)
COLOR_MID = (1.0, 1.0, 1.0)
COLOR_HIGH = (1.0, 0.1, 0.05)
COLOR_NAN = (1.0, 0.0, 1.0)
COLOR_VISIBLE = (0.1, 0.8, 0.2)
COLOR_PARTIAL = (1.0, 0.8, 0.1)
COLOR_INVISIBLE = (0.35, 0.35, 0.35)

# Names the shader declares with the same values (checked by the test).
SHADER_CONSTANTS = (
    "RATIO_FLOOR", "LOG2_RANGE", "COLOR_LOW", "COLOR_MID", "COLOR_HIGH", "COLOR_NAN",
    "COLOR_VISIBLE", "COLOR_PARTIAL", "COLOR_INVISIBLE",
)

MODE_RATIO = 0
MODE_VISIBILITY = 1


def ratio_param(value):
    """The signed parameter t in [-1, 1] of ratio_color (NaN stays NaN)."""
    v = np.asarray(value, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.log2(np.maximum(v, RATIO_FLOOR)) / LOG2_RANGE  # max() propagates NaN
    # log2(+Inf) = +Inf clips to 1, as the shader's isinf branch.
    return np.clip(t, -1.0, 1.0)


def ratio_color(value):
    """Colour of each ratio value: blue (<= 1/2) -> white (1) -> red (>= 2), log2 scale."""
    t = ratio_param(value)
    nan = np.isnan(t)
    t = np.where(nan, 0.0, t)[..., None]
    low, mid, high = (np.asarray(c, dtype=np.float64) for c in (COLOR_LOW, COLOR_MID, COLOR_HIGH))
    rgb = np.where(t < 0.0, mid + (low - mid) * (-t), mid + (high - mid) * t)
    rgb = np.where(nan[..., None], np.asarray(COLOR_NAN), rgb)
    return rgb.astype(np.float32)


def visibility_color(value):
    """Colour of each visibility type (0 visible, 1 partial, 2 invisible, else COLOR_NAN)."""
    v = np.asarray(value, dtype=np.float64)
    rgb = np.empty(v.shape + (3,), dtype=np.float64)
    rgb[...] = COLOR_NAN
    with np.errstate(invalid="ignore"):
        k = np.floor(v + 0.5)
    for kind, colour in ((0.0, COLOR_VISIBLE), (1.0, COLOR_PARTIAL), (2.0, COLOR_INVISIBLE)):
        rgb[k == kind] = colour
    return rgb.astype(np.float32)


def overlay_color(value, mode=MODE_RATIO):
    """The shader's colour for ``mode`` (MODE_RATIO or MODE_VISIBILITY)."""
    return visibility_color(value) if mode == MODE_VISIBILITY else ratio_color(value)
