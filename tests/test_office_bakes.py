"""The office scene generator and its Cycles DIFFUSE bakes (the shadow-free evaluation harness).

Cycles is the independent renderer here: its bakes are the "photographs" (albedo x light with
real shadows and interreflections).  These tests check the harness itself: units against the
exact point-to-polygon form factor, shadows, linearity in the lamp powers, the Monte Carlo noise
floor and the on-disk cache.  Bakes are cached under <repo>/.cache/bakes (or
$RELIGHT_BAKE_CACHE), so only the first run pays for them (~40 s on 2 shared cores).
"""
import time

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from relight_addon.core.geometry.formfactor import point_to_polygon  # noqa: E402
from scenes import bake  # noqa: E402
from scenes.office import (ROOM, TABLE_CENTRE_XY, _diffuse_material,  # noqa: E402
                                              _new_image, build_office, office_geometry)

SIZE = 48
SAMPLES = 64


@pytest.fixture
def office():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    info = build_office(seed=0, n_lamps=2, texture_size=SIZE, variant="small")
    yield info
    bpy.ops.wm.read_factory_settings(use_empty=True)


def covered(info):
    return bake.coverage_masks(info.objects, SIZE)


def powers(info, **overrides):
    p = dict(info.lamp_powers)
    p.update({f"Lamp {k}": v for k, v in overrides.items()})
    return p


def rel_mad(a, b, masks):
    """Mean |a - b| / mean |a| over covered texels of every object."""
    x = np.concatenate([a[n][masks[n]].ravel() for n in sorted(a)])
    y = np.concatenate([b[n][masks[n]].ravel() for n in sorted(a)])
    return float(np.abs(x - y).mean() / np.abs(x).mean())


def test_geometry_is_plain_numpy():
    d = office_geometry(seed=3, n_lamps=4, texture_size=32, variant="boxes3")
    assert len(d.lamps) == 4 and [lp.name for lp in d.lamps][:2] == ["Lamp A", "Lamp B"]
    centre = np.array(ROOM) / 2
    for s in d.surfaces:
        assert s.albedo.shape == (32, 32, 3) and s.albedo.dtype == np.float32
        assert 0.2 <= s.albedo.min() and s.albedo.max() <= 0.8
        assert s.uvs.min() >= 0 and s.uvs.max() <= 1
        if s.name in ("Floor", "Ceiling") or s.name.startswith("Wall"):
            q = s.quads[0]
            n = np.cross(q[1] - q[0], q[3] - q[0])
            assert n @ (centre - q.mean(0)) > 0, s.name  # room faces point inward
    # the poster: a block of another colour on the north wall
    north = d.surface("Wall North").albedo
    assert np.unique(north.reshape(-1, 3), axis=0).shape[0] >= 3


