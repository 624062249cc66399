"""AR environment lighting (core/ar: envmap, irradiance, main_light, lighting).

Truths: brute-force sums over every pixel of the map (tests/ar_truth.py, written apart from
core/ar), closed forms (solid angles, the irradiance of band-limited maps and of a uniform
map), numerical integration over a fine cube, a synthetic map with a known light, and the
bundled HDRIs of the bpy wheel.
"""
from __future__ import annotations

import numpy as np
import pytest

import ar_truth as T
from relight_addon.core.ar import envmap as E
from relight_addon.core.ar import irradiance as I
from relight_addon.core.ar.lighting import prepare_environment
from relight_addon.core.ar.main_light import extract_lights, extract_main_light

HDRIS = T.bundled_hdris()
needs_hdris = pytest.mark.skipif(not HDRIS, reason="the bpy wheel's HDRIs are not installed")


def random_normals(n, seed=0):
    v = np.random.default_rng(seed).normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


class _Maps(dict):
    """Bundled maps, read and validated on first use."""

    def __missing__(self, key):
        self[key] = E.validate_environment(T.load_exr(HDRIS[key]))
        return self[key]


@pytest.fixture(scope="module")
def maps():
    return _Maps()


# --- conventions and solid angles ------------------------------------------------------------

def test_equirect_convention_and_solid_angles():
    # Blender: +X at the image centre, +Y at u = 1/4, the zenith at v = 1 (measured with a
    # Cycles render of a coded World image when this module was written)
    u, v = E.direction_to_equirect(np.array([[1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1.0]]))
    np.testing.assert_allclose(u[:3], [0.5, 0.25, 0.75], atol=1e-12)
    assert v[3] == pytest.approx(1.0)
    np.testing.assert_allclose(E.equirect_directions(16, 32), T.pixel_directions(16, 32),
                               atol=1e-12)
    assert E.equirect_solid_angles(16, 32).sum() * 32 == pytest.approx(4 * np.pi)
    assert E.cube_solid_angles(32).sum() * 6 == pytest.approx(4 * np.pi)
    # one texel's solid angle against a fine midpoint rule over it
    e = np.linspace(-1, 1, 9)
    s = np.linspace(e[2], e[3], 401)[:-1] + (e[3] - e[2]) / 800
    t = np.linspace(e[5], e[6], 401)[:-1] + (e[6] - e[5]) / 800
    S, Tt = np.meshgrid(s, t)
    fine = ((1 + S ** 2 + Tt ** 2) ** -1.5).sum() * ((e[3] - e[2]) / 400) ** 2
    assert E.cube_solid_angles(8)[5, 2] == pytest.approx(fine, rel=1e-5)


def test_cube_faces_follow_opengl():
    # the OpenGL specification's table (major axis, sc, tc) for direction (x, y, z)
    rng = np.random.default_rng(1)
    d = rng.normal(size=(2000, 3))
    face, s, t = E.direction_to_cube(d)
    x, y, z = d.T
    ax = np.abs(d)
    spec_face = np.where((ax[:, 0] >= ax[:, 1]) & (ax[:, 0] >= ax[:, 2]), np.where(x > 0, 0, 1),
                         np.where(ax[:, 1] >= ax[:, 2], np.where(y > 0, 2, 3),
                                  np.where(z > 0, 4, 5)))
    sc = np.choose(spec_face, [-z, z, x, x, x, -x])
    tc = np.choose(spec_face, [-y, -y, z, -z, -y, -y])
    ma = np.choose(spec_face, [ax[:, 0], ax[:, 0], ax[:, 1], ax[:, 1], ax[:, 2], ax[:, 2]])
    assert np.array_equal(face, spec_face)
    np.testing.assert_allclose(s, sc / ma, atol=1e-12)
    np.testing.assert_allclose(t, tc / ma, atol=1e-12)
    back = np.stack([E.face_directions(f, s[i], t[i]) for i, f in enumerate(face)])
    back /= np.linalg.norm(back, axis=1, keepdims=True)
    np.testing.assert_allclose(back, d / np.linalg.norm(d, axis=1, keepdims=True), atol=1e-12)


def smooth_map(h=64, w=128):
    d = E.equirect_directions(h, w)
    base = 1.0 + 0.6 * d[..., 2] + 0.3 * d[..., 0] * d[..., 1] + 0.2 * np.sin(3 * d[..., 0])
    return np.stack([base, 0.8 * base + 0.1, 1.2 * base], -1)


