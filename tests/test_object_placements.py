"""Exact virtual objects' shadows against Cycles truth at one placement of each kind (issue 42
item 6): a grey sphere (radius 0.25 m, albedo 0.5) on the floor in the open, under a lamp,
partly under a table, on a box and against a wall, in the family's test rooms 20 and 21
(scenes/object_placements.py: 32 texels per wall; the photo and each truth a 512-sample Cycles
DIFFUSE bake, seeds 0 and 1, the truth with the sphere really there; cached by scenes/bake.py
and shipped in tests/data/cache/bakes).  The room is read as photographed and precomputed at
medium; each placement is inserted by ``add_objects`` (what Update runs) and scored in the
sphere's shadow (texels the truth shows darker than the photo by 20 %, not hidden under it):
mean CIEDE2000 <= 3.0, and at least 3x below the room's maps that ignore the sphere.

Before the objects' change near them was gathered twice (the second gather seeing the first's
whole change: the sphere's underside sees the floor it darkens, direct and indirect), a sphere
on the open floor of held-out room 14 read 3.13 (the four texels at its contact 2.3x too
bright); the benchmark (benchmarks/bench_object_placements.py) measures all the rooms.
"""
import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from scenes import object_placements as op  # noqa: E402

# (room, placement label): one of each kind the issue names, and a lamp above
CASES = [
    ("room 20", "sphere, open floor"),
    ("room 20", "sphere under the ceiling lamp"),
    ("room 20", "sphere partly under the table"),
    ("room 21", "sphere on the box"),
    ("room 21", "sphere against the east wall"),
    ("room 21", "sphere under the pendant point"),
]


def _index(room, label):
    return next(i for i, p in enumerate(op.PLACEMENTS[room]) if p[0] == label)


@pytest.fixture(scope="module")
def scored():
    from relight_addon.core.relight.shadowfree import ShadowFreeOptions, shadow_free
    out = {}
    for room in sorted({r for r, _ in CASES}):
        which = [_index(room, label) for r, label in CASES if r == room]
        shot = op.photographed(room, which, log=lambda msg: None)
        res = shadow_free(shot["room"], ShadowFreeOptions(preset="medium"))
        x = op.texel_positions(res)
        for read in shot["reads"]:
            label = op.PLACEMENTS[room][read["index"]][0]
            out[room, label] = op.score(res, shot, read, x)
    return out


@pytest.mark.slow
@pytest.mark.parametrize("room,label", CASES)
def test_an_exact_sphere_shadow_against_the_truth(scored, room, label):
    row = scored[room, label]
    print(room, label, {k: round(v, 3) if isinstance(v, float) else v for k, v in row.items()})
    assert row["shadow_texels"] >= op.MIN_SHADOW, row
    assert row["exact_shadow"] <= op.TARGET, row
    assert row["ignored_shadow"] >= op.BETTER * row["exact_shadow"], row
    # the room away from the sphere keeps its relit colour
    assert row["exact_all"] <= row["ignored_all"] + 0.05, row


@pytest.mark.slow
def test_the_placements_cover_what_the_issue_asks(scored):
    kinds = {next(p[1] for p in op.PLACEMENTS[r] if p[0] == label) for r, label in CASES}
    assert kinds == {"floor in the open", "near a lamp", "partly under a table", "on a table",
                     "against a wall"}
    assert all(np.isfinite(v) for row in scored.values() for v in row.values()
               if isinstance(v, float))
