"""scenes/light_models.py: internal consistency (numpy only) and a few Cycles bakes (bpy 5.x).

The full measurement is benchmarks/light_units.py; the bakes here are a quick regression of the
main conventions (a few seconds, no cache)."""
import math

import numpy as np
import pytest

import scenes.light_models as LM


def _mc_cone(sin_beta, theta, n=200_000, seed=0):
    rng = np.random.default_rng(seed)
    cb = math.sqrt(1 - sin_beta ** 2)
    cz = 1 - rng.random(n) * (1 - cb)
    ph = 2 * np.pi * rng.random(n)
    sz = np.sqrt(1 - cz * cz)
    d = np.stack([sz * np.cos(ph), sz * np.sin(ph), cz], 1)
    nrm = np.array([math.sin(theta), 0, math.cos(theta)])
    return 2 * np.pi * (1 - cb) * np.maximum(d @ nrm, 0).mean()


@pytest.mark.parametrize("sb", [0.1, 0.5, 0.9])
@pytest.mark.parametrize("deg", [0, 60, 85, 95, 110])
def test_cone_irradiance_matches_monte_carlo(sb, deg):
    th = math.radians(deg)
    ref = _mc_cone(sb, th)
    got = float(LM.cone_irradiance(sb, math.cos(th)))
    assert got == pytest.approx(ref, rel=0.01, abs=2e-4)


@pytest.mark.parametrize("spread_deg", [2, 10, 60, 120, 170])
def test_spread_profile_conserves_power(spread_deg):
    """Integral over the hemisphere of f(a) cos(a) = pi, as for a Lambertian emitter."""
    a = np.linspace(0, np.pi / 2, 400_001)
    f = LM.spread_profile(a, math.radians(spread_deg))
    integral = 2 * np.pi * np.trapz(f * np.cos(a) * np.sin(a), a)
    assert integral == pytest.approx(np.pi, rel=2e-3)


def test_point_limits():
    pts = np.array([[0, 0, -2.0], [0.5, 0, -1.0]])
    nrm = np.array([[0, 0, 1.0], [0, 0, 1.0]])
    e0 = LM.irradiance_point(pts, nrm, (0, 0, 0), 100.0)
    for soft in (True, False):
        e = LM.irradiance_point(pts, nrm, (0, 0, 0), 100.0, radius=1e-4, soft_falloff=soft)
        np.testing.assert_allclose(e, e0, rtol=1e-6)
    # far from the sphere (wholly above the horizon) the sphere is exactly inverse-square
    e = LM.irradiance_point(pts[:1], nrm[:1], (0, 0, 0), 100.0, radius=0.5, soft_falloff=False)
    np.testing.assert_allclose(e, e0[:1], rtol=1e-12)
    assert e0[0, 0] == pytest.approx(100.0 / (4 * np.pi * 4.0))


def test_area_spread_tends_to_lambert():
    pts = np.array([[0.1, 0.05, -0.4], [0.6, 0.0, -0.3]])
    nrm = np.array([[0, 0, 1.0], [-0.3, 0, 1.0]]) / np.array([[1.0], [math.hypot(0.3, 1)]])
    lam = LM.irradiance_area(pts, nrm, np.eye(4), 50.0, shape="RECTANGLE", size=0.5, size_y=0.3)
    wide = LM.irradiance_area(pts, nrm, np.eye(4), 50.0, shape="RECTANGLE", size=0.5, size_y=0.3,
                              spread=math.radians(179.99), grid=256)
    np.testing.assert_allclose(wide, lam, rtol=5e-3)


def test_sun_angle_only_matters_at_the_horizon():
    n = np.array([[0, 0, 1.0], [math.sin(1.2), 0, math.cos(1.2)]])
    d = (0, 0, -1.0)
    a = LM.irradiance_sun(n, d, 3.0)
    b = LM.irradiance_sun(n, d, 3.0, angle=math.radians(30))
    np.testing.assert_allclose(a, b, rtol=1e-12)
    np.testing.assert_allclose(a[:, 0], 3.0 * np.array([1.0, math.cos(1.2)]))


