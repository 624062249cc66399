"""Unoccluded irradiance of Blender lights on a Lambertian receiver, as Cycles computes it.

bpy-free numpy reference implementations, checked against Cycles DIFFUSE bakes of Blender 5.0.1
by benchmarks/light_units.py (tables: benchmarks/results/light_units.md).  Every ``irradiance_*``
returns E (W/m^2, shape (n, 3)) at receiver points with unit normals, unoccluded; a diffuse
surface of albedo rho then has radiosity rho E and DIFFUSE-bakes (with colour) to rho E / pi.

Radiant colour of every light: ``energy`` x ``colour`` x 2**``exposure`` (x ``blackbody_colour``
with ``use_temperature``); ``diffuse_factor`` / ``specular_factor`` / ``volume_factor`` and
spot ``use_square`` do nothing in Cycles; object scale changes neither a POINT's / SPOT's
power nor its radius (it does shape the spot cone and scales AREA sizes).

* POINT, radius 0: intensity P / (4 pi) W/sr, E = P cos / (4 pi d^2) (Cycles = this to 1e-4;
  the guess P cos / (4 pi^2 d^2) is low by exactly pi).
* POINT, radius r: uniform radiance L = P / (4 pi^2 r^2) filling a cone of half-angle beta,
  sin beta = r / sqrt(d^2 + r^2) with ``use_soft_falloff`` (a disk facing the receiver) or
  r / d without (a sphere; E = pi L anywhere inside it).  Closed form ``cone_irradiance`` incl.
  the horizon.  Measured / model over 53 probes (d/r 0.5-30, theta 0-135 deg, both
  falloffs): within 2 sigma of the bake noise or 5e-4 except two at -8e-4 (worst ratios 0.963
  and 0.989 are grazing probes with 2 % noise); r = 0: 0.9995-1.0002.
* SPOT: the POINT above x ``spot_attenuation`` (smoothstep in the scale-corrected local frame,
  no extra cosine, same power as a POINT: not renormalised to the cone).  Max |dev| 5e-4 of
  the peak for r = 0 (incl. rotated, non-uniformly scaled cones); with a radius the mask is
  averaged over the source (quadrature; max |dev| 0.15 % of the peak, 0.8 % at d < r).
* SUN: E = S cos for a disc wholly above the horizon, whatever ``angle``; near the horizon the
  disc (uniform radiance S / (pi sin^2(angle / 2))) is clipped: ratios 0.9985-1.0004
  (angles 0-120 deg, theta 0-120 deg).
* AREA: one-sided Lambertian exitance P / A (normalize; A = scaled area, ellipse pi/4 a b with
  sizes as diameters), or P per m^2 (normalize off).  ``spread`` < 180 deg multiplies the
  radiance by the power-conserving ``spread_profile``.  Ratios 0.9985-1.0022 on 40 random
  probes per shape (spread: sums 0.9992-1.0006, single probes 0.991-1.001 at the edge of the
  lit footprint).
* Mesh emission (Emission shader or Principled emission): radiance strength x colour on BOTH
  sides of a face (exitance pi S per side): ``irradiance_emissive_polygon``, 0.995-1.003.
* ``normalize`` off: POINT / SPOT radiance becomes P / pi (E x 4 pi r^2, or x 4 at r = 0),
  SUN radiance S (E x pi sin^2(angle / 2); angle 0 unchanged), AREA exitance P.
* Bakes see only the receiver's FRONT (normal / winding) side; renders shade both sides.
"""
from __future__ import annotations

import numpy as np

__all__ = ["light_colour", "blackbody_colour", "cone_irradiance", "irradiance_point",
           "irradiance_spot", "spot_attenuation", "irradiance_sun", "irradiance_area",
           "area_exitance", "spread_profile", "irradiance_emissive_polygon"]


def _rows(a, n=None):
    a = np.asarray(a, np.float64)
    return a.reshape(-1, a.shape[-1]) if n is None else np.broadcast_to(a, (n, a.shape[-1]))


def light_colour(colour=(1.0, 1.0, 1.0), exposure=0.0, temperature=None):
    """Radiant colour multiplier (3,): colour x 2**exposure (x blackbody_colour(temperature)
    when the light has ``use_temperature``; pass temperature=None otherwise)."""
    c = np.asarray(colour, np.float64) * 2.0 ** float(exposure)
    return c if temperature is None else c * blackbody_colour(temperature)


