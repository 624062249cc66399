"""Reflectance (eq 4.1) and lamp exitance (eq 4.2, and per lamp by NNLS) estimation."""
import numpy as np
import pytest

from relight_addon.core.radiosity.precompute import solve_radiosity
from relight_addon.core.relight.albedo import estimate_reflectance
from relight_addon.core.relight.exitance import equal_lamp_exitance, fit_lamp_exitance
from relight_addon.core.texture.colour import LUMINANCE
from relight_addon.core.scene import SceneData
from scenes.testscenes import cornell_box, flip


def test_uniform_lighting_recovers_reflectances_up_to_the_mean():
    """Under uniform irradiance B_i = rho_i H: eq 4.1 returns rho_i exactly when rho^ is right."""
    rng = np.random.default_rng(0)
    rho_true = rng.uniform(0.1, 0.8, (40, 3))
    area = rng.uniform(0.5, 2.0, 40)
    photo = 0.37 * rho_true                                       # any exposure
    mean_true = float(area @ (rho_true @ LUMINANCE)) / area.sum()
    est = estimate_reflectance(photo, area, rho_mean=mean_true)
    assert np.allclose(est.rho, rho_true, rtol=1e-9)
    assert est.rho_mean == pytest.approx(mean_true)


def test_mean_reflectance_is_re_estimated_when_clamping_bites():
    photo = np.array([[0.9, 0.9, 0.9], [0.1, 0.1, 0.1]])
    area = np.array([1.0, 1.0])
    est = estimate_reflectance(photo, area, rho_mean=0.8, rho_max=0.95)
    # 0.9 / 0.5 * 0.8 = 1.44 is clamped to 0.95, so the mean drops and is re-estimated.
    assert est.rho_mean < 0.8
    assert est.rho.max() <= 0.95
    lum_mean = float(area @ (est.rho @ LUMINANCE)) / area.sum()
    assert est.rho_mean == pytest.approx(lum_mean, rel=1e-6)      # a fixed point
    with pytest.raises(ValueError, match="black"):
        estimate_reflectance(np.zeros((2, 3)), area)


def _two_lamp_cornell(e_left, e_right):
    base = cornell_box()
    keep = base.emission.max(axis=1) == 0
    s, z = 5.5, 5.5 - 0.01
    lamps = []
    for x0 in (0.8, 3.7):
        q = np.array([[[x0, 2.2, z], [x0 + 1.0, 2.2, z], [x0 + 1.0, 3.2, z], [x0, 3.2, z]]])
        lamps.append(flip(q)[0])                                     # facing down
    corners = np.concatenate([base.corners[keep], np.array(lamps)])
    n = len(corners)
    rho = np.concatenate([base.rho[keep], np.zeros((2, 3))])
    emission = np.zeros((n, 3))
    emission[-2], emission[-1] = e_left, e_right
    lamp = np.full(n, -1)
    lamp[-2], lamp[-1] = 0, 1
    occluder = np.concatenate([base.occluder[keep], [False, False]])
    assert corners[..., :2].max() <= s
    return SceneData(corners, rho, emission, lamp, ["left", "right"], occluder=occluder)


def test_unequal_lamps_are_recovered_from_an_independent_photo():
    """Mitsuba 3 renders the 'photo' of a box lit by two unequal lamps; with the true
    reflectances, NNLS on our per-lamp basis finds both exitances, eq 4.2 cannot."""
    pytest.importorskip("mitsuba")
    from reference.mitsuba_ref import patch_radiosity
    truth = np.array([30.0, 80.0])
    scene = _two_lamp_cornell(truth[0], truth[1])
    surfaces = np.flatnonzero(scene.lamp < 0)
    photo = patch_radiosity(scene, patches=surfaces, spp=1 << 18)
    unit = SceneData(scene.corners, scene.rho, (scene.lamp >= 0)[:, None] * 1.0, scene.lamp,
                     scene.lamp_names, occluder=scene.occluder)
    sol = solve_radiosity(unit, "medium")
    basis = np.stack([sol.patch_radiosity(np.eye(2)[k])[surfaces] for k in range(2)])
    area = scene.area_normal()[0][surfaces]
    fit = fit_lamp_exitance(basis, photo, area)
    print(f"NNLS exitances {fit.exitance} (truth {truth}), residual {fit.residual:.3f}")
    assert not fit.rank_deficient
    assert np.allclose(fit.exitance, truth, rtol=0.08)
    # Eq 4.2 with the true mean reflectance gives one value for both lamps.
    lum = photo @ LUMINANCE
    b_a = float(area @ lum) / area.sum()
    rho_mean = float(area @ (scene.rho[surfaces] @ LUMINANCE)) / area.sum()
    lamp_area = scene.area_normal()[0][scene.lamp >= 0].sum()
    equal = equal_lamp_exitance(b_a, rho_mean, area.sum(), lamp_area)
    print(f"eq 4.2 equal-lamp exitance {equal:.1f}")
    nnls_err = np.abs(fit.exitance / truth - 1).max()
    equal_err = np.abs(equal / truth - 1).max()
    assert nnls_err < equal_err / 3


def test_nnls_never_returns_negative_exitance():
    rng = np.random.default_rng(1)
    basis = rng.random((3, 50, 3))
    observed = 2.0 * basis[0] - 0.5 * basis[1]                     # not reachable with E >= 0
    fit = fit_lamp_exitance(basis, observed, np.ones(50))
    assert np.all(fit.exitance >= 0)
    assert fit.exitance[1] == 0.0
