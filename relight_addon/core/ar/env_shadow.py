# SPDX-License-Identifier: GPL-3.0-or-later
"""Soft shadows of a sphere set under an environment map (seed 002 §4.3.1, exact where it
approximates).

A receiver (point p, normal n) under the map gets the irradiance E(n).  The spheres standing for
the virtual object hide part of it; the shadow factor the photograph is multiplied by is

    F(p) = (irradiance past the spheres) / E(n)          in [0, 1], per RGB channel.

Seed 002 (eq. 4.3.1.4) takes, per sphere, F = 1 - cos(w) sin^2(a) L(S) / L(H): the sphere's
cosine-weighted solid angle (wrong once the sphere straddles the horizon, cap.py) times the
ratio of the map's radiance over the sphere's cap to its mean over the hemisphere, both read from
the mip chain.  Three weightings are offered here (``weighting``):

``"light+caps"`` (default): the map is its main light (and up to three further compact lights)
    plus a residual (main_light.extract_lights, ARCore's split).  The residual's part hidden by
    sphere i is b_i = L_res(cap_i) C(beta_i, alpha_i) / E_res(n): C the exact clamped-cosine
    integral of the cap (cap.py), E_res the residual's irradiance (the irradiance table less
    the lights'), L_res(cap) the residual's mean radiance over the part of the cap above the
    receiver's horizon (:func:`visible_cap`), read from the cap-filtered tables (cap_filter.py)
    at that cap's cosine-weighted centroid (:func:`cosine_centroid`).  Each light, a cone of its
    solid angle, is a lamp: its visible fraction V past the spheres is
    relight.sphere_shadow.sphere_visibility (the lamps' own formula: one implementation), its
    irradiance E_L = L_light C(beta_L, theta_L).  F = (E_res (1 - B) + sum E_L V) / (E_res +
    sum E_L).
``"light+sh"``: the same with L_res(cap) from the residual's SH9 (the zonal cap filter, exact
    for a band-limited residual; wrong by x3 under a courtyard's dark canopy).
``"mips"`` (the seed's L(S) / L(H)): b_i = L_mip(cap_i) C_i / E(n), L_mip the cube mip chain
    read in the cap's direction at the level whose texels have the cap's solid angle, E(n) the
    map's irradiance (the table).  F = 1 - B.

Every way, the b_i of a set combine within the object's silhouette
(sphere_shadow.combined_visibility with the hull sphere's b: one rule for lamps and maps).
``cap="seed"`` swaps the exact C for the seed's pi cos(beta) sin^2(alpha).  Positions are world
coordinates (the map's directions are world-fixed): move a set with :func:`world_spheres`.

The numpy twin of the shader's sphere-shadow evaluation (blender/shaders).
"""
from __future__ import annotations

import numpy as np

from ..relight.sphere_shadow import combined_visibility, sphere_visibility, sun_disk
from ..texture.colour import LUMINANCE
from .cap import cap_cosine_integral, seed_cap_cosine_integral
from .cap_filter import sample_cap_filtered
from .envmap import sample_cube_mips, sample_nodes
from .irradiance import sh9_basis
from .main_light import light_irradiance

E_FLOOR = 1e-9          # of the map's mean irradiance: a receiver lit by less is not shadowed


def world_spheres(centres, radii, matrix):
    """(centres (m, 3), radii (m,)) of a set fitted in object coordinates, moved by the 4 x 4
    ``matrix`` (object to world; radii scaled by the cube root of its |determinant|, exact for a
    uniform scale)."""
    m = np.asarray(matrix, float)
    c = np.asarray(centres, float) @ m[:3, :3].T + m[:3, 3]
    return c, np.asarray(radii, float) * abs(np.linalg.det(m[:3, :3])) ** (1.0 / 3.0)


def cap_geometry(points, normals, centre, radius):
    """(axis (n, 3) unit, cos beta (n,), sin^2 alpha (n,)) of one sphere seen from the points."""
    to_c = np.asarray(centre, float) - points
    d = np.maximum(np.linalg.norm(to_c, axis=-1), 1e-12)
    axis = to_c / d[:, None]
    return axis, np.einsum("ij,ij->i", axis, normals), (radius / d) ** 2