def cone_irradiance(sin_beta, cos_theta):
    """Irradiance from a circular cone of half-angle beta and UNIT radiance on a plane whose
    normal makes angle theta with the cone axis: integral over the cone of max(cos, 0) d omega.

    Closed form (the sphere-to-tilted-element view factor x pi): pi sin^2(beta) cos(theta) while
    the cone is wholly above the horizon (theta <= pi/2 - beta), 0 once wholly below, and in
    between the partial-visibility expression.  Vectorised; sin_beta in (0, 1]."""
    sb = np.clip(np.asarray(sin_beta, np.float64), 1e-12, 1.0)
    ct = np.clip(np.asarray(cos_theta, np.float64), -1.0, 1.0)
    sb, ct = np.broadcast_arrays(sb, ct)
    st = np.sqrt(np.maximum(1.0 - ct * ct, 0.0))
    full = ct >= sb                   # theta <= pi/2 - beta
    none = ct <= -sb                  # theta >= pi/2 + beta
    out = np.where(full, np.pi * sb * sb * ct, 0.0)
    part = ~(full | none)
    if np.any(part):
        s, c, t = sb[part], ct[part], st[part]
        H2 = 1.0 / (s * s)            # (d / r)^2 for a sphere
        root = np.sqrt(np.maximum(H2 - 1.0, 0.0))   # = cot(beta)
        cot_t = c / np.maximum(t, 1e-300)
        a1 = np.arcsin(np.clip(root / np.sqrt(H2) / np.maximum(t, 1e-300), -1.0, 1.0))
        a2 = np.arccos(np.clip(-root * cot_t, -1.0, 1.0))
        a3 = np.sqrt(np.maximum(1.0 - H2 * c * c, 0.0))
        F = 0.5 - a1 / np.pi + (c * a2 - root * a3) / (np.pi * H2)
        out[part] = np.pi * np.maximum(F, 0.0)
    return out


def irradiance_point(points, normals, light_pos, power, colour=(1, 1, 1), radius=0.0,
                     soft_falloff=True, exposure=0.0, normalize=True):
    """POINT light (Cycles, Blender 5.0): (n, 3) irradiance in W/m^2.

    radius = ``shadow_soft_size``.  r = 0: E = P max(cos, 0) / (4 pi d^2).  r > 0: uniform
    radiance L = P / (4 pi^2 r^2) over a cone of half-angle beta, sin(beta) = r / d (sphere,
    soft_falloff False; inside the sphere, d <= r, E = pi L on any plane) or
    r / sqrt(d^2 + r^2) (soft_falloff True: a disk of radius r always facing the receiver).
    normalize False: L = P / pi (E x 4 pi r^2), or intensity P / pi at r = 0 (E x 4).
    ``colour`` is the radiant colour without exposure (see ``light_colour``).
    """
    p = _rows(points)
    n = _rows(normals, len(p))
    w = np.asarray(light_pos, np.float64) - p
    d = np.linalg.norm(w, axis=1)
    ct = np.einsum("ij,ij->i", w, n) / np.maximum(d, 1e-300)
    rgb = float(power) * light_colour(colour, exposure)
    r = float(radius)
    if r <= 0.0:
        e = np.maximum(ct, 0.0) / (4.0 * np.pi * d * d)
    else:
        L = 1.0 / (4.0 * np.pi ** 2 * r * r)
        if soft_falloff:
            e = L * cone_irradiance(r / np.sqrt(d * d + r * r), ct)
        else:
            e = L * cone_irradiance(np.minimum(r / np.maximum(d, 1e-300), 1.0), ct)
            e[d <= r] = np.pi * L        # inside the sphere: lit from every direction
    if not normalize:
        e = e * (4.0 * np.pi * r * r if r > 0.0 else 4.0)
    return e[:, None] * rgb[None, :]


def irradiance_sun(normals, direction, strength, colour=(1, 1, 1), angle=0.0, exposure=0.0,
                   normalize=True):
    """SUN light: E = S max(cos theta, 0), theta between the normal and -direction (direction =
    where the light travels: the object's local -Z axis), while the sun's disc is wholly above
    the receiver's horizon; ``angle`` (angular diameter, 2 beta) only matters near the horizon:
    the disc has uniform radiance S / (pi sin^2 beta), E = that x ``cone_irradiance``.
    normalize=False: radiance S itself (E = S pi sin^2(beta) cos theta; angle 0: S cos theta)."""
    n = _rows(normals)
    dv = np.asarray(direction, np.float64)
    dv = dv / np.linalg.norm(dv)
    ct = -(n @ dv)
    sb = np.sin(0.5 * float(angle))
    if sb < 1e-6:
        e = np.maximum(ct, 0.0)
    else:
        e = cone_irradiance(sb, ct) / (np.pi * sb * sb)
        if not normalize:
            e = e * np.pi * sb * sb
    return (float(strength) * e)[:, None] * light_colour(colour, exposure)[None]