def test_bake_unit_factor():
    """A white plane 1 m under a 100 W, 1 m square light: bake = albedo x E / pi (radiance)."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    n = 16
    me = bpy.data.meshes.new("Plane")
    me.from_pydata([(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)], [], [(0, 1, 2, 3)])
    uv = me.uv_layers.new(name="UVMap")
    uv.data.foreach_set("uv", np.array([0, 0, 1, 0, 1, 1, 0, 1], np.float32))
    me.update()
    obj = bpy.data.objects.new("Plane", me)
    bpy.context.scene.collection.objects.link(obj)
    me.materials.append(_diffuse_material(bpy, "White", _new_image(bpy, "white", np.ones((n, n, 3),
                                                                                        np.float32))))
    light = bpy.data.lights.new("Lamp", "AREA")
    light.shape, light.size, light.energy = "SQUARE", 1.0, 100.0
    lo = bpy.data.objects.new("Lamp", light)
    lo.location = (0, 0, 1)
    bpy.context.scene.collection.objects.link(lo)
    out = bake.bake_lighting({"Lamp": 100.0}, samples=256, seed=0, bounces=4)["Plane"]
    c = (np.arange(n) + 0.5) / n * 2 - 1
    yy, xx = np.meshgrid(c, c, indexing="ij")           # row = v (y), column = u (x)
    pts = np.stack([xx, yy, np.zeros_like(xx)], -1).reshape(-1, 3)
    sq = np.array([[-.5, -.5, 1], [-.5, .5, 1], [.5, .5, 1], [.5, -.5, 1]], float)
    ff = point_to_polygon(pts, np.tile([0, 0, 1.0], (len(pts), 1)), np.tile(sq, (len(pts), 1, 1)),
                          np.tile([0, 0, -1.0], (len(pts), 1)))
    E = (ff * 100.0).reshape(n, n)                       # irradiance, exitance 100 W/m^2
    ratio = out[..., 1].sum() / E.sum()
    print(f"\nbake / irradiance = {ratio:.4f} (1/pi = {1 / np.pi:.4f}); "
          f"x BAKE_TO_RADIOSITY = {ratio * bake.BAKE_TO_RADIOSITY:.4f}")
    assert abs(ratio * bake.BAKE_TO_RADIOSITY - 1.0) < 0.02
    # and texel by texel (Monte Carlo noise of 256 samples)
    np.testing.assert_allclose(out[..., 1] * np.pi, E, rtol=0.08, atol=0.5)


def test_office_bakes(office):
    info = office
    masks = covered(info)
    t0 = time.perf_counter()
    orig = bake.bake_lighting(powers(info), samples=SAMPLES, seed=0)
    t_first = time.perf_counter() - t0
    assert set(orig) == set(info.objects)
    for name, img in orig.items():
        assert img.shape == (SIZE, SIZE, 3) and img.dtype == np.float32
        assert np.isfinite(img).all() and img.min() >= 0.0, name

    # Brightness: the floor lands in a photo-like range.
    floor = orig["Floor"][masks["Floor"]]
    print(f"\nfloor bake: mean {floor.mean():.3f}, p5 {np.percentile(floor, 5):.3f}, "
          f"p95 {np.percentile(floor, 95):.3f}; first call {t_first:.2f} s")
    assert 0.1 < floor.mean() < 0.8

    # A real shadow: irradiance (bake / albedo) under the table vs the open floor.
    irr = orig["Floor"] / office_geometry(0, 2, SIZE).surface("Floor").albedo
    W, D, _ = ROOM
    col, row = int(TABLE_CENTRE_XY[0] / W * SIZE), int(TABLE_CENTRE_XY[1] / D * SIZE)
    under = irr[row - 2:row + 3, col - 2:col + 3].mean()
    open_floor = np.median(irr[masks["Floor"]])
    print(f"floor irradiance-like: under the table {under:.3f}, median {open_floor:.3f}")
    assert under < 0.5 * open_floor


def test_linearity_and_noise_floor(office):
    info = office
    masks = covered(info)
    names = info.lamps
    assert names == ["Lamp A", "Lamp B"]
    p = info.lamp_powers["Lamp A"]
    t0 = time.perf_counter()
    all_on = bake.bake_lighting(powers(info), samples=SAMPLES, seed=0)
    all_on_2 = bake.bake_lighting(powers(info), samples=SAMPLES, seed=1)
    only_a = bake.bake_lighting(powers(info, B=0.0), samples=SAMPLES, seed=2)
    only_b = bake.bake_lighting(powers(info, A=0.0), samples=SAMPLES, seed=3)
    only_a2 = bake.bake_lighting(powers(info, A=2 * p, B=0.0), samples=SAMPLES, seed=2)
    print(f"\n5 bakes in {time.perf_counter() - t0:.1f} s; per-bake Cycles seconds this session: "
          f"{[round(s, 2) for s in bake.CACHE_STATS['bake_seconds']]}")

    # Noise floor at SAMPLES: two seeds of the same lighting.
    noise = rel_mad(all_on, all_on_2, masks)
    summed = {n: only_a[n] + only_b[n] for n in all_on}
    lin = rel_mad(all_on, summed, masks)
    de_noise = bake.delta_e_2000_texels(all_on, all_on_2, masks)
    de_lin = bake.delta_e_2000_texels(all_on, summed, masks)
    print(f"relative MAD: seeds {noise:.4f}, all-on vs A + B {lin:.4f}; dE2000 mean: seeds "
          f"{de_noise.mean():.3f} (p95 {np.percentile(de_noise, 95):.3f}), all-on vs A + B "
          f"{de_lin.mean():.3f} (p95 {np.percentile(de_lin, 95):.3f})")
    # A + B carries the noise of two bakes: allow sqrt(2) x the floor plus a margin.
    assert lin < 1.6 * noise
    assert de_lin.mean() < 1.6 * de_noise.mean()
    tot_all = sum(float(all_on[n][masks[n]].sum()) for n in all_on)
    tot_sum = sum(float(summed[n][masks[n]].sum()) for n in all_on)
    assert abs(tot_sum / tot_all - 1) < 0.01

    # Doubling lamp A doubles its bake (same seed: same paths).
    x = np.concatenate([only_a[n][masks[n]].ravel() for n in sorted(only_a)])
    y = np.concatenate([only_a2[n][masks[n]].ravel() for n in sorted(only_a)])
    ratio = y.sum() / x.sum()
    print(f"doubling: sum ratio {ratio:.5f}, max texel |y - 2x| {np.abs(y - 2 * x).max():.2e}")
    assert abs(ratio - 2.0) < 2e-3
    assert rel_mad({"a": 2 * x[None]}, {"a": y[None]}, {"a": np.ones(1, bool)}) < 0.25 * noise + 1e-4

    # Noise floor against samples.
    nf = bake.noise_floor(powers(info), samples_list=(16, SAMPLES), seeds=(0, 1))
    for s, v in nf.items():
        print(f"noise floor {s:4d} samples: dE2000 mean {v['mean']:.3f}, p95 {v['p95']:.3f}, "
              f"max {v['max']:.2f}")
    assert nf[SAMPLES]["mean"] < nf[16]["mean"]
    assert 0.3 < nf[SAMPLES]["mean"] / nf[16]["mean"] < 0.8   # ~ 1/sqrt(4)


def test_cache_hits(office):
    info = office
    bake.bake_lighting(powers(info), samples=SAMPLES, seed=0)    # fills the cache if needed
    hits = bake.CACHE_STATS["hits"]
    # Rebuild the scene from scratch: same data, same key.
    bpy.ops.wm.read_factory_settings(use_empty=True)
    info = build_office(seed=0, n_lamps=2, texture_size=SIZE, variant="small")
    t0 = time.perf_counter()
    again = bake.bake_lighting(powers(info), samples=SAMPLES, seed=0)
    dt = time.perf_counter() - t0
    assert bake.CACHE_STATS["hits"] == hits + 1
    assert dt < 1.0
    assert set(again) == set(info.objects)
    # a different lighting is a different key
    misses = bake.CACHE_STATS["misses"]
    key1 = bake._cache_key(bpy.context.scene, bake.surface_objects(), powers(info), SAMPLES, 0, 16,
                           3, SIZE)
    key2 = bake._cache_key(bpy.context.scene, bake.surface_objects(), powers(info, A=1.0), SAMPLES,
                           0, 16, 3, SIZE)
    assert key1 != key2 and bake.CACHE_STATS["misses"] == misses


def test_reader_sees_true_albedo(office):
    """The bridge reads the office's albedo images exactly (float, linear, packed) and its lamps."""
    from relight_addon.blender.read import read_scene
    info = office
    sd, rep = read_scene(bpy.context)
    assert rep.ok and not rep.warnings
    assert sd.lamp_names == info.lamps
    data = info.data
    seen = {im.name: im for im in sd.images}
    for obj, img_name in info.albedo_images.items():
        assert bpy.data.images[img_name].packed_file is not None
        np.testing.assert_allclose(seen[img_name].texels, data.surface(obj).albedo, atol=1e-6)
    lamp = sd.lamp >= 0
    np.testing.assert_allclose(sd.emission[lamp], 40.0 / (1.2 * 0.6), rtol=1e-5)
