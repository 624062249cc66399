"""Relighting holds on rooms the pipeline was not tuned on (issue 9): the small test rooms of the
family (scenes/family.py, 32 texels per surface, Cycles bakes in tests/data/family/), read as a
user hands them to the add-on and scored against their Cycles truth (scenes/family_eval.py).

Room 20: unequal lamps (3:1), a wall disk 0.3 m from the east wall, a table.  Room 21: a pendant
point lamp and a spot on the west wall.  Room 22: a warm square and a cool emissive panel (1:2).
Bounds are the benchmark's targets (benchmarks/results/family.md), looser where the issue says
so: the original lighting within the noise floor + 0.3; lamp off <= 2.0 CIEDE2000 on the mean
over the rooms, overall and in the switched-off lamp's former shadow, <= 3.0 on every target,
in the former shadow at most half the global exposure scale's error; exitance ratios within
5 % with exact powers.
"""
import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

# left out of `make test-quick`: the room family's solves against Cycles truth (minutes)
pytestmark = pytest.mark.slow

from relight_addon.core.relight.shadowfree import ShadowFreeOptions, shadow_free  # noqa: E402
from scenes import family as fam  # noqa: E402
from scenes import family_eval as fe  # noqa: E402
from scenes.addon import register_repo_addon  # noqa: E402


@pytest.fixture(scope="module")
def scored():
    register_repo_addon()
    out = {}
    for index in fam.TEST_ROOMS:
        room = fe.photographed_room(index, "exact")
        res = shadow_free(room.data, ShadowFreeOptions(preset="medium"))
        out[index] = (room, res, fe.score(room, res))
    return out


def _off_targets(sc):
    return {k: v for k, v in sc["targets"].items() if k.endswith(" off") or k.startswith("only")}


def test_the_test_rooms_cover_what_the_issue_asks():
    types = {lp.type for i in fam.TEST_ROOMS for lp in fam.room_spec(i).lamps}
    assert {"POINT", "SPOT"} <= types
    powers = [sorted(lp.power for lp in fam.room_spec(20).lamps)]
    assert powers[0][1] / powers[0][0] >= 2.5                          # unequal lamps
    assert any(abs(lp.wall_distance - 0.3) < 0.05 for lp in fam.room_spec(20).lamps)


def test_lamp_off_against_the_truth(scored):
    means, shadows = [], []
    for index, (room, res, sc) in scored.items():
        for label, row in _off_targets(sc).items():
            relit, scale = row["relit"], row["scale"]
            assert relit["all"][0] <= 3.0, (index, label, row)
            means.append(relit["all"][0])
            if relit["shadow_texels"] >= 20:
                assert relit["shadow"][0] <= 3.0, (index, label, row)
                assert relit["shadow"][0] <= 0.5 * scale["shadow"][0], (index, label, row)
                shadows.append(relit["shadow"][0])
    assert np.mean(means) <= 2.0, means
    assert shadows and np.mean(shadows) <= 2.0, shadows


def test_doubled_lamps_against_the_truth(scored):
    for index, (room, res, sc) in scored.items():
        for label, row in sc["targets"].items():
            if label.endswith("x2"):
                assert row["relit"]["all"][0] <= 2.0, (index, label, row)


def test_original_lighting_within_the_noise_floor(scored):
    """At the photo's own lighting the relit textures against the truth stay within the noise
    floor (photo vs truth: two independent bakes) + 0.3 CIEDE2000, the issue's target."""
    for index, (room, res, sc) in scored.items():
        orig = sc["targets"]["original"]["relit"]["all"][0]
        assert orig <= sc["floor"][0] + 0.3, (index, orig, sc["floor"])


def test_exitance_ratios_with_exact_powers(scored):
    for index, (room, res, sc) in scored.items():
        assert sc["ratio_error"] <= 0.05, (index, sc["ratio_error"], res.lamps)


def test_estimated_reflectances_match_the_true_albedo(scored):
    """The reflectance the precompute finds for each wall, the floor and the ceiling, against
    the albedo the room was built with: within 20 % per channel (the shadow-depth fit of rho^
    included; measured: 16 % at worst, room 22's near-white walls at 0.66 for 0.78).  Furniture
    is left out: its small, partly hidden faces come out up to 45 % dark (room 22's shelf), an
    error the relit texture does not show (it follows the photo)."""
    for index, (room, res, sc) in scored.items():
        sol = res.solution
        patch = sol.system.patch
        for s in room.spec.surfaces:
            if not (s.name in ("Floor", "Ceiling") or s.name.startswith("Wall")):
                continue
            groups = [g for g, (label, _) in enumerate(room.report.groups) if label == s.name]
            sel = np.isin(np.asarray(sol.scene.group)[patch], groups) & res.photographed[patch]
            a = sol.system.leaf_area[sel]
            est = (sol.system.rho[sel] * a[:, None]).sum(0) / a.sum()
            true = s.albedo[fam.coverage(s)].mean(axis=0)
            np.testing.assert_allclose(est, true, rtol=0.2, err_msg=f"room {index} {s.name}")


def test_a_weak_lamp_among_four_keeps_the_users_power():
    """Family room 5 (7 x 6 m, four tinted lamps 1:4, a cabinet against a wall; never tuned on),
    read with the lamps' exact powers, at medium: the mean reflectance rho^ within 15 % of the
    room's true area-mean albedo, and every lamp ratio within 5 %.  Before the surfaces' vote
    on the shadow depth, the contact shadows around the cabinet pulled rho^ to 0.29 (true
    0.47), and the shadow-edge fit then replaced the weakest lamp's power (5 % of the light)
    by 1.43 times it."""
    from relight_addon.core.scene import quad_area_normal
    from relight_addon.core.texture.colour import luminance
    register_repo_addon()
    room = fe.photographed_room(5, "exact")
    res = shadow_free(room.data, ShadowFreeOptions(preset="medium"))
    area = albedo = 0.0
    for s in room.spec.surfaces:
        a = float(quad_area_normal(s.quads)[0].sum())
        area += a
        albedo += a * float(luminance(s.albedo[fam.coverage(s)]).mean())
    assert res.lamps.rho_mean == pytest.approx(albedo / area, rel=0.15)
    assert fe.ratio_error(room, res) <= 0.05, res.lamps


def test_a_power_the_photo_corrects_is_taken_against_the_lamps_it_leaves():
    """Family room 1 (three cool disks 1:3) with every power 30 % off (alternately high and
    low): the photo pins two lamps and not the weakest (its share of the light is small), so
    the two are corrected against the one that keeps the user's power.  Their photo ratios
    have their geometric mean 1 over all three lamps; applied as they are, they left the ratio
    error at 0.23 (measured), against 0.08 now."""
    register_repo_addon()
    room = fe.photographed_room(1, "off30")
    res = shadow_free(room.data, ShadowFreeOptions(preset="medium"))
    assert 0 < res.lamps.applied.sum() < 3, res.lamps          # the partial case
    assert fe.ratio_error(room, res) <= 0.12, res.lamps
