# SPDX-License-Identifier: GPL-3.0-or-later
"""The environment's mean radiance over caps of every size: cap-filtered maps.

A sphere that hides part of the sky hides the radiance over its cap.  The box-filtered cube
mips (seed 002's L(S)) and the SH9 of the map are both poor estimates of that mean over a large
cap (a courtyard's dark canopy overhead next to its bright opening: SH9 says a cap of 55 deg
overhead is 3x brighter than it is, tests/test_ar_env_shadow.py).  So the map is filtered
once per cap half-angle of CAP_ANGLES, exactly: each output pixel the mean radiance of the
source over the cap of that half-angle around the pixel's direction (a sum over every pixel of
the map averaged down to CAP_SOURCE), stored as small latitude-node tables
(envmap.sample_nodes); a lookup
interpolates linearly in the half-angle between the two nearest tables (bilinear in each).
Caps smaller than the first angle read the first table (the main lights, the sharp part, are
taken out of the map before: main_light.py).
"""
from __future__ import annotations

import numpy as np

from .envmap import (equirect_directions, equirect_solid_angles, node_directions, resize_equirect,
                     sample_nodes)

CAP_ANGLES = np.radians([4.0, 8.0, 12.0, 18.0, 26.0, 36.0, 48.0, 62.0, 76.0, 90.0])
CAP_SOURCE = (64, 128)          # source map for the sums (2.8 deg pixels)
CAP_TABLE = (33, 64)            # each filtered table: latitude nodes every 5.6 deg


def cap_filtered_maps(env, angles=CAP_ANGLES, source=CAP_SOURCE, size=CAP_TABLE, chunk=1024):
    """(len(angles), h, w, 3) latitude-node tables (envmap.node_directions) of the mean
    radiance of ``env`` over caps of each half-angle (radians) around each node's direction."""
    h, w = env.shape[:2]
    if h > source[0] and w > source[1]:
        env = resize_equirect(env, *source)
        h, w = source
    d = equirect_directions(h, w).reshape(-1, 3)
    om = np.repeat(equirect_solid_angles(h, w), w)
    lw = env.reshape(-1, 3) * om[:, None]
    n = node_directions(*size).reshape(-1, 3)
    out = np.empty((len(angles), len(n), 3))
    for a in range(0, len(n), chunk):
        cos = n[a:a + chunk] @ d.T
        for k, ang in enumerate(angles):
            inside = (cos >= np.cos(ang)).astype(float)
            wsum = inside @ om
            # a cap narrower than a source pixel: the pixel it falls in
            near = wsum <= 0
            num = inside @ lw
            if near.any():
                j = np.argmax(cos[near], axis=1)
                num[near] = lw[j]
                wsum[near] = om[j]
            out[k, a:a + chunk] = num / wsum[:, None]
    return out.reshape((len(angles),) + tuple(size) + (3,))


def sample_cap_filtered(tables, d, half_angle, angles=CAP_ANGLES):
    """Mean radiance (n, 3) over caps around unit directions ``d`` (n, 3) with half-angles
    ``half_angle`` (n,): linear in the angle between the two nearest tables."""
    a = np.clip(np.asarray(half_angle, float), angles[0], angles[-1])
    k = np.clip(np.searchsorted(angles, a, side="right") - 1, 0, len(angles) - 2)
    f = ((a - angles[k]) / (angles[k + 1] - angles[k]))[:, None]
    out = np.empty((len(d), 3))
    for j in np.unique(k):
        sel = k == j
        lo = sample_nodes(tables[j], d[sel])
        hi = sample_nodes(tables[j + 1], d[sel])
        out[sel] = lo * (1 - f[sel]) + hi * f[sel]
    return out
