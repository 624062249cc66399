"""Glossy reflection from the cube mips (core/ar/glossy.py).

Truths: McGuire's formula evaluated by hand, the mirror limit (the finest level in the mirror
direction), and Cycles' render of a sphere with a white GGX Glossy BSDF under the same World
map (tests/ar_cycles.py, cached; slow on a cold cache: ~10 s a render).
"""
from __future__ import annotations

import numpy as np
import pytest

import ar_truth as T
from relight_addon.core.ar import envmap as E
from relight_addon.core.ar import glossy as G

HDRIS = T.bundled_hdris()


def test_mcguire_level_and_exponent():
    assert G.mcguire_mip_level(3.0, 128) == pytest.approx(np.log2(128 * np.sqrt(3)) - 1.0)
    assert G.mcguire_mip_level(0.0, 128) == 7.0                   # clamped to the 1 x 1 level
    assert G.mcguire_mip_level(1e12, 128) == 0.0                  # a mirror: the finest
    assert G.phong_exponent(1.0) == 0.0
    assert G.phong_exponent(0.5) == pytest.approx(2 / 0.25 ** 2 - 2)
    assert np.isfinite(G.phong_exponent(0.0))
    r = G.reflect(np.array([[0.0, 0.6, -0.8]]), np.array([[0.0, 0.0, 1.0]]))
    np.testing.assert_allclose(r, [[0.0, 0.6, 0.8]])


def test_mirror_reads_the_finest_level():
    d = E.equirect_directions(64, 128)
    env = np.stack([1 + d[..., 0], 1 + d[..., 1], 1 + d[..., 2]], -1)
    mips = E.cube_mips(E.equirect_to_cube(env, 32))
    rng = np.random.default_rng(0)
    v = rng.normal(size=(200, 3)); v /= np.linalg.norm(v, axis=1, keepdims=True)
    np.testing.assert_allclose(G.glossy_radiance(mips, v, 1e9), E.sample_cube(mips[0], v))
    np.testing.assert_allclose(G.glossy_radiance(mips, v, 1e9), 1 + v, atol=0.01)


@pytest.mark.slow
@pytest.mark.skipif(not HDRIS, reason="the bpy wheel's HDRIs are not installed")
@pytest.mark.parametrize("roughness", [0.2, 0.4])
def test_against_a_cycles_glossy_sphere(roughness):
    """Pixels of the sphere's central disk (r < 0.8), luminance.  Measured (forest, 64 px, 128
    samples): mean relative error 0.19 (r 0.2), 0.27 (r 0.4); ratio of the means 1.00, 1.03;
    the image flipped left-right or up-down does not correlate (the map's orientation)."""
    pytest.importorskip("bpy")
    import ar_cycles as C
    from relight_addon.core.ar.lighting import prepare_environment
    lit = prepare_environment(T.load_exr(HDRIS["forest"]))
    res = 64
    img, _ = C.cycles_glossy_sphere(HDRIS["forest"], roughness, res, 128)
    c = (np.arange(res) + 0.5) / res * 2 - 1
    Z, Y = np.meshgrid(c, c, indexing="ij")
    disk = Y ** 2 + Z ** 2 < 0.64
    X = np.sqrt(np.maximum(1 - Y ** 2 - Z ** 2, 0))
    got = img[disk] @ T.LUM

    def predict(sy, sz):
        n = np.stack([X, sy * Y, sz * Z], -1)[disk]
        r = G.reflect(np.array([-1.0, 0, 0]), n)
        return G.glossy_radiance(lit.mips, r, G.phong_exponent(roughness), lit.padded) @ T.LUM

    pred = predict(1, 1)
    assert np.mean(np.abs(pred - got) / got) < 0.35
    assert pred.mean() / got.mean() == pytest.approx(1.0, abs=0.1)
    assert np.corrcoef(pred, got)[0, 1] > 0.8
    assert abs(np.corrcoef(predict(-1, 1), got)[0, 1]) < 0.5
