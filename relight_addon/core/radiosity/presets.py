"""Quality presets: each is one point on the speed/accuracy curve (benchmarks/bench_cornell.py).

Thresholds are relative so that a preset means the same thing at any scene scale and lamp power:
``eps_bf`` and ``eps_bfv`` are fractions of the brightest source radiosity, ``min_area`` is a
fraction of the total surface area.
"""
from __future__ import annotations

from dataclasses import dataclass, replace


@dataclass(frozen=True)
class Quality:
    name: str
    eps_bf: float          # BF oracle: refine a link while B_s * F > eps_bf * B_max
    eps_bfv: float         # BFV oracle: the same for partially visible links (shadow boundaries)
    min_area: float        # smallest element, as a fraction of the total area
    quadrature: int        # m x m Gauss points per leaf for the final form factors
    rays: int              # visibility rays per final link (at least one per sample point)
    # visibility rays per candidate link during refinement.  Medium: 8 (was 4) made family
    # room 6's former shadows stable over seeds (0.44-0.48 CIEDE2000; 0.47-0.62 with 4: a
    # spot's bright pool on a wall lit the floor in blotches on seed 0)
    oracle_rays: int
    confirm_rays: int = 0  # x oracle_rays: re-test of bright links the oracle's rays all agreed on
    passes: int = 3        # refine / solve passes (the BF oracle needs a radiosity estimate)
    separation: float = 0.4  # cluster link when (radius sum) < separation * (centre distance)
    cluster_above: int = 400  # input patch count above which patches are clustered
    # gather entries of near sources split over the source's children by form factor this
    # many levels down (radiosity.source_split), while source radius > split_near x distance.
    # Cornell box, seeds 0-4 (benchmarks/results/cornell.md): medium 3 levels at 0.15 mean
    # 0.6-1.1 % (none: 1.2-1.5 %) for +0.7 s; high needs 32 rays a link to gain as much (one
    # block face sees a wall mostly hidden behind the other block).  Draft: 3 at 0.15 with
    # eps_bf 0.01, eps_bfv 0.005 and 8 rays (was none at 0.02 / 0.01 / 4 rays: mean 4.2-6.6 %,
    # max 23-35 %), with ff_quadrature 3 and rows closed at the leaves' centres
    # (radiosity.conserve): mean 1.4-1.6 %, max 4.7-9.0 %; family tuning rooms 0.95 -> 0.78
    # CIEDE2000 (former shadows 1.22 -> 0.99).  (Draft once kept none because on the
    # suite's room of random photos the split sent the lamp fit's rho^ from 0.5 to 0.29; that
    # test passes with it now)
    split_levels: int = 0
    split_near: float = 0.3
    # a receiver is split for its links' F variation only where the sum over its links varies
    aggregate: bool = True
    # elements crossed by a contact line (an object standing on a face: radiosity.contacts) are
    # split this many levels below min_area.  Medium: 2.  Clutter furnace, box on the floor,
    # medium: every leaf within 0.23 % at rho 0.5-0.99 (1.3 % at 0.9 without; straddling leaves
    # up to 5 %).  On the test office it first relit four floor texels black by a table leg's
    # foot (their centres on leaves buried whole, which read no light; now read in the open:
    # radiosity.exposure.read_in_the_open).  Draft: a split leaf beside the box, decided by one
    # point, is as likely dark as lit (3.2 % at rho 0.9).  High: family room 20's former
    # shadows went 0.83 -> 1.15 CIEDE2000 with 2 levels (before the texels read in the open)
    contact_levels: int = 0
    # the unoccluded form factors of a leaf near its sources (final_links.final_form_factors) are
    # averaged over this many m x m Gauss points when more than ``quadrature`` (its visibility,
    # exposure and hemisphere still those of its quadrature points).  Draft: 3.  At its one
    # point a face of a closed cube (one wall emitting, rho 0.99) that the oracle left whole took
    # 20 % more from the facing wall than that wall sends (F 0.2395 at its centre against
    # 0.1998): once the other walls were refined the emitted power came out 3 % high (0.7 %
    # with the source split, 1.1 % low with 2 x 2 points everywhere); 3 x 3 with the split's
    # reciprocal shares (radiosity.source_split): 0.02 % (2 x 2: 0.11 %, the test's bound 0.1 %)
    # Medium and high: 3.  On RenderPark's classroom (24 tubes of 0.05 m^2 under the ceiling)
    # the walls' leaves that reach above a tube's plane read 3-8 % dark on 2 x 2 points: medium
    # was less accurate than draft against Mitsuba 3 (4.88 / 7.74 % mean / max against 2.56 /
    # 4.83 %), 1.18 / 2.52 % with 3; the Cornell box unchanged at medium and high over seeds
    # 0-4.  Cost: the Cornell box at medium 1.77 -> 2.09 s, RenderPark's office 110 -> 136 s
    # (refining only the pairs whose 2 x 2 values spread took 117 s, but a leaf's row then mixes
    # two quadratures and is no longer exactly 1 in a closed room: 9e-5 off).  Not where a
    # touching object's side crosses the leaf (final_links._finer_form_factors); twice as many a side
    # where the source hovers just over the leaf's plane (final_links._hovering: a tube's reflector),
    # up to 16 a side where a small source stands on the leaf's edge (final_links._edge_contact_points:
    # the reflector's end caps; the Cornell box and the clutter furnace have no such pair)
    ff_quadrature: int = 0
    # the visibility rays of a near leaf's points leave from spots spread over the points'
    # Gauss cells, one visible fraction per (leaf, source) pair (final_links.final_form_factors
    # ``jitter``), except on leaves a contact line crosses.  From 2 x 2 fixed points a thin
    # occluder close to the leaf is missed: RenderPark's classroom's reflectors read their
    # partner, half hidden by the tube between them, 19 % bright at medium.  High: the
    # classroom's largest patches 0.48 / 1.58 -> 0.41 / 1.37 % mean / max against Mitsuba 3,
    # those near the lamps 1.07 / 1.53 (-1.1 % bias) -> 0.41 / 0.89 % (-0.2 %); the office's
    # 0.84 / 2.87 -> 0.59 / 2.30 and 0.96 / 2.97 -> 0.78 / 1.89 %; the Cornell box over seeds
    # 0-4 0.42-0.47 / 1.07-1.44 -> 0.36-0.40 / 0.91-0.97 %; the classroom's high solve +0-10 %
    # in time and memory.  Medium (8 rays a link, 2 a point): on the Cornell box
    # 0.62-0.70 / 1.52-2.21 -> 0.47-0.60 / 1.10-1.96 %, but on the classroom its 8 rays are
    # too few for the troughs: largest 0.55 / 2.19 -> 0.76 / 1.97 %, near the lamps 2.27 /
    # 4.06 (+1.6 %) -> 2.15 / 6.26 % (-1.7 %) (with partial_rays 32), so not there yet
    jitter_origins: bool = False
    # a final link whose first rays were partly blocked (a shadow's edge crosses it, and its
    # visible fraction is the noisiest) takes this many in all, when more than ``rays``.  High
    # with 64, against Mitsuba 3: RenderPark's classroom's largest patches 0.41 / 1.37 ->
    # 0.29 / 0.94 % mean / max, those near the lamps 0.41 / 0.89 -> 0.25 / 0.75 %, 440 -> 472 s,
    # peak 1.50 -> 1.56 GB; the Cornell box over seeds 0-4 0.36-0.40 / 0.91-0.97 ->
    # 0.33-0.36 / 0.90-1.02 %.  128: the classroom 0.26 / 0.75 and 0.25 / 0.62 %, but 664 s.
    # (Rays added after a first look are biased towards what the first rays saw: a link they
    # all saw free keeps V = 1)
    partial_rays: int = 0
    # the near pairs of shadows the refinement had no room to resolve (bright, partly visible
    # links whose receiver is too small to split: precompute._unresolved_shadows) cast this
    # many rays a leaf, from spots spread over it (with or without ``jitter_origins``).
    # Why: RenderPark's classroom's reflectors (one leaf each at medium) read the reflector
    # facing them, a sixth of it hidden by the tube between them, 20 % bright from 2 x 2 fixed
    # points (no ray met the tube), so the patches near its lamps came out 1.0-2.1 % bright on
    # every seed.  With 1024 spread rays, over seeds 0-4 against Mitsuba 3 (mean / max %,
    # results/mgf_classroom_seeds.md, cornell.md): the classroom near the lamps at medium
    # 1.76-2.28 / 2.89-5.35 (seeds 1-4) -> 0.26-0.34 / 0.66-1.05, at high 0.17-0.24 / 0.34-0.57
    # (its seed 4 0.47 / 1.38 before); the Cornell box at medium 0.62-0.70 / 1.52-2.21 ->
    # 0.53-0.67 / 1.39-2.97, for 40 % more time there.  256 instead of 1024 at medium: a clutter
    # furnace's leaf beside a panel 1 mm away read 1.05 % off (the kernel-weighted ratio's bias
    # next to the gap), 0.17 % with 1024.
    spread_rays: int = 0
    solver: str = "gmres"
    tol: float = 1e-8
    # the shadow-edge fit's bias floor (log-ratio sigma) before the photo overrides a lamp's set
    # power (relight.exitance).  With exact powers the fit's log ratios erred by 0.11-0.12 rms
    # on the family's tuning rooms at medium and high, 0.135 at draft, where 7 % of lamps came
    # out beyond 2 sigma at 0.05 (room 7's lamps, 55 and 121 W, pinned 15 % off): draft 0.10
    exitance_bias: float = 0.05
    # meshes of more than PROXY_FACTOR x proxy_faces faces (scans) are solved on a decimated
    # proxy of about proxy_faces triangles (radiosity.proxy).  On scans of family rooms 0, 3,
    # 5, 16 (100k triangles, benchmarks/results/scan.md) at medium, lamp off, all / former
    # shadows: 1,500 triangles 0.56-0.94 / 0.55-0.98 (room 0: 0.56 / 0.93), 3,000 0.50-0.78 /
    # 0.50-0.81 (0.53 / 0.71), 6,000 0.55 / 0.72 on room 0 (the clean rooms 0.57-0.74 /
    # 0.50-0.78), for 1.1-1.8x and 2.5x the time of 1,500.  At high 6,000 was worse than
    # 3,000 on the mean (0.66 / 0.71 over the four rooms against medium's 0.60 / 0.71; room 5
    # 0.72 / 0.55), so every preset above draft keeps 3,000.  (Finer proxies once did worse
    # still: their triangles' own mean normals and too few texels a triangle for the rho^
    # vote, radiosity.proxy.plane_normals and relight.exitance.VOTE_MIN_COVER)
    proxy_faces: int = 3000

    def with_(self, **changes) -> "Quality":
        return replace(self, **changes)


