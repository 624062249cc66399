"""Closed furnaces holding clutter (issue 10: small boxes, thin panels, 1 mm gaps, a box
standing on the floor): every face emits 1 and reflects rho, so the exact radiosity is
E / (1 - rho) everywhere.  Apart from test_radiosity.py because these are the suite's longest
solves (many presets, rho and seeds), so that the two test workers can share them out."""
import numpy as np
import pytest

# left out of `make test-quick`: furnaces with clutter at every preset, several seeds (minutes)
pytestmark = pytest.mark.slow

from relight_addon.core.radiosity.precompute import solve_radiosity
from relight_addon.core.radiosity.presets import PRESETS
from scenes.testscenes import clutter_furnace, hover_furnace


@pytest.mark.parametrize("preset,rho", [("draft", 0.5), ("draft", 0.99), ("medium", 0.9),
                                        ("high", 0.9)])
def test_clutter_furnace_is_exact_at_every_preset(preset, rho):
    """Faces across a 1 mm gap see their neighbour and a sliver of the room: estimated from a
    few rays per point, the slivers added up to rows of 1.4-2.0 and radiosities of up to 3.5x
    the exact value (medium, rho 0.9).  Rows of closed views are 1 by construction now
    (core/radiosity/conserve.py): every leaf within 1 % (measured ~1e-14, 1e-3 at 0.99)."""
    sol = solve_radiosity(clutter_furnace(rho), preset)
    B = sol.radiosity()[:, 0]
    rows = sol.system.gather(np.ones((sol.system.n_leaves, 1)))[:, 0]
    rel = np.abs(B * (1 - rho) - 1.0)
    print(f"{preset} rho {rho}: leaves {len(B)}, rows {rows.min():.6f}-{rows.max():.6f}, "
          f"max rel err {rel.max():.2e}")
    assert rows.max() <= 1.0 + 1e-9
    assert rel.max() < 0.01


FOUR_SEEDS = ((0, 1, 2, 3),) * 3


@pytest.mark.parametrize("preset,contact_levels,others,straddling,seeds_by_rho",
                         [("medium", 0, 0.025, 0.09, FOUR_SEEDS),
                          ("medium", 2, 0.01, 0.04, FOUR_SEEDS),
                          ("draft", 0, 0.01, 0.04, FOUR_SEEDS),
                          ("high", 0, 0.012, 0.025, ((0,), (1,), (0,)))])
def test_a_box_standing_on_the_floor_keeps_the_furnace_exact(preset, contact_levels, others,
                                                             straddling, seeds_by_rho):
    """The clutter furnace with a 10 cm box standing on the floor.  The floor leaves
    it straddles average their lit part with the part under it (no light reaches that): their
    mean radiosity is lower, and as sources the gather counted that darkness a second time
    (rays to the part under the box are blocked).  Leaves were then off by up to 3 % at rho 0.5
    and 10 % at 0.9.  Now (radiosity.exposure) every other leaf is exact to about 2 % and a
    straddling leaf's exposed part to 8 %: (B - (1 - a) E) / a = E / (1 - rho), a the leaf's
    exposed fraction; leaves that nothing reaches (under the box whole) keep B = E.  With the
    box's outline split (radiosity.contacts, 2 levels: medium's preset) the issue's 1 % holds:
    over seeds 0-3 at rho 0.5 / 0.9 / 0.99 others 0.32 / 0.29 / 0.76 %, straddling at most
    0.5 % (without: 0.28 / 1.33 / 1.14 % and 3.2 / 7.5 / 5.3 %; before the exposure change
    0.3 / 1.3 / 1.5 %).  Draft missed it (7.8 / 26 / 40 %) while its leaves, decided by one
    point each, all counted as exposed; decided by their centre: others at most 0.36 %, one
    straddling leaf 1.7 % (radiosity.exposure).  Without the split the worst of seeds 0-7 at
    rho 0.99 is 0.24-2.01 % (straddling 1.4-7.6 %): the bounds leave room for that spread.
    High (its rays leave from spots over each point's cell, but on the leaves a contact line
    crosses from the points, where their exposure is judged; 64 rays on a partly blocked
    link): others at most 0.87 %, straddling 1.14 % over seeds 0-3 (0.91 and 2.1 % with 32
    rays on every link; 4.6 % at rho 0.5 with every leaf's rays spread).  With its unresolved
    shadows cast from 1024 spread rays, seeds 0-1 at rho 0.5 / 0.9 / 0.99: others 0.45 / 0.82 /
    0.89 %, straddling 0.56 / 0 / 0 %.  Those 6 solves took 194 s of the suite (its longest
    test), so high runs one seed a rho, in turn."""
    quality = PRESETS[preset].with_(contact_levels=contact_levels)
    for rho, seeds in zip((0.5, 0.9, 0.99), seeds_by_rho):
        worst = [0.0, 0.0]
        for seed in seeds:
            sol = solve_radiosity(clutter_furnace(rho, touching=True), quality, seed=seed)
            S = sol.system
            B = sol.radiosity()[:, 0]
            a = S.exposure
            rows = np.asarray(S.M.sum(axis=1)).ravel()
            reached = rows > 0.01
            # straddling: part of it buried (by its quadrature points, or by the hemisphere its
            # centre sees)
            part = reached & (a > 0) & ((a < 1) | (rows < 0.99))
            whole = reached & (a == 1) & ~part
            rel = np.abs((B - (1.0 - a)) / np.where(a > 0, a, 1.0) * (1 - rho) - 1.0)
            worst[0] = max(worst[0], rel[whole].max())
            worst[1] = max(worst[1], rel[part].max(initial=0.0))
            assert np.allclose(B[~reached], 1.0)
        print(f"{preset}, contact levels {contact_levels}, rho {rho}: others max rel err {worst[0]:.2e}, "
              f"straddling {worst[1]:.2e}")
        assert worst[0] < others
        assert worst[1] < straddling


@pytest.mark.parametrize("preset", ["medium", "high"])
def test_medium_and_high_keep_a_furnace_with_hovering_clutter_exact(preset):
    """hover_furnace (boxes 1 mm above the floor and apart, thin panels, a box 1 mm off a wall;
    test_contacts.py has draft's, which needs the gap lines): medium and high, with elements
    small enough without them, are within 1 % on every face (measured 0.008 % at most) and
    every leaf (0.89 % at most, medium at rho 0.9 seed 0)."""
    rho = 0.9
    sol = solve_radiosity(hover_furnace(rho), PRESETS[preset], seed=0)
    faces = np.abs(sol.patch_radiosity()[:, 0] * (1 - rho) - 1.0)
    leaves = np.abs(sol.radiosity()[:, 0] * (1 - rho) - 1.0)
    print(f"{preset} rho {rho}: worst face {faces.max():.2e}, leaf {leaves.max():.2e}")
    assert faces.max() < 0.01 and leaves.max() < 0.01
