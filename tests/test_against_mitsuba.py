"""The radiosity solver against Mitsuba 3 (an independent path tracer) on the same geometry."""
import numpy as np
import pytest

pytest.importorskip("mitsuba")

from reference.mitsuba_ref import patch_radiosity, relative_stderr  # noqa: E402
from relight_addon.core.radiosity.precompute import solve_radiosity  # noqa: E402
from scenes.testscenes import cornell_box, parallel_squares  # noqa: E402


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


@pytest.fixture(scope="module")
def cornell_reference():
    scene = cornell_box()
    ref, err = patch_radiosity(scene, spp=1 << 20, return_stderr=True)   # ~1 % worst-patch noise
    return scene, ref, err


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
