"""The Cycles bakes and Mitsuba 3 references shipped in tests/data/cache (see conftest.py)
against fresh renders: a cheap subset is rendered again here, uncached and with other seeds,
and must agree with the shipped entries within its noise.  With the bpy and Mitsuba versions
they were made with (tests/data/cache/versions.json), the entries the tests read must be the
shipped ones: a scene changed without `make test-cache` would make CI render them silently."""
import json
import os
import shutil

import numpy as np
import pytest

from conftest import SHIPPED_CACHE

VERSIONS = json.loads(open(os.path.join(SHIPPED_CACHE, "versions.json")).read())


@pytest.mark.slow
def test_mitsuba_cornell_box_renders_as_shipped():
    pytest.importorskip("mitsuba")
    from reference.mitsuba_ref import DEFAULT_REPEATS, _cache_dir, mitsuba_version, patch_radiosity
    from scenes.testscenes import cornell_box
    scene = cornell_box()
    # the reference test_against_mitsuba.py reads (1 M samples a patch) ...
    shipped, shipped_err = patch_radiosity(scene, spp=1 << 20, return_stderr=True)
    # ... and a quarter of it rendered here, another seed, nothing read from or written to a cache
    fresh, fresh_err = patch_radiosity(scene, spp=1 << 18, seed=7, return_stderr=True,
                                       cache=False)
    lit = scene.emission.max(axis=1) == 0
    z = np.abs(fresh - shipped)[lit] / np.hypot(fresh_err, shipped_err)[lit]
    rel = np.abs(fresh / shipped - 1.0)[lit]
    print(f"z max {z.max():.2f}, mean {z.mean():.2f}; relative difference max {rel.max():.4f}")
    assert z.max() < 5.0 and z.mean() < 2.0
    assert rel.max() < 0.04
    if mitsuba_version() == VERSIONS["mitsuba"]:
        name = _cache_dir(scene, 1 << 20, -1, 0, DEFAULT_REPEATS).name
        shipped_dir = os.path.join(SHIPPED_CACHE, "mitsuba", name)
        assert all(os.path.exists(os.path.join(shipped_dir, f"p{p}.npy"))
                   for p in range(scene.n_patches)), "stale shipped references: make test-cache"


def test_cycles_office_bake_renders_as_shipped(tmp_path):
    bpy = pytest.importorskip("bpy")
    from scenes import bake
    from scenes.office import build_office
    bpy.ops.wm.read_factory_settings(use_empty=True)
    info = build_office(seed=0, n_lamps=2, texture_size=24)        # test_shadowfree.py's office
    only_a = {k: (v if k == "Lamp A" else 0.0) for k, v in dict(info.lamp_powers).items()}
    # read from a copy of the shipped folder alone: a hit there is a shipped entry
    shutil.copytree(os.path.join(SHIPPED_CACHE, "bakes"), tmp_path / "bakes")
    hits = bake.CACHE_STATS["hits"]
    shipped = bake.bake_lighting(only_a, samples=512, seed=0, texture_size=24,
                                 cache_dir=str(tmp_path / "bakes"))
    hit = bake.CACHE_STATS["hits"] == hits + 1
    fresh = bake.bake_lighting(only_a, samples=64, seed=7, texture_size=24, use_cache=False)
    lum = np.array([0.2126, 0.7152, 0.0722])
    means = np.array([[image.reshape(-1, 3).mean(0) @ lum for image in (shipped[n], fresh[n])]
                      for n in shipped])
    lit = means[:, 0] > 0.05 * means[:, 0].max()
    rel = np.abs(means[lit, 1] / means[lit, 0] - 1.0)
    print(f"{lit.sum()} lit surfaces, surface means differ by at most {rel.max():.4f}")
    assert lit.sum() >= 4 and rel.max() < 0.03
    if bpy.app.version_string.split()[0] in VERSIONS["bpy"]:      # the lines' bpy versions
        assert hit, "stale shipped bakes: make test-cache"
