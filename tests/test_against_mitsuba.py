"""The radiosity solver against Mitsuba 3 (an independent path tracer) on the same geometry."""
import numpy as np
import pytest

pytest.importorskip("mitsuba")

from reference.mitsuba_ref import patch_radiosity, relative_stderr  # noqa: E402
from relight_addon.core.radiosity.precompute import solve_radiosity  # noqa: E402
from relight_addon.core.radiosity.presets import PRESETS  # noqa: E402
from scenes.testscenes import ceiling_fixture, cornell_box, parallel_squares  # noqa: E402


def test_form_factor_with_blocker_matches_mitsuba_irradiance_meter():
    """Square blocker halfway between two parallel squares: F with visibility within 1 %."""
    scene = parallel_squares(blocker=True, blocker_size=0.5, receiver_rho=0.5)
    ref, err = patch_radiosity(scene, patches=[1], spp=1 << 20, return_stderr=True)
    ours = solve_radiosity(scene, "high").patch_radiosity()[1]
    print(f"receiver radiosity: ours {ours[0]:.5f}, Mitsuba {ref[0, 0]:.5f} +- {err[0, 0]:.5f}")
    assert relative_stderr(ref, err).max() < 0.003          # the reference is sharp enough
    assert ours[0] == pytest.approx(ref[0, 0], rel=0.01)
    # The blocker really blocks: well below the unoccluded 0.5 * 0.199825.
    assert ours[0] < 0.9 * 0.5 * 0.199825


def test_a_fixtures_reflectors_see_the_tube_between_them_at_medium():
    """RenderPark's classroom's ceiling fixture: each slanted reflector, one leaf at medium,
    faces the other across the tube, which hides a sixth of it.  From the leaf's 2 x 2 fixed
    points no ray met the tube: the reflectors read each other 20 % bright and came out
    +3.0 % against Mitsuba 3 (mean over 16 seeds; the classroom's patches near its lamps
    +1.0-2.1 %).  Medium casts such shadows, which it has no room to refine, from spots spread
    over the leaf (presets.Quality.spread_rays): no bias left over seeds 0-7."""
    scene = ceiling_fixture()
    reflectors = [5, 7]
    lum = np.array([0.2126, 0.7152, 0.0722])
    ref, err = patch_radiosity(scene, patches=reflectors, spp=1 << 21, return_stderr=True)
    ref, err = ref @ lum, err @ lum
    assert (err / ref).max() < 0.004

    def signed(q):
        return np.array([solve_radiosity(scene, q, seed=seed).patch_radiosity()[reflectors] @ lum
                         / ref - 1.0 for seed in range(8)])
    medium = PRESETS["medium"]
    fixed_points = signed(medium.with_(spread_rays=0))
    assert fixed_points.mean() > 0.02                       # the bias this test is about
    spread = signed(medium)
    print(f"reflectors, signed error over seeds 0-7: fixed points {fixed_points.mean():+.4f}, "
          f"spread {spread.mean():+.4f} (worst {np.abs(spread).max():.4f})")
    assert abs(spread.mean()) < 0.01
    assert np.abs(spread).max() < 0.05


@pytest.fixture(scope="module")
def cornell_reference():
    scene = cornell_box()
    ref, err = patch_radiosity(scene, spp=1 << 20, return_stderr=True)   # ~1 % worst-patch noise
    return scene, ref, err


@pytest.mark.slow
def test_cornell_box_patch_radiosity_matches_mitsuba(cornell_reference):
    """High within 1 % on average and 3 % on the worst patch channel, and no bias: before the
    floor under the boxes counted twice (radiosity.exposure) and sources were spread over their
    leaves by area (radiosity.source_split), every patch came out low (mean 1.6-1.8 %, signed
    -1.4 %, worst 4.4-5.2 % over seeds 0-4 against 2^22 spp; now 0.43-0.46 %, 1.1-1.6 %)."""
    scene, ref, err = cornell_reference
    sol = solve_radiosity(scene, "high")
    ours = sol.patch_radiosity()
    lit = scene.emission.max(axis=1) == 0                    # lamps are exact by construction
    signed = (ours[lit] - ref[lit]) / np.maximum(ref[lit], 1e-12)
    rel = np.abs(signed)
    noise = relative_stderr(ref[lit], err[lit])
    print(f"Cornell box (high): mean rel err {rel.mean():.4f}, max {rel.max():.4f}, signed "
          f"{signed.mean():+.4f}, reference noise mean {noise.mean():.4f}")
    assert noise.mean() < 0.01
    assert rel.mean() <= 0.01 and rel.max() <= 0.03
    assert abs(signed.mean()) <= 0.005
    assert np.all(np.isfinite(ours))


@pytest.mark.slow
def test_cornell_box_medium_is_stable_over_seeds(cornell_reference):
    """The medium preset gives the same quality whatever the random seed (issue 10): before the
    oracle re-tested large links its few rays called unoccluded, a block face came out 14 % dark
    on two seeds of five (worst quad 15.5 % vs 5.5 % on the others).  Bounds: the preset's
    spread measured at 2^22 spp (mean 0.62-1.06 %, worst channel 1.6-3.1 % over seeds 0-4;
    1.7-2.2 % and 4.7-6.0 % before exposure.py and source_split.py) plus the reference's own
    noise (~1 % worst patch at 2^20 spp)."""
    scene, ref, err = cornell_reference
    lit = scene.emission.max(axis=1) == 0
    worst = []
    for seed in range(5):
        ours = solve_radiosity(scene, "medium", seed=seed).patch_radiosity()
        rel = np.abs(ours[lit] - ref[lit]) / np.maximum(ref[lit], 1e-12)
        print(f"seed {seed}: mean {rel.mean():.4f}, max {rel.max():.4f}")
        assert rel.mean() <= 0.015, seed
        worst.append(rel.max())
    assert max(worst) <= 0.045, worst


def test_cornell_box_draft_meets_its_bounds_on_every_seed(cornell_reference):
    """Draft within issue 47's bounds for a fast preset (RenderPark's default: 1.61 % mean,
    7.22 % worst quad) on every seed.  Before its links took 8 rays a point where their first
    rays were partly blocked (presets.Quality.partial_point_rays), a link of a large element
    gave each of its leaves one ray: a floor leaf in the tall box's shadow read 2.3x its light
    on one seed and the box's side facing it 13.5 % bright (with contact lines; without them
    the short box's side facing the wall was 4-6 % bright on every seed, max 5.5-7.8 %).
    Measured at 2^22 spp: mean 0.74-0.98 %, worst channel 3.9-5.1 % over seeds 0-4; bounds
    allow the 2^20 reference's noise (about 1 % on its noisiest patch)."""
    scene, ref, err = cornell_reference
    lit = scene.emission.max(axis=1) == 0
    for seed in range(5):
        ours = solve_radiosity(scene, "draft", seed=seed).patch_radiosity()
        rel = np.abs(ours[lit] - ref[lit]) / np.maximum(ref[lit], 1e-12)
        print(f"draft seed {seed}: mean {rel.mean():.4f}, max {rel.max():.4f}")
        assert np.all(np.isfinite(ours))
        assert rel.mean() <= 0.016, seed
        assert rel.max() <= 0.07, seed
