"""Direct irradiance from lamp patches (core/relight/direct.py) against analytic values."""
import numpy as np
import pytest

from relight_addon.core.geometry.raycast import make_occluder
from relight_addon.core.relight.direct import lamp_irradiance
from relight_addon.core.scene import SceneData


def corner_rectangle_F(a, b):
    """Form factor from a point to an a x b rectangle parallel to its plane at distance 1, with
    one corner right above the point (the classic closed form)."""
    sa, sb = np.sqrt(1 + a * a), np.sqrt(1 + b * b)
    return (a / sa * np.arctan(b / sa) + b / sb * np.arctan(a / sb)) / (2 * np.pi)


def _scene(blocker=None):
    lamp = [[0, 0, 1], [0, 1, 1], [1, 1, 1], [1, 0, 1]]          # faces down (-z)
    patches = [lamp]
    if blocker is not None:
        patches.append(blocker)
    n = len(patches)
    emission = np.zeros((n, 3))
    emission[0] = [2.0, 1.0, 0.5]
    return SceneData(np.array(patches, float), 0.0, emission, [0] + [-1] * (n - 1), ["lamp"],
                     occluder=[False] + [True] * (n - 1))


def test_corner_aligned_unit_square_is_the_analytic_value():
    assert corner_rectangle_F(1.0, 1.0) == pytest.approx(0.138532, abs=1e-6)
    sc = _scene()
    U, O = lamp_irradiance(sc, [[0.0, 0.0, 0.0]], [[0.0, 0.0, 1.0]])
    np.testing.assert_allclose(U[0, 0], np.array([2.0, 1.0, 0.5]) * 0.138532, rtol=1e-5)
    np.testing.assert_allclose(O, U)


@pytest.mark.parametrize("backend", ["embree", "numpy"])
def test_half_hidden_lamp_gives_the_visible_half(backend):
    """A blocker at z = 1/2 over [0, 1/4] x [0, 1/2] hides exactly the lamp's half x < 1/2 from
    the origin: the occluded irradiance is that of the rectangle [1/2, 1] x [0, 1]."""
    if backend == "embree":
        pytest.importorskip("embreex")
    blocker = [[0, 0, 0.5], [0.25, 0, 0.5], [0.25, 0.5, 0.5], [0, 0.5, 0.5]]
    sc = _scene(blocker)
    occ = make_occluder(sc.occluder_triangles(), backend)
    U, O = lamp_irradiance(sc, [[0.0, 0.0, 0.0]], [[0.0, 0.0, 1.0]], occ, rays=256, seed=1)
    visible = corner_rectangle_F(1.0, 1.0) - corner_rectangle_F(0.5, 1.0)
    np.testing.assert_allclose(U[0, 0, 0], 2.0 * corner_rectangle_F(1.0, 1.0), rtol=1e-5)
    np.testing.assert_allclose(O[0, 0, 0], 2.0 * visible, rtol=0.02)
    # the ratio estimator has no bias for the hidden half being the nearer one
    assert abs(O[0, 0, 0] / U[0, 0, 0] - visible / corner_rectangle_F(1.0, 1.0)) < 0.02


def test_receiver_behind_the_lamp_plane_gets_nothing():
    U, O = lamp_irradiance(_scene(), [[0.5, 0.5, 2.0]], [[0.0, 0.0, -1.0]])
    assert not U.any() and not O.any()