# --------------------------------------------------------------------------- Cycles
def _lu():
    bpy = pytest.importorskip("bpy")
    if tuple(bpy.app.version) < (5, 0, 0):
        pytest.skip("light units were measured on Blender 5.0 only")
    import benchmarks.light_units as lu
    return lu


def test_cycles_point_and_spot():
    lu = _lu()
    cases = [(0.3, 0), (1.0, 60), (0.15, 95)]
    D = lu.fib_dirs(len(cases))
    probes = [lu.probe(d * u, lu.tilted_normal(-u, th), side=0.004, k=4)
              for (d, th), u in zip(cases, D)]
    for r, soft in ((0.0, True), (0.1, True), (0.1, False)):
        cfg = {"probes": probes, "lights": [{"type": "POINT", "props": {
            "energy": 100.0, "shadow_soft_size": r, "use_soft_falloff": soft}}]}
        E = lu.measure(cfg, 64, 0, use_cache=False)
        for pr, e in zip(probes, E):
            pts, nrm = lu.texel_points(pr)
            pred = LM.irradiance_point(pts, nrm, (0, 0, 0), 100.0, radius=r, soft_falloff=soft)
            assert e.mean() == pytest.approx(pred.mean(), rel=0.01), (r, soft, pr)
    # spot: profile across a 60 deg cone, blend 0.3, rotated and non-uniformly scaled
    M = lu.loc_rot_scale((0, 0, 0), (0.3, 0.5, 0.2), (1, 2, 1))
    ang = np.arange(0, 50, 2.5)
    probes = lu._spot_probes(ang, ang * 37.0, 1.0, M)
    cfg = {"probes": probes, "lights": [{"type": "SPOT", "rot": [0.3, 0.5, 0.2],
                                         "scale": [1, 2, 1], "props": {
                                             "energy": 100.0, "spot_size": math.radians(60),
                                             "spot_blend": 0.3, "shadow_soft_size": 0.0}}]}
    E = lu.measure(cfg, 16, 0, use_cache=False).mean(axis=(1, 2))
    pred = np.array([LM.irradiance_spot(*lu.texel_points(p), M, 100.0,
                                        spot_size=math.radians(60), spot_blend=0.3).mean()
                     for p in probes])
    np.testing.assert_allclose(E, pred, atol=2e-3 * pred.max())


def test_cycles_area_spread_emission_and_back_faces():
    lu = _lu()
    xs = [0.0, 0.2, 0.3]
    probes = [lu.probe((x, 0.0, -0.5), (0, 0, 1), 0.005, 4) for x in xs]
    spread = math.radians(60)
    cfg = {"probes": probes, "lights": [{"type": "AREA", "props": {
        "energy": 50.0, "shape": "RECTANGLE", "size": 0.5, "size_y": 0.3, "spread": spread}}]}
    E = lu.measure(cfg, 256, 0, use_cache=False).mean(axis=(1, 2))
    pred = np.array([LM.irradiance_area(*lu.texel_points(p), np.eye(4), 50.0,
                                        shape="RECTANGLE", size=0.5, size_y=0.3,
                                        spread=spread).mean() for p in probes])
    np.testing.assert_allclose(E, pred, rtol=0.01)

    # mesh emission lights both sides; a receiver facing away from every lamp bakes to 0
    quad = lu.QUAD
    probes = [lu.probe((0.05, 0, 0.3), (0, 0, -1), 0.005, 4),
              lu.probe((0.05, 0, -0.3), (0, 0, 1), 0.005, 4),
              lu.probe((0.5, 0.5, -0.3), (0, 0, -1), 0.005, 4)]
    cfg = {"probes": probes, "emitters": [{"verts": quad, "faces": [[0, 1, 2, 3]],
                                           "strength": 10.0}]}
    E = lu.measure(cfg, 256, 0, use_cache=False).mean(axis=(1, 2))
    pred = np.array([LM.irradiance_emissive_polygon(*lu.texel_points(p), quad, 10.0).mean()
                     for p in probes])
    np.testing.assert_allclose(E[:2], pred[:2], rtol=0.01)
    assert pred[0] > 1.0 and E[2] == 0.0
