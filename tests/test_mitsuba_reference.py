"""Validate the Mitsuba reference (tests/reference/mitsuba_ref.py) against analytic truth, so
that the solver tests can trust it.  Results are cached under .cache/mitsuba/."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
for p in (ROOT, ROOT / "tests"):
    if str(p) not in sys.path:
        sys.path.insert(0, str(p))

pytest.importorskip("mitsuba")

from scenes import testscenes as T  # noqa: E402
from relight_addon.core.scene import SceneData  # noqa: E402
from reference import mitsuba_ref as M  # noqa: E402

SPP_FF = 1 << 22  # ~0.12 % standard error for the unit-square form factors


def parallel_rectangles_ff(a, b, c):
    """Form factor between directly opposed parallel a x b rectangles at distance c."""
    x, y = a / c, b / c
    sx, sy = np.sqrt(1 + x * x), np.sqrt(1 + y * y)
    return 2 / (np.pi * x * y) * (
        np.log(sx * sy / np.sqrt(1 + x * x + y * y))
        + x * sy * np.arctan(x / sy) + y * sx * np.arctan(y / sx)
        - x * np.arctan(x) - y * np.arctan(y))


def _check_ff(H, err, exact, rtol):
    assert np.allclose(H, H[..., :1]), "grey scene must give grey irradiance"
    assert np.all(err < rtol / 3 * exact), f"reference too noisy: stderr {err} vs {exact}"
    assert np.all(np.abs(H - exact) < rtol * exact), f"{H} vs exact {exact}"


def test_analytic_form_factor_constants():
    assert parallel_rectangles_ff(1, 1, 1) == pytest.approx(T.PARALLEL_UNIT_SQUARES_F1, abs=1e-6)


def test_parallel_unit_squares_direct():
    # max_depth=2: at most one reflection; the emitter is black so this is the direct light.
    scene = T.parallel_squares(distance=1.0)
    H, err = M.patch_irradiance(scene, [1], spp=SPP_FF, max_depth=2, return_stderr=True)
    _check_ff(H, err, T.PARALLEL_UNIT_SQUARES_F1, 0.005)


def test_perpendicular_unit_squares_direct():
    scene = T.perpendicular_squares()
    H, err = M.patch_irradiance(scene, [1], spp=SPP_FF, max_depth=2, return_stderr=True)
    _check_ff(H, err, T.PERPENDICULAR_UNIT_SQUARES_F, 0.005)


def test_closed_cube_furnace():
    rho = np.array([0.3, 0.5, 0.7])
    E = 1.0
    scene = T.closed_cube(rho=rho, emission=E, n=1)
    H, err = M.patch_irradiance(scene, spp=1 << 16, max_depth=-1, return_stderr=True)
    exact = E / (1 - rho)
    assert np.all(err < 0.0035 * exact)  # well below the 1 % tolerance
    assert np.allclose(H, exact, rtol=0.01), (H, exact)
    B = M.patch_radiosity(scene, spp=1 << 16, max_depth=-1)  # cached, same run
    assert np.allclose(B, exact, rtol=0.01)


def test_back_faces_neither_receive_nor_emit_nor_reflect():
    # receiver turned away from the emitter
    s = T.parallel_squares()
    s.corners[1] = T.flip(s.corners[1])
    assert np.all(M.patch_irradiance(s, [1], spp=1 << 14) == 0)
    # emitter turned away from the receiver (area lights are one-sided)
    s = T.parallel_squares()
    s.corners[0] = T.flip(s.corners[0])
    assert np.all(M.patch_irradiance(s, [1], spp=1 << 14) == 0)
    # a white reflector shows its back to an emitter: nothing comes back to the emitter
    emitter = np.array([[[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]], float)  # z=0, up
    reflector = emitter + [0, 0, 1]  # z=1, facing up: back side towards the emitter
    scene = SceneData(corners=np.concatenate([emitter, reflector]), rho=[[0, 0, 0], [0.9, 0.9, 0.9]],
                      emission=[[1, 1, 1], [0, 0, 0]], lamp=[0, -1])
    assert np.all(M.patch_irradiance(scene, [0], spp=1 << 14, max_depth=-1) == 0)
    # control: the reflector turned towards the emitter does send light back
    scene.corners[1] = T.flip(scene.corners[1])
    H = M.patch_irradiance(scene, [0], spp=1 << 16, max_depth=-1)
    f = T.PARALLEL_UNIT_SQUARES_F1
    assert np.allclose(H, 0.9 * f * f, rtol=0.05)  # + tiny multiple-bounce term (emitter is black)


def test_non_occluding_emitter_is_transparent():
    """A non-occluder emitter (null BSDF) at z=1 in front of an occluding emitter at z=2."""
    f1, f2 = parallel_rectangles_ff(1, 1, 1), parallel_rectangles_ff(1, 1, 2)
    base = T.parallel_squares(distance=1.0)  # 0 emitter z=1, 1 receiver
    far = T.parallel_squares(distance=2.0).corners[0]
    def scene(near_occludes):
        return SceneData(corners=np.concatenate([base.corners, far[None]]),
                         rho=[[0] * 3, [0.5] * 3, [0] * 3], emission=[[1] * 3, [0] * 3, [1] * 3],
                         lamp=[0, -1, 1], occluder=[near_occludes, True, True])
    H_transparent = M.patch_irradiance(scene(False), [1], spp=1 << 21, max_depth=1)
    H_opaque = M.patch_irradiance(scene(True), [1], spp=1 << 21, max_depth=1)
    assert np.allclose(H_transparent, f1 + f2, rtol=0.01), (H_transparent, f1 + f2)
    assert np.allclose(H_opaque, f1, rtol=0.01), (H_opaque, f1)
