"""Sphere shadows under an environment map (core/ar/cap.py, core/ar/env_shadow.py).

Truths: a fine numerical integration of the cosine over a cap clipped by the horizon; the
closed form of a uniform map (F = 1 - C / pi); shadow factors ray traced under the same map
through analytic spheres and, with Embree, through a real mesh (tests/ar_truth.py).
"""
from __future__ import annotations

import numpy as np
import pytest

import ar_truth as T
from relight_addon.core.ar.cap import cap_cosine_integral, seed_cap_cosine_integral
from relight_addon.core.ar.env_shadow import env_shadow_factor, luminance_factor, world_spheres
from relight_addon.core.ar.lighting import prepare_environment

HDRIS = T.bundled_hdris()
needs_hdris = pytest.mark.skipif(not HDRIS, reason="the bpy wheel's HDRIs are not installed")
UP = np.array([0.0, 0.0, 1.0])


class _Lit(dict):
    def __missing__(self, key):
        self[key] = prepare_environment(T.load_exr(HDRIS[key]))
        return self[key]


@pytest.fixture(scope="module")
def lit():
    """Bundled maps prepared on first use (2-4 s each)."""
    return _Lit()


def numeric_cap_integral(beta, alpha, n=300):
    """Integral over the cap (axis at angle beta from the normal z, half-angle alpha) of
    max(cos, 0), by a midpoint rule in the cap's own polar coordinates (n x 2n cells)."""
    t = (np.arange(n) + 0.5) / n * alpha
    p = (np.arange(2 * n) + 0.5) / (2 * n) * 2 * np.pi
    Tt, P = np.meshgrid(t, p, indexing="ij")
    # direction in the cap frame (axis = z'), rotated by beta about y
    x, y, z = np.sin(Tt) * np.cos(P), np.sin(Tt) * np.sin(P), np.cos(Tt)
    cz = -np.sin(beta) * x + np.cos(beta) * z
    dw = np.sin(Tt) * (alpha / n) * (2 * np.pi / (2 * n))
    return float((np.maximum(cz, 0) * dw).sum())


def test_cap_integral_exact_including_the_horizon():
    errs, seed_errs = [], []
    for alpha in np.radians([2, 10, 30, 50, 70, 85]):
        for beta in np.linspace(0, np.pi, 19):
            truth = numeric_cap_integral(beta, alpha)
            c = cap_cosine_integral(np.cos(beta), np.sin(alpha) ** 2)
            errs.append(abs(c - truth))
            seed_errs.append(abs(seed_cap_cosine_integral(np.cos(beta), np.sin(alpha) ** 2)
                                 - truth) / np.pi)
    assert max(errs) < 2e-4
    # the seed's formula (in units of its 1/pi-normalised integral) is wrong for caps across
    # the horizon; centred on it, by (alpha - sin alpha cos alpha) / pi: 0.23 at 64 deg
    a = np.radians(64)
    assert seed_cap_cosine_integral(0.0, np.sin(a) ** 2) == 0.0
    assert cap_cosine_integral(0.0, np.sin(a) ** 2) / np.pi == pytest.approx(
        (a - np.sin(a) * np.cos(a)) / np.pi, abs=1e-12)
    assert (a - np.sin(a) * np.cos(a)) / np.pi == pytest.approx(0.23, abs=0.005)
    assert max(seed_errs) > 0.4                       # 85 deg caps on this grid
    # receiver inside the sphere, wholly above, wholly below
    assert cap_cosine_integral(0.3, 1.5) == pytest.approx(np.pi)
    assert cap_cosine_integral(1.0, 0.25) == pytest.approx(np.pi * 0.25)
    assert cap_cosine_integral(-0.9, 0.1) == 0.0
    with np.errstate(invalid="raise", divide="raise", over="raise"):
        v = cap_cosine_integral(np.array([1.0, -1.0, 0.0, 0.0, 1e-300]),
                                np.array([0.0, 0.0, 0.0, 1.0 - 1e-16, 1e-300]))
    assert np.all(np.isfinite(v)) and np.all((v >= 0) & (v <= np.pi))


def uniform_lighting(value=1.0):
    return prepare_environment(np.full((32, 64, 3), value))


def floor_grid(half=1.5, n=31, z=0.0):
    x = np.linspace(-half, half, n)
    X, Y = np.meshgrid(x, x)
    P = np.stack([X.ravel(), Y.ravel(), np.full(X.size, z)], 1)
    return P, np.tile(UP, (len(P), 1))