def smoothstep(x):
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def spot_attenuation(rays, matrix, spot_size, spot_blend):
    """Cycles' spot mask for rays (m, 3) travelling FROM the light (not normalised).

    The ray is taken to the light object's local frame with its scale divided out per axis
    (u / sx, v / sy, -z / sz, then normalised: so a non-uniform scale makes the cone elliptic),
    then smoothstep((z - cos(spot_size / 2)) / ((1 - cos(spot_size / 2)) * spot_blend)); with
    blend 0 a hard step.  No extra cosine factor."""
    M = np.asarray(matrix, np.float64)[:3, :3]
    ax = M.T                                  # rows: world X, Y, Z axes of the object
    lens = np.linalg.norm(ax, axis=1)
    u, v, z = ax[0] / lens[0], ax[1] / lens[1], ax[2] / lens[2]
    r = _rows(rays)
    loc = np.stack([r @ u / lens[0], r @ v / lens[1], -(r @ z) / lens[2]], 1)
    loc /= np.maximum(np.linalg.norm(loc, axis=1, keepdims=True), 1e-300)
    ch = np.cos(0.5 * float(spot_size))
    if spot_blend <= 0.0:
        return (loc[:, 2] > ch).astype(np.float64)
    return smoothstep((loc[:, 2] - ch) / ((1.0 - ch) * float(spot_blend)))


def _cone_dirs(axis, sin_beta, nu=12, nv=24):
    """(m, nu*nv, 3) midpoint-stratified directions uniform in solid angle inside the cone."""
    w = _rows(axis)
    m = len(w)
    a = np.where(np.abs(w[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]])
    t1 = np.cross(a, w)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(w, t1)
    cb = np.sqrt(np.maximum(1.0 - np.asarray(sin_beta, float) ** 2, 0.0)).reshape(m, 1)
    uu = (np.arange(nu) + 0.5) / nu
    vv = (np.arange(nv) + 0.5) / nv
    U, V = np.meshgrid(uu, vv, indexing="ij")
    U, V = U.ravel()[None], V.ravel()[None]
    cz = 1.0 - U * (1.0 - cb)
    sz = np.sqrt(np.maximum(1.0 - cz * cz, 0.0))
    ph = 2.0 * np.pi * V
    return (cz[..., None] * w[:, None] + (sz * np.cos(ph))[..., None] * t1[:, None]
            + (sz * np.sin(ph))[..., None] * t2[:, None])


def irradiance_spot(points, normals, matrix, power, colour=(1, 1, 1), spot_size=np.pi / 4,
                    spot_blend=0.15, radius=0.0, soft_falloff=True, exposure=0.0, normalize=True,
                    quad=(32, 64)):
    """SPOT light: a POINT light (same power convention, same radius / soft-falloff geometry)
    times ``spot_attenuation`` of the direction light -> receiver; ``matrix`` = the light
    object's 4x4 world matrix (position, -Z = spot axis, scale shapes the cone).

    With a radius the mask is averaged over the source as Cycles does (it evaluates it per
    light sample, for the direction sample point -> receiver): ratio estimator
    closed-form-cone x sum(mask x cos+) / sum(cos+) on a ``quad`` (cos, azimuth) midpoint grid
    over the cone (the default grid is within ~1.5 % of the peak at a blurred cone edge;
    (96, 192) within the bake noise).  Inside a sphere spot (d < r, no soft falloff) Cycles
    applies no mask at all."""
    M = np.asarray(matrix, np.float64)
    pos = M[:3, 3]
    p = _rows(points)
    n = _rows(normals, len(p))
    base = irradiance_point(p, n, pos, power, colour, radius, soft_falloff, exposure, normalize)
    r = float(radius)
    w = pos - p
    d = np.linalg.norm(w, axis=1)
    if r <= 0.0:
        return base * spot_attenuation(-w, M, spot_size, spot_blend)[:, None]
    sb = r / np.sqrt(d * d + r * r) if soft_falloff else np.minimum(r / d, 1.0)
    inside = d <= r if not soft_falloff else np.zeros(len(p), bool)
    fac = np.ones(len(p))
    out = ~inside
    if np.any(out):
        dirs = _cone_dirs(w[out] / d[out, None], sb[out], *quad)         # receiver -> light
        cos_r = np.maximum(np.einsum("mqk,mk->mq", dirs, n[out]), 0.0)
        att = spot_attenuation(-dirs.reshape(-1, 3), M, spot_size, spot_blend).reshape(
            cos_r.shape)
        den = cos_r.sum(1)
        fac[out] = np.where(den > 0, (att * cos_r).sum(1) / np.maximum(den, 1e-300), 0.0)
    return base * fac[:, None]