PRESETS = {
    "draft": Quality("draft", eps_bf=0.01, eps_bfv=0.005, min_area=2e-3, quadrature=1, rays=8,
                     oracle_rays=8, passes=2, separation=0.4, exitance_bias=0.10,
                     proxy_faces=1000, split_levels=3, split_near=0.15, ff_quadrature=3),
    "medium": Quality("medium", eps_bf=0.002, eps_bfv=0.003, min_area=3e-4, quadrature=2,
                      rays=8, oracle_rays=8, passes=2, separation=0.3, confirm_rays=4,
                      split_levels=3, split_near=0.15, contact_levels=2, ff_quadrature=3,
                      spread_rays=1024),
    "high": Quality("high", eps_bf=0.002, eps_bfv=0.001, min_area=8e-5, quadrature=2, rays=32,
                    oracle_rays=8, separation=0.25, confirm_rays=4,
                    split_levels=3, split_near=0.15, ff_quadrature=3, jitter_origins=True,
                    partial_rays=64, spread_rays=1024),
    # ultra with high's spread origins and 128 rays on partly blocked links: on the Cornell
    # box over seeds 0-4 without them it fell behind high (0.35-0.37 / 0.99-1.30 % against
    # high's 0.33-0.36 / 0.90-1.02 %), with them 0.24-0.26 / 0.88-0.91 %
    "ultra": Quality("ultra", eps_bf=0.0007, eps_bfv=0.0003, min_area=2e-5, quadrature=3,
                     rays=32, oracle_rays=8, separation=0.15, confirm_rays=4,
                     split_levels=3, split_near=0.1, jitter_origins=True, partial_rays=128,
                     spread_rays=1024),
}


# a mesh of more than this x proxy_faces faces is solved on a proxy (more than 6,000 faces
# above draft, as when the proxy was 1,500 triangles and the factor 4)
PROXY_FACTOR = 2


def get_preset(preset) -> Quality:
    if isinstance(preset, Quality):
        return preset
    try:
        return PRESETS[preset]
    except KeyError:
        raise ValueError(f"Unknown quality preset {preset!r}; choose one of {sorted(PRESETS)}") from None
