"""How much of the photo's lamp ratios replaces the user's set powers (relight.exitance):
nothing below PINNED_Z sigma, all from PINNED_Z + PINNED_RAMP on, continuously between, so that
an estimate near the edge does not flip the relit result with the solver's seed."""
import os
import sys

import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from relight_addon.core.relight.exitance import (  # noqa: E402
    PINNED_RAMP, PINNED_SIGMA, PINNED_Z, photo_factors, photo_weights)

ON2 = np.array([True, True])


def _pair(z, sigma=0.06):
    """Two lamps whose photo ratios (geometric mean 1) put lamp 0 at z sigma from 1."""
    t0 = np.exp(-z * sigma)
    return np.array([t0, 1 / t0]), np.array([sigma, 3 * sigma])   # lamp 1 too unsure


def test_weights_are_zero_below_the_edge_one_past_the_ramp_and_linear_between():
    sigma = np.full(4, 0.05)
    z = np.array([PINNED_Z - 0.01, PINNED_Z + 0.25 * PINNED_RAMP, PINNED_Z + PINNED_RAMP, 9.0])
    w = photo_weights(np.exp(z * sigma), sigma)
    assert w == pytest.approx([0.0, 0.25, 1.0, 1.0])
    assert photo_weights(np.exp(-z * sigma), sigma) == pytest.approx(w)     # either side of 1
    # too unsure to override, however far: kept; no estimate: kept
    assert photo_weights(np.array([0.2]), np.array([PINNED_SIGMA])) == [0.0]
    assert photo_weights(np.array([np.nan, 1.0]), np.array([0.05, 0.0])).tolist() == [0.0, 0.0]


def test_a_lamp_past_the_ramp_takes_the_photos_ratio_against_the_kept_lamp():
    """The rule before the ramp: the photo's ratio between a pinned and a kept lamp, exactly."""
    t, sigma = _pair(5.0)
    w = photo_weights(t, sigma)
    assert w.tolist() == [1.0, 0.0]
    f = photo_factors(t, w, ON2)
    assert f[0] / f[1] == pytest.approx(t[0] / t[1])
    assert f[1] == pytest.approx(1.0)                 # the kept lamp keeps the user's power


def test_every_lamp_in_full_takes_the_photos_ratios():
    t = np.array([0.7, 1.1, 1 / 0.77])
    f = photo_factors(t, np.ones(3), np.ones(3, bool))
    assert f / f[0] == pytest.approx(t / t[0])


def test_partial_weight_takes_a_continuous_share_of_the_ratio():
    """Beside one kept lamp, weight w takes (t / t_kept) ** (w / (2 - w)); the ratio moves
    continuously and monotonically with z through the edge and the ramp's end."""
    t = np.array([0.8, 1.25])
    for w in (0.1, 0.5, 0.9):
        f = photo_factors(t, np.array([w, 0.0]), ON2)
        assert f[0] / f[1] == pytest.approx((t[0] / t[1]) ** (w / (2 - w)))
    zs = np.linspace(PINNED_Z - 0.2, PINNED_Z + PINNED_RAMP + 0.2, 401)
    ratios = []
    for z in zs:
        t, sigma = _pair(z)
        f = photo_factors(t, photo_weights(t, sigma), ON2)
        ratios.append(np.log(f[0] / f[1]))
    ratios = np.array(ratios)
    assert ratios[zs < PINNED_Z] == pytest.approx(0.0, abs=1e-12)
    steps = np.diff(ratios)
    assert np.all(steps <= 1e-12)                     # lamp 0 below 1: more correction, lower
    assert np.max(np.abs(steps)) < 0.01               # no jump (the old rule: 0.24 at once)
    t, sigma = _pair(zs[-1])
    assert ratios[-1] == pytest.approx(np.log(t[0] / t[1]))


def test_lamps_off_in_the_photo_are_left_alone():
    t = np.array([0.8, np.nan, 1.25])
    on = np.array([True, False, True])
    f = photo_factors(t, np.array([1.0, 0.0, 0.0]), on)
    assert f[1] == 1.0 and np.isfinite(f).all()
    assert f[0] / f[2] == pytest.approx(0.8 / 1.25)
    # a lamp the fit cannot tell (no ratio, or none of the light) neither moves nor moves others
    for bad in (np.nan, 0.0):
        t = np.array([0.8, bad, 1.25])
        f = photo_factors(t, np.array([1.0, 0.0, 0.0]), np.ones(3, bool))
        assert np.isfinite(f).all() and f[1] == 1.0
        assert f[0] / f[2] == pytest.approx(0.8 / 1.25)