def area_light_frame(matrix, shape="SQUARE", size=1.0, size_y=1.0):
    """Centre, unit axes u, v, world lengths len_u, len_v, emitting normal (local -Z), is_round,
    of an AREA light whose object has world matrix ``matrix``.  Sizes are full widths
    (diameters for DISK / ELLIPSE) multiplied by the object's X / Y scale; SQUARE and DISK use
    ``size`` for both axes."""
    M = np.asarray(matrix, np.float64)
    X, Y, Z = M[:3, 0], M[:3, 1], M[:3, 2]
    sx, sy = np.linalg.norm(X), np.linalg.norm(Y)
    sy_ = size if shape in ("SQUARE", "DISK") else size_y
    nrm = -Z / np.linalg.norm(Z)
    return (M[:3, 3], X / sx, Y / sy, float(size) * sx, float(sy_) * sy, nrm,
            shape in ("DISK", "ELLIPSE"))


def area_light_polygon(matrix, shape="SQUARE", size=1.0, size_y=1.0, segments=256):
    """(k, 3) outline of the light (rectangle corners, or a ``segments``-gon for round shapes
    with the same area as the ellipse, so Lambert's formula stays within ~1e-4)."""
    c, u, v, lu, lv, nrm, rnd = area_light_frame(matrix, shape, size, size_y)
    if not rnd:
        s = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], float) * 0.5
    else:
        ph = 2 * np.pi * np.arange(segments) / segments
        k = np.sqrt(2 * np.pi / segments / np.sin(2 * np.pi / segments))   # equal area
        s = 0.5 * k * np.stack([np.cos(ph), np.sin(ph)], 1)
    return c + s[:, :1] * lu * u + s[:, 1:] * lv * v


def area_exitance(power, shape="SQUARE", size=1.0, size_y=1.0, matrix=None, colour=(1, 1, 1),
                  exposure=0.0, normalize=True):
    """Lambertian exitance M (3,) W/m^2 of the emitting side: P x colour x 2**exposure / A with
    ``normalize`` (A with the object's scale), else P x colour x 2**exposure (per m^2)."""
    M = np.eye(4) if matrix is None else matrix
    _, _, _, lu, lv, _, rnd = area_light_frame(M, shape, size, size_y)
    A = lu * lv * (np.pi / 4 if rnd else 1.0)
    return float(power) * light_colour(colour, exposure) / (A if normalize else 1.0)


def spread_profile(angle, spread):
    """Cycles' area-light spread factor on the Lambertian radiance for emission angle ``angle``
    (from the light normal): (tan(h) - tan(angle)) / (tan(h) - h) for angle < h = spread / 2,
    else 0 (3 / h**3 replaces 1 / (tan h - h) below h = 0.05).  Power-conserving: the integral
    of f cos over the hemisphere is pi, like a Lambertian emitter.  spread >= pi: 1."""
    h = 0.5 * float(spread)
    a = np.asarray(angle, np.float64)
    if h >= 0.5 * np.pi - 1e-7:
        return np.ones_like(a)
    norm = 1.0 / (np.tan(h) - h) if h > 0.05 else 3.0 / h ** 3
    return np.where(a < h, np.maximum(np.tan(h) - np.tan(np.minimum(a, h)), 0.0) * norm, 0.0)


