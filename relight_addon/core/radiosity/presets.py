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
    oracle_rays: int       # visibility rays per candidate link while refining (stable shadows)
    confirm_rays: int = 0  # x oracle_rays: re-test of bright links the oracle's rays all agreed on
    passes: int = 3        # refine / solve passes (the BF oracle needs a radiosity estimate)
    separation: float = 0.4  # cluster link when (radius sum) < separation * (centre distance)
    cluster_above: int = 400  # input patch count above which patches are clustered
    # near sources' gather entries split over their children this many levels down
    # (radiosity.source_split) while the source's radius > split_near x its distance: a near
    # source's radiosity varies over it
    split_levels: int = 0
    split_near: float = 0.3
    # a receiver is split for its links' F variation only where the sum over its links varies
    aggregate: bool = True
    # elements crossed by a contact line (radiosity.contacts) split this many levels below
    # min_area: an object standing on a face darkens part of the leaves under its foot
    contact_levels: int = 0
    # the same where an object hovers just above a face (radiosity.contacts' gap lines): one
    # gather point on an element across its outline sees either the object's underside or the
    # room
    gap_levels: int = 0
    # a near leaf's unoccluded form factors averaged over this many m x m Gauss points when more
    # than ``quadrature`` (radiosity.final_links): one point errs by 20 % on a leaf as large as
    # its gap to the source, and form factors cost no rays
    ff_quadrature: int = 0
    # a near leaf's rays leave from spots spread over its points' Gauss cells (final_links
    # ``jitter``; not where a contact line crosses): fixed points miss a thin occluder near it
    jitter_origins: bool = False
    # rays in all of a final link whose first rays were partly blocked, when more than
    # ``rays``: a shadow's edge crosses it, and its visible fraction is the noisiest
    partial_rays: int = 0
    # and at least this many a point of such a link (final_links ``partial_point_rays``): a
    # large element's link gives each of its leaves' points one ray, a penumbra leaf's visible
    # fraction then one ray's 0 or 1
    partial_point_rays: int = 1
    # rays a leaf, from spots spread over it, of the near pairs of shadows the refinement could
    # not resolve (precompute._unresolved_shadows): fixed points misjudge a visibility that
    # varies across the leaf
    spread_rays: int = 0
    solver: str = "gmres"
    tol: float = 1e-8
    # the shadow-edge fit's bias floor (log-ratio sigma) before the photo overrides a lamp's set
    # power (relight.exitance): the fit's own error with exact powers
    exitance_bias: float = 0.05
    # meshes of more than PROXY_FACTOR x this many faces (scans) are solved on a decimated proxy
    # of about this many triangles (radiosity.proxy): the indirect light needs no finer mesh
    proxy_faces: int = 3000

    def with_(self, **changes) -> "Quality":
        return replace(self, **changes)


PRESETS = {
    "draft": Quality("draft", eps_bf=0.01, eps_bfv=0.005, min_area=2e-3, quadrature=1, rays=8,
                     oracle_rays=8, passes=2, separation=0.4, exitance_bias=0.10,
                     proxy_faces=1000, split_levels=3, split_near=0.15, ff_quadrature=3,
                     gap_levels=2, partial_rays=32, contact_levels=1,
                     partial_point_rays=8),
    "medium": Quality("medium", eps_bf=0.002, eps_bfv=0.003, min_area=3e-4, quadrature=2,
                      rays=8, oracle_rays=8, passes=2, separation=0.3, confirm_rays=4,
                      split_levels=3, split_near=0.15, contact_levels=2, ff_quadrature=3,
                      spread_rays=1024),
    "high": Quality("high", eps_bf=0.002, eps_bfv=0.001, min_area=8e-5, quadrature=2, rays=32,
                    oracle_rays=8, separation=0.25, confirm_rays=4,
                    split_levels=3, split_near=0.15, ff_quadrature=3, jitter_origins=True,
                    partial_rays=64, spread_rays=1024),
    # ultra: high's spread origins, more rays on partly blocked links (without, worse than high)
    "ultra": Quality("ultra", eps_bf=0.0007, eps_bfv=0.0003, min_area=2e-5, quadrature=3,
                     rays=32, oracle_rays=8, separation=0.15, confirm_rays=4,
                     split_levels=3, split_near=0.1, jitter_origins=True, partial_rays=128,
                     spread_rays=1024),
}


# a mesh of more than this x proxy_faces faces is solved on a proxy
PROXY_FACTOR = 2


def get_preset(preset) -> Quality:
    if isinstance(preset, Quality):
        return preset
    try:
        return PRESETS[preset]
    except KeyError:
        raise ValueError(f"Unknown quality preset {preset!r}; choose one of {sorted(PRESETS)}") from None