def visible_cap(axis, cos_beta, sin2_alpha, normals):
    """(axis (n, 3), half-angle (n,)) of the cap standing for the part of a cap above the
    receiver's horizon: the same top edge, its bottom edge raised to the horizon (elevations
    max(e - a, 0) .. e + a, e the axis' elevation), so that a sphere dipping below a table top
    is weighted by the radiance the table top sees, not by the floor under it."""
    alpha = np.arcsin(np.sqrt(np.clip(sin2_alpha, 0.0, 1.0)))
    e = np.arcsin(np.clip(cos_beta, -1.0, 1.0))
    lo, hi = np.maximum(e - alpha, 0.0), e + alpha
    straddle = (e < alpha) & (hi > 0)
    t = axis - cos_beta[:, None] * normals
    tn = np.linalg.norm(t, axis=1, keepdims=True)
    t = np.where(tn > 1e-12, t / np.maximum(tn, 1e-300), axis)
    e2 = 0.5 * (lo + hi)
    ax2 = np.cos(e2)[:, None] * t + np.sin(e2)[:, None] * normals
    return (np.where(straddle[:, None], ax2, axis),
            np.where(straddle, np.maximum(0.5 * (hi - lo), 0.0), alpha))


def cosine_centroid(axis, cos_beta, sin2_alpha, normals):
    """Unit direction (n, 3) of the cosine-weighted mean of a cap (axis, half-angle alpha)
    about the receivers' normals: integral of w (w.n) dw over the cap, which is
    A cos(beta) axis + B (n - cos(beta) axis) with A = 2 pi (1 - cos^3 a) / 3 and
    B = pi (2/3 - cos a + cos^3 a / 3).  The cap-filtered map read there instead of at the axis
    gives the cosine-weighted mean radiance exactly for radiance linear in w."""
    ca = np.sqrt(np.clip(1.0 - sin2_alpha, 0.0, 1.0))
    A = 2 * np.pi * (1 - ca ** 3) / 3
    B = np.pi * (2.0 / 3.0 - ca + ca ** 3 / 3)
    cb = cos_beta[:, None]
    m = A[:, None] * cb * axis + B[:, None] * (normals - cb * axis)
    norm = np.linalg.norm(m, axis=1, keepdims=True)
    return np.where(norm > 1e-12, m / np.maximum(norm, 1e-300), axis)


def sh9_cap_radiance(sh, axis, sin2_alpha):
    """Mean radiance (n, 3) over caps (unit ``axis`` (n, 3), sin^2 of the half-angle) of the
    band-limited map ``sh`` (9, 3): each band scaled by the cap's zonal filter, band 0 by 1,
    band 1 by (1 + cos a) / 2, band 2 by cos a (1 + cos a) / 2; clamped at 0."""
    ca = np.sqrt(np.clip(1.0 - sin2_alpha, 0.0, 1.0))
    k = np.stack([np.ones_like(ca)] + [(1 + ca) / 2] * 3 + [ca * (1 + ca) / 2] * 5, axis=-1)
    return np.maximum((sh9_basis(axis) * k) @ sh, 0.0)


def mip_level_for_cap(sin2_alpha, size):
    """Fractional cube mip level whose texels have the solid angle of a cap (size = level 0's
    face width): texels of (4 pi / 6) / s^2 sr at width s."""
    omega = 2 * np.pi * sin2_alpha / (1 + np.sqrt(np.clip(1 - sin2_alpha, 0, 1)))   # 2 pi (1 - cos)
    s = np.sqrt((4 * np.pi / 6) / np.maximum(omega, 1e-12))
    return np.clip(np.log2(size / s), 0.0, np.log2(size))


def _cap_term(cap):
    return cap_cosine_integral if cap == "exact" else seed_cap_cosine_integral