@pytest.mark.parametrize("height", [0.8, 0.1])          # high, and cut by the floor
def test_one_sphere_under_a_uniform_map(height):
    """Uniform map: E = pi L, F = 1 - C / pi exactly; against ray tracing the sphere."""
    lit = uniform_lighting()
    c, r = np.array([[0.1, -0.2, height]]), np.array([0.3])
    P, N = floor_grid()
    F = env_shadow_factor(P, N, c, r, lit)
    axis = c[0] - P
    d = np.linalg.norm(axis, axis=1)
    closed = 1 - cap_cosine_integral(axis[:, 2] / d, (r[0] / d) ** 2) / np.pi
    # (up to the midpoint rule of the irradiance table over a 32 x 64 map: ~1e-3 of pi)
    np.testing.assert_allclose(F, np.repeat(closed[:, None], 3, 1), atol=1.5e-3)
    traced = T.traced_shadow_factor(T.SphereOccluder(c, r), P, UP, lit.env, rays=1024, seed=3)
    assert np.abs(F[:, 1] - traced).mean() < 0.006
    seed = env_shadow_factor(P, N, c, r, lit, cap="seed")[:, 1]
    if height < 0.3:             # caps across the horizon: the seed's formula is off there
        out = d > r[0] + 0.02        # receivers outside the sphere's footprint
        assert np.abs(seed - traced)[out].max() > 0.1 > np.abs(F[:, 1] - traced)[out].max()


@needs_hdris
@pytest.mark.parametrize("name", ["courtyard", "city"])
def test_one_sphere_under_a_bundled_map(lit, name):
    lit = lit[name]
    c, r = np.array([[0.0, 0.0, 0.6]]), np.array([0.35])
    P, N = floor_grid(2.0, 41)
    F = luminance_factor(P, N, env_shadow_factor(P, N, c, r, lit), lit)
    traced = T.traced_shadow_factor(T.SphereOccluder(c, r), P, UP, lit.env, rays=1024, seed=1)
    shadow = (traced < 0.99) | (F < 0.99)
    # measured: city 0.012, interior 0.015 (the main light's cone vs its real outline)
    assert np.abs(F - traced)[shadow].mean() < 0.025
    sh = luminance_factor(P, N, env_shadow_factor(P, N, c, r, lit, weighting="light+sh"), lit)
    assert np.abs(sh - traced)[shadow].mean() < 0.06
    seedway = luminance_factor(P, N, env_shadow_factor(P, N, c, r, lit, weighting="mips"), lit)
    assert np.abs(seedway - traced)[shadow].mean() < 0.06


@needs_hdris
@pytest.mark.parametrize("name", ["courtyard", "city"])
def test_suzanne_on_the_floor_with_32_spheres_against_embree(lit, name):
    """The issue's target: MAE <= 0.03 inside the shadow at 32 spheres, against the real mesh
    ray traced under the same map (Suzanne 5 cm above the floor; an overcast courtyard and a
    sunny city).  benchmarks/results/ar.md (32 cells, 512 rays): 0.019 and 0.014; the chair
    and the torus standing on a table top reach 0.05-0.08 there (the spheres miss the contacts)."""
    import ar_scenes as S
    from relight_addon.core.geometry.raycast import make_occluder
    from relight_addon.core.relight.spheres import fit_spheres, silhouette_sphere
    tri = S.suzanne()
    c, r = fit_spheres(tri, 32, seed=0)
    hull = silhouette_sphere(tri)
    (P, n), = S.receivers("ground", tri, 28)
    N = np.tile(n, (len(P), 1))
    F = luminance_factor(P, N, env_shadow_factor(P, N, c, r, lit[name], hull), lit[name])
    traced = T.traced_shadow_factor(make_occluder(tri), P, n, lit[name].env, rays=512, seed=2)
    shadow = (traced < 0.99) | (F < 0.99)
    assert shadow.sum() > 100
    assert np.abs(F - traced)[shadow].mean() < 0.03
    # the seed's way (mip-chain weighting, its cap formula) on the same receivers
    seed = luminance_factor(P, N, env_shadow_factor(P, N, c, r, lit[name], hull, weighting="mips",
                                                    cap="seed"), lit[name])
    assert np.abs(seed - traced)[shadow].mean() > np.abs(F - traced)[shadow].mean()


def test_edge_cases_are_finite():
    lit = uniform_lighting()
    P = np.array([[0, 0, 0.5], [0, 0, 0.0], [5, 5, 0.0]])
    N = np.tile(UP, (3, 1))
    with np.errstate(invalid="raise", divide="raise"):
        F = env_shadow_factor(P, N, [[0, 0, 0.5]], [0.4], lit)
    assert np.all(np.isfinite(F)) and F[0].max() == 0.0 and F[2].min() > 0.99
    assert np.array_equal(env_shadow_factor(P, N, np.zeros((0, 3)), np.zeros(0), lit),
                          np.ones((3, 3)))
    black = prepare_environment(np.zeros((8, 16, 3)))
    assert np.array_equal(env_shadow_factor(P, N, [[0, 0, 0.5]], [0.4], black)[2], np.ones(3))


def test_world_spheres_follow_the_matrix():
    m = np.eye(4)
    m[:3, :3] *= 2.0
    m[:3, 3] = [1, 2, 3]
    c, r = world_spheres([[0.5, 0, 0]], [0.25], m)
    np.testing.assert_allclose(c, [[2, 2, 3]])
    np.testing.assert_allclose(r, [0.5])