def test_equirect_cube_round_trip():
    env = smooth_map()
    cube = E.equirect_to_cube(env, 32)
    back = E.cube_to_equirect(cube, 64, 128)
    assert np.abs(back - env).max() < 0.01 * env.max()
    # texels hold their solid-angle means: the total power is kept
    power = (env * E.equirect_solid_angles(64, 128)[:, None, None]).sum((0, 1))
    cpow = (cube * E.cube_solid_angles(32)[None, :, :, None]).sum((0, 1, 2))
    np.testing.assert_allclose(cpow, power, rtol=2e-3)
    # seamless: lookups just either side of a face edge agree
    a = np.array([1.0, 0.3, 0.999]); b = np.array([0.999, 0.3, 1.0])
    va, vb = E.sample_cube(cube, a[None]), E.sample_cube(cube, b[None])
    assert np.abs(va - vb).max() < 0.01 * np.abs(va).max()


@needs_hdris
def test_coarsest_mip_is_each_faces_mean(maps):
    env = maps["sunset"]
    mips = E.cube_mips(E.equirect_to_cube(env, 64))
    assert [m.shape[1] for m in mips] == [64, 32, 16, 8, 4, 2, 1]
    h, w = env.shape[:2]
    d = T.pixel_directions(h, w).reshape(-1, 3)
    om = np.repeat(T.pixel_solid_angles(h, w), w)
    ax = np.argmax(np.abs(d), 1)
    face = 2 * ax + (d[np.arange(len(d)), ax] < 0)
    L = env.reshape(-1, 3)
    for f in range(6):
        sel = face == f
        mean = (L[sel] * om[sel, None]).sum(0) / om[sel].sum()
        np.testing.assert_allclose(mips[-1][f, 0, 0], mean, rtol=0.01)


# --- validation ---------------------------------------------------------------------------------

@pytest.mark.parametrize("bad,words", [
    (np.ones((1, 1, 3)), "too small"),
    (np.ones((1, 1, 4)), "too small"),
    (np.where(np.arange(8 * 16 * 3).reshape(8, 16, 3) == 5, np.nan, 1.0), "NaN"),
    (np.where(np.arange(8 * 16 * 3).reshape(8, 16, 3) == 5, np.inf, 1.0), "infinite"),
    (np.where(np.arange(8 * 16 * 3).reshape(8, 16, 3) == 5, -2.0, 1.0), "negative"),
    (np.ones((8, 16, 2)), "shape"),
    ("sky", "not an array"),
])
def test_bad_environments_raise_one_clear_sentence(bad, words):
    before = np.array(bad, copy=True) if not isinstance(bad, str) else bad
    with pytest.raises(ValueError) as info:
        prepare_environment(bad)
    msg = str(info.value)
    assert words in msg and msg.endswith(".") and msg.count(". ") == 0
    if not isinstance(bad, str):
        np.testing.assert_array_equal(np.asarray(bad), before)       # nothing changed


@needs_hdris
def test_bundled_maps_validate_with_noise_clamped(maps):
    raw = T.load_exr(HDRIS["forest"])
    assert raw.min() < 0                                              # half-float noise
    env = maps["forest"]
    assert env.min() >= 0 and env.shape == raw.shape
    assert np.array_equal(E.validate_environment(raw[::-1], bottom_row_first=True), env)


# --- irradiance ---------------------------------------------------------------------------------

def test_sh9_is_exact_for_a_band_limited_map():
    env = smooth_map(128, 256)
    d = E.equirect_directions(128, 256)
    env = np.stack([1 + d[..., 2] + 0.5 * d[..., 0] * d[..., 1] + 0.3 * d[..., 1] ** 2] * 3, -1)
    n = random_normals(200)
    truth = T.brute_irradiance(env, n)
    sh = I.sh9_project(env)
    np.testing.assert_allclose(I.sh9_irradiance(sh, n), truth, rtol=2e-4)
    np.testing.assert_allclose(I.evaluate_polynomial(I.irradiance_polynomial(sh), n),
                               I.sh9_irradiance(sh, n), atol=1e-12)


def test_face_weights_exact_and_seed():
    n = random_normals(300, 2)
    W = I.exact_face_weights(n)
    np.testing.assert_allclose(W.sum(1), np.pi, atol=1e-12)
    # against a fine midpoint rule over each face
    size = 192
    d = E.cube_directions(size).reshape(6, -1, 3)
    om = E.cube_solid_angles(size).ravel()
    fine = np.stack([(np.maximum(d[f] @ n[:20].T, 0) * om[:, None]).sum(0) for f in range(6)], 1)
    np.testing.assert_allclose(W[:20], fine, atol=2e-4)
    W4 = I.exact_face_weights(n[:20], 4).reshape(20, 6, 16).sum(-1)
    np.testing.assert_allclose(W4, W[:20], atol=1e-12)
    S = I.seed_face_weights(n).sum(1)
    assert 3.03 < S.min() and S.max() < 3.08             # about 3.05, not pi
    one = I.face_irradiance(E.cube_mips(np.full((6, 8, 8, 3), 2.0)), n)
    np.testing.assert_allclose(one, 2.0 * np.pi, rtol=1e-12)   # uniform map: E = pi L