def env_shadow_factor(points, normals, centres, radii, lighting, hull=None,
                      weighting="light+caps", cap="exact"):
    """Shadow factor (n, 3) in [0, 1] of receivers ``points`` (n, 3) with unit ``normals``
    (n, 3) under ``lighting`` (lighting.EnvironmentLighting), from the spheres ``centres``
    (m, 3), ``radii`` (m,) and the optional ``hull`` = (centre, radius) silhouette sphere
    (relight.spheres.silhouette_sphere), all in world coordinates.  ``weighting``:
    "light+caps" (default), "light+sh" or "mips" (seed 002); ``cap``: "exact" (default) or
    "seed".  1 where nothing is
    hidden; never NaN."""
    p = np.asarray(points, float)
    nrm = np.asarray(normals, float)
    nrm = nrm / np.maximum(np.linalg.norm(nrm, axis=-1, keepdims=True), 1e-300)
    n = len(p)
    centres, radii = np.asarray(centres, float).reshape(-1, 3), np.asarray(radii, float).ravel()
    C = _cap_term(cap)
    # the map's mean irradiance: pi x its mean radiance (the SH band-0 coefficient x Y00)
    floor = E_FLOOR * max(float(np.abs(lighting.sh[0]).max()) * np.pi / np.sqrt(4 * np.pi), 1e-300)

    if weighting in ("light+caps", "light+sh"):
        # the residual's irradiance: the exact one (irradiance map) less the lights' own
        e_amb = sample_nodes(lighting.irradiance, nrm)
        for light in lighting.lights:
            e_amb = e_amb - light_irradiance(light, nrm)
        e_amb = np.maximum(e_amb, floor)

        def blocked(c, r):
            axis, cb, s2 = cap_geometry(p, nrm, c, r)
            if weighting == "light+caps":
                ax2, alpha2 = visible_cap(axis, cb, s2, nrm)
                rad = sample_cap_filtered(lighting.caps,
                                          cosine_centroid(ax2, np.einsum("ij,ij->i", ax2, nrm),
                                                          np.sin(alpha2) ** 2, nrm), alpha2)
            else:
                rad = sh9_cap_radiance(lighting.sh_ambient, axis, s2)
            b = rad * C(cb, s2)[:, None] / e_amb
            return np.where(s2[:, None] >= 1.0, 1.0, b)       # inside the sphere: all hidden
    elif weighting == "mips":
        e_all = np.maximum(sample_nodes(lighting.irradiance, nrm), floor)
        size = lighting.mips[0].shape[1]

        def blocked(c, r):
            axis, cb, s2 = cap_geometry(p, nrm, c, r)
            rad = sample_cube_mips(lighting.mips, axis, mip_level_for_cap(s2, size),
                                   lighting.padded)
            return np.where(s2[:, None] >= 1.0, 1.0, rad * C(cb, s2)[:, None] / e_all)
    else:
        raise ValueError(f"Unknown weighting {weighting!r}: expected 'light+caps', 'light+sh' "
                         f"or 'mips'.")

    part = None if hull is None else np.minimum(blocked(hull[0], hull[1]), 1.0)
    visible = combined_visibility((np.minimum(blocked(c, r), 1.0) for c, r in zip(centres, radii)),
                                  (n, 3), part)
    if weighting == "mips":
        return np.clip(visible, 0.0, 1.0)

    lit = e_amb * visible
    total = e_amb.copy()
    for light in lighting.lights:
        if light.solid_angle <= 0:
            continue
        e_light = light_irradiance(light, nrm)
        pos, rad = sun_disk(-light.direction, 2.0 * light.half_angle)
        lit = lit + e_light * sphere_visibility(p, pos, rad, centres, radii, hull)[:, None]
        total = total + e_light
    return np.clip(lit / total, 0.0, 1.0)


def luminance_factor(points, normals, factor, lighting):
    """Luminance shadow factor (n,) from the RGB ``factor`` (n, 3), weighted by the map's RGB
    irradiance at each normal (what a grey receiver's photo is darkened by)."""
    e = sample_nodes(lighting.irradiance, np.asarray(normals, float)) * LUMINANCE
    return (factor * e).sum(-1) / np.maximum(e.sum(-1), 1e-300)