def irradiance_area(points, normals, matrix, power, colour=(1, 1, 1), shape="SQUARE", size=1.0,
                    size_y=1.0, spread=np.pi, normalize=True, exposure=0.0, grid=96):
    """AREA light, one-sided (emits towards the object's local -Z): (n, 3) irradiance.

    spread = pi: exitance ``area_exitance`` x the exact point-to-polygon form factor.
    spread < pi: radiance (M / pi) x ``spread_profile`` of the emission angle, integrated over
    the part of the light within the spread cone of each receiver (midpoint grid x grid)."""
    from relight_addon.core.geometry.formfactor import point_to_polygon
    p = _rows(points)
    n = _rows(normals, len(p))
    Mx = area_exitance(power, shape, size, size_y, matrix, colour, exposure, normalize)
    if spread >= np.pi - 1e-6:
        poly = area_light_polygon(matrix, shape, size, size_y)
        c, u, v, lu, lv, nrm, rnd = area_light_frame(matrix, shape, size, size_y)
        ff = point_to_polygon(p, n, np.broadcast_to(poly, (len(p),) + poly.shape),
                              np.broadcast_to(nrm, p.shape))
        return ff[:, None] * Mx[None]
    c, u, v, lu, lv, nrm, rnd = area_light_frame(matrix, shape, size, size_y)
    h = 0.5 * spread
    out = np.zeros(len(p))
    g = (np.arange(grid) + 0.5) / grid
    for i in range(len(p)):
        rel = p[i] - c
        z = rel @ nrm
        if z <= 0:
            continue
        fu, fv = rel @ u, rel @ v
        rho = z * np.tan(h)
        u0, u1 = max(fu - rho, -lu / 2), min(fu + rho, lu / 2)
        v0, v1 = max(fv - rho, -lv / 2), min(fv + rho, lv / 2)
        if u0 >= u1 or v0 >= v1:
            continue
        qu = (u0 + (u1 - u0) * g)[:, None]
        qv = (v0 + (v1 - v0) * g)[None, :]
        inside = np.ones((grid, grid), bool)
        if rnd:
            inside = (qu / (lu / 2)) ** 2 + (qv / (lv / 2)) ** 2 <= 1.0
        r_in = np.hypot(qu - fu, qv - fv)
        ang = np.arctan2(r_in, z)
        # vector receiver -> light point, in (u, v, nrm) components
        wu, wv, wn = qu - fu, qv - fv, -z
        t2 = wu * wu + wv * wv + wn * wn
        cos_r = np.maximum((wu * (n[i] @ u) + wv * (n[i] @ v) + wn * (n[i] @ nrm))
                           / np.sqrt(t2), 0.0)
        cos_a = z / np.sqrt(t2)
        f = spread_profile(ang, spread) * inside
        out[i] = (f * cos_r * cos_a / t2).sum() * (u1 - u0) * (v1 - v0) / grid ** 2 / np.pi
    return out[:, None] * Mx[None]


def blackbody_colour(temperature):
    """Light colour of ``use_temperature`` (3,) linear Rec.709, multiplied into ``colour``:
    Planck's law at ``temperature`` (K, clamped to [800, 12000] as Cycles does) through the CIE
    1931 2-degree observer, XYZ -> linear Rec.709 (D65, no adaptation), scaled to luminance 1,
    then negative channels set to 0.  Needs colour-science (for the observer table)."""
    import colour
    T = min(max(float(temperature), 800.0), 12000.0)
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    lam = cmfs.wavelengths * 1e-9
    c1, c2 = 3.741771852e-16, 1.438776877e-2
    planck = c1 / lam ** 5 / np.expm1(c2 / (lam * T))
    xyz = planck @ cmfs.values
    m = np.array([[3.2404542, -1.5371385, -0.4985314],
                  [-0.9692660, 1.8760108, 0.0415560],
                  [0.0556434, -0.2040259, 1.0572252]])
    rgb = m @ xyz
    rgb = rgb / (np.array([0.2126729, 0.7151522, 0.0721750]) @ rgb)
    return np.maximum(rgb, 0.0)


def irradiance_emissive_polygon(points, normals, polygon, strength, colour=(1, 1, 1)):
    """Mesh emission (Emission shader, or Principled "Emission Strength" x "Emission Color"):
    radiance = strength x colour on BOTH sides of the face (exitance pi x strength per side),
    whatever the face's winding.  E = pi S colour x point-to-polygon form factor."""
    from relight_addon.core.geometry.formfactor import point_to_polygon
    p = _rows(points)
    n = _rows(normals, len(p))
    poly = np.asarray(polygon, np.float64)
    ff = point_to_polygon(p, n, np.broadcast_to(poly, (len(p),) + poly.shape))
    return (np.pi * float(strength) * ff)[:, None] * np.asarray(colour, np.float64)[None]