QUICK_MAP = "city"          # the others are marked slow (about 4 s each)


@needs_hdris
@pytest.mark.parametrize("name", [pytest.param(k, marks=() if k == QUICK_MAP else pytest.mark.slow)
                                  for k in sorted(HDRIS)])
def test_irradiance_on_every_bundled_hdri(maps, name):
    """SH9, SH9 of the residual + the extracted lights (cap formula), and the irradiance map
    against the brute-force sum over every pixel, at 150 random normals.  Measured (seed 0):
    SH9 1.6-22 % mean relative error (sunrise's low sun and black ground the worst), the split
    0.5-4.7 %, the irradiance table (of the residual, 64 x 128 source, + the lights' pixels) under
    1 %: only the irradiance map meets the 1 % target on every map (benchmarks/results/ar.md)."""
    from relight_addon.core.ar.cap import cap_cosine_integral, cone_sin2
    env = maps[name]
    n = random_normals(150)
    truth = T.brute_irradiance(env, n) @ T.LUM
    rel = lambda e: np.mean(np.abs(e @ T.LUM - truth) / truth)   # noqa: E731
    sh = rel(I.sh9_irradiance(I.sh9_project(env), n))
    lights, res = extract_lights(env)
    split = I.sh9_irradiance(I.sh9_project(res), n)
    for lt in lights:
        split = split + lt.radiance * cap_cosine_integral(
            n @ lt.direction, cone_sin2(lt.half_angle))[:, None]
    imap = rel(E.sample_nodes(I.irradiance_map(res, sparse=env - res), n))
    assert imap < 0.01
    assert sh < 0.25 and rel(split) < 0.06
    if name in ("city", "sunrise"):                      # a sun: the split helps
        assert rel(split) < 0.5 * sh


# --- main light ---------------------------------------------------------------------------------

def test_main_light_of_a_synthetic_sun():
    h, w = 256, 512
    d = E.equirect_directions(h, w)
    sun = np.array([0.3, -0.5, 0.6]); sun /= np.linalg.norm(sun)
    half = np.radians(3.0)
    disk = d @ sun > np.cos(half)
    sky = np.array([0.4, 0.5, 0.7])
    env = np.where(disk[..., None], sky + np.array([900.0, 800.0, 700.0]), sky)
    env = env * np.ones((h, w, 3))
    light, res = extract_main_light(env)
    assert np.degrees(np.arccos(light.direction @ sun)) < 0.3
    om = np.broadcast_to(E.equirect_solid_angles(h, w)[:, None], (h, w))
    true_om = om[disk].sum()
    assert light.solid_angle == pytest.approx(true_om, rel=0.15)
    np.testing.assert_allclose(light.irradiance, np.array([900.0, 800, 700]) * true_om, rtol=0.01)
    total = ((env @ T.LUM) * om).sum()
    assert light.share == pytest.approx(np.array([900, 800, 700.0]) @ T.LUM * true_om / total,
                                        rel=0.01)
    np.testing.assert_allclose(res, sky * np.ones((h, w, 3)), atol=1e-9)   # the sky is left
    uniform, same = extract_main_light(np.ones((8, 16, 3)))
    assert uniform.share == 0 and np.array_equal(same, np.ones((8, 16, 3)))


@needs_hdris
def test_lights_and_residual_sum_to_the_map(maps):
    env = maps["studio"]
    lights, res = extract_lights(env)
    assert 1 <= len(lights) <= 4 and lights[0].share > 0.2
    om = E.equirect_solid_angles(*env.shape[:2])[:, None, None]
    power = lambda a: (a * om).sum((0, 1))          # noqa: E731
    np.testing.assert_allclose(power(res) + sum(lt.irradiance for lt in lights), power(env),
                               rtol=1e-9)
    peak = np.unravel_index(np.argmax(env @ T.LUM), env.shape[:2])
    assert lights[0].direction @ E.equirect_directions(*env.shape[:2])[peak] > np.cos(
        lights[0].half_angle + np.radians(1))
