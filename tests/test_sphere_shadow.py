"""Sphere-set soft shadows (core.relight.sphere_shadow) and sphere fitting (core.relight.spheres).

Truths are independent of the modules: geometric umbra tests (segment against sphere),
analytic solid angles, and Monte Carlo ray-sphere intersection written here.  The error of the
approximation against the real mesh is measured in benchmarks/bench_sphere_shadow.py.
"""
from __future__ import annotations

import numpy as np
import pytest

from relight_addon.core.relight.sphere_shadow import (
    SUN_DISTANCE, bounding_sphere, cap_visibility, may_shadow, sphere_visibility, sun_disk,
    to_local, world_bound)
from relight_addon.core.relight.spheres import fit_spheres, silhouette_sphere


# ------------------------------------------------------------------------------------------
# independent truths
# ------------------------------------------------------------------------------------------

def _frame(w):
    a = np.array([1.0, 0, 0]) if abs(w[0]) < 0.9 else np.array([0, 1.0, 0])
    u = np.cross(w, a)
    u /= np.linalg.norm(u)
    return u, np.cross(w, u)


def segment_sphere_distance(p, q, c):
    """Distance from the centre ``c`` (3,) to the segments p (n, 3) -> q (3,)."""
    d = q - p
    t = np.clip(np.einsum("ij,ij->i", c - p, d) / np.einsum("ij,ij->i", d, d), 0, 1)
    return np.linalg.norm(p + t[:, None] * d - c, axis=1)


def mc_disk_visibility(p, lamp, lamp_radius, c, radius, n, rng):
    """Fraction of a disk lamp (facing the receiver ``p``, uniform by area) whose segments from
    ``p`` miss the sphere (c, radius): n random rays, analytic ray-sphere intersection."""
    axis = lamp - p
    u, v = _frame(axis / np.linalg.norm(axis))
    r = lamp_radius * np.sqrt(rng.random(n))
    phi = 2 * np.pi * rng.random(n)
    q = lamp + (r * np.cos(phi))[:, None] * u + (r * np.sin(phi))[:, None] * v
    d = q - p
    length = np.linalg.norm(d, axis=1)
    d /= length[:, None]
    oc = c - p
    b = d @ oc
    disc = b * b - (oc @ oc - radius * radius)
    s = np.sqrt(np.maximum(disc, 0))
    hit = (disc >= 0) & (b - s < length) & (b + s > 0)
    return 1.0 - hit.mean()


def cap_solid_angle(sin_theta):
    return 2 * np.pi * (1 - np.sqrt(1 - sin_theta ** 2))


# ------------------------------------------------------------------------------------------
# (1) point lamp: hard shadow = the geometric umbra
# ------------------------------------------------------------------------------------------

def test_point_lamp_hard_shadow_matches_segment_sphere_test():
    rng = np.random.default_rng(1)
    lamp = np.array([0.4, -0.3, 4.0])
    centre, radius = np.array([0.0, 0.2, 1.5]), 0.5
    p = np.column_stack([rng.uniform(-2, 2, 4000), rng.uniform(-2, 2, 4000), np.zeros(4000)])
    dist = segment_sphere_distance(p, lamp, centre)
    # 0.5 % of R off the umbra's edge is >= 7e-4 rad of axis angle here (receivers within 3.3 m
    # of the centre): well beyond the module's smallest penumbra width (1e-4 rad)
    inside, outside = dist < 0.995 * radius, dist > 1.005 * radius
    assert inside.sum() > 200 and outside.sum() > 2000      # both sides well represented
    v = cap_visibility(p, lamp, 0.0, centre, radius)
    assert np.all(v[inside] == 0.0)
    assert np.all(v[outside] == 1.0)
    # same through sphere_visibility, and a second disjoint sphere shadows its own umbra
    c2, r2 = np.array([-1.0, -1.0, 1.0]), 0.3
    v2 = sphere_visibility(p, lamp, 0.0, [centre, c2], [radius, r2])
    in2 = segment_sphere_distance(p, lamp, c2) < 0.995 * r2
    out2 = segment_sphere_distance(p, lamp, c2) > 1.005 * r2
    assert in2.sum() > 50
    assert np.all(v2[inside | in2] == 0.0)
    assert np.all(v2[outside & out2] == 1.0)


# ------------------------------------------------------------------------------------------
# (2) caps that contain one another: exact values
# ------------------------------------------------------------------------------------------

@pytest.mark.parametrize("offset", [0.0, 0.05, 0.1])
def test_lamp_fully_covered_is_black(offset):
    # lamp cap: sin = 0.5/10 (2.9 deg); sphere cap: sin = 1/5 (11.5 deg), axes <= 0.1/5 rad apart
    p = np.zeros((1, 3))
    v = cap_visibility(p, np.array([0, 0, 10.0]), 0.5, np.array([offset, 0, 5.0]), 1.0)
    assert v[0] == 0.0


@pytest.mark.parametrize("offset", [0.0, 0.3, 0.7])
def test_sphere_inside_lamp_cap_hides_its_solid_angle(offset):
    # lamp: r 2 at 10 m (sin 0.2); sphere: r 0.1 at 5 m (sin 0.02); offsets keep it inside
    p = np.zeros((1, 3))
    c = np.array([offset, 0.0, 0.0])
    c[2] = np.sqrt(25.0 - offset ** 2)                     # |c - p| = 5 exactly
    gamma = np.arcsin(offset / 5.0)
    assert gamma < np.arcsin(0.2) - np.arcsin(0.02)
    expected = 1 - cap_solid_angle(0.02) / cap_solid_angle(0.2)
    v = cap_visibility(p, np.array([0, 0, 10.0]), 2.0, c, 0.1)
    assert v[0] == pytest.approx(expected, abs=1e-9)
    assert expected == pytest.approx(1 - 0.01, abs=2e-4)   # (0.02 / 0.2)^2 in the small limit


def test_disjoint_caps_do_not_shadow():
    # lamp cap 5.7 deg, sphere cap 11.5 deg, axes 30 deg apart
    p = np.zeros((1, 3))
    g = np.radians(30)
    v = cap_visibility(p, np.array([0, 0, 5.0]), 0.5, 5 * np.array([np.sin(g), 0, np.cos(g)]), 1.0)
    assert v[0] == 1.0


# ------------------------------------------------------------------------------------------
# (3) partial overlap against Monte Carlo ray-sphere truth
# ------------------------------------------------------------------------------------------
#
# In the partial-overlap zone |theta_L - theta_O| < gamma < theta_L + theta_O the module ramps the
# overlap with a smoothstep in gamma instead of the lens-shaped area of two caps (equal caps half
# overlapping: the lens covers 39.1 % of a cap, smoothstep(0.5) says 50 %).  Measured here (11 axis
# angles evenly spread over the zone, ends included, 20k rays each, seed 7) the |error| against
# a disk lamp facing the receiver is, for the five configurations below in order:
#     mean 0.051, 0.026, 0.004, 0.039, 0.026;  max 0.120, 0.061, 0.010, 0.096, 0.060
# (seeds 0-9: means within 0.004, maxima within 0.012 of these).  It is largest when the two caps
# have similar sizes; the approximation is too dark near full overlap (error < 0) and slightly
# too light near the touching end.  Bounds = measured x ~1.35; the Monte Carlo standard error is
# <= 0.5 / sqrt(20000) = 0.0035 per point.

MC_RAYS = 20_000
PARTIAL = [  # lamp radius, sphere radius, sphere distance (lamp at 3 m), MAE bound, max bound
    (0.5, 0.3, 1.5, 0.070, 0.165),
    (0.2, 0.3, 1.5, 0.036, 0.085),
    (0.5, 0.1, 1.5, 0.007, 0.016),
    (0.5, 0.5, 2.0, 0.055, 0.130),
    (0.3, 0.3, 1.0, 0.036, 0.085),
]


@pytest.mark.parametrize("lamp_r,radius,dist,mae_bound,max_bound", PARTIAL)
def test_partial_overlap_against_monte_carlo(lamp_r, radius, dist, mae_bound, max_bound):
    rng = np.random.default_rng(7)
    p = np.zeros(3)
    lamp = np.array([0.0, 0.0, 3.0])
    th_l, th_o = np.arcsin(lamp_r / 3.0), np.arcsin(radius / dist)
    errs = []
    for x in np.linspace(0.0, 1.0, 11):
        g = abs(th_l - th_o) + x * 2 * min(th_l, th_o)
        c = dist * np.array([np.sin(g), 0.0, np.cos(g)])
        approx = cap_visibility(p[None], lamp, lamp_r, c, radius)[0]
        errs.append(approx - mc_disk_visibility(p, lamp, lamp_r, c, radius, MC_RAYS, rng))
    errs = np.abs(errs)
    assert errs.mean() < mae_bound
    assert errs.max() < max_bound
    # outside the zone the model is exact up to the Monte Carlo noise (and the disk/cap shape)
    for g in (abs(th_l - th_o) * 0.5, (th_l + th_o) * 1.3):
        c = dist * np.array([np.sin(g), 0.0, np.cos(g)])
        approx = cap_visibility(p[None], lamp, lamp_r, c, radius)[0]
        assert approx == pytest.approx(
            mc_disk_visibility(p, lamp, lamp_r, c, radius, MC_RAYS, rng), abs=0.015)


def test_sun_disk_geometry_and_shadow():
    direction = np.array([1.0, 0.0, -1.0])
    pos, r = sun_disk(direction, np.radians(2.0))
    assert np.allclose(pos, SUN_DISTANCE * np.array([-1, 0, 1]) / np.sqrt(2))
    assert np.arctan(r / SUN_DISTANCE) == pytest.approx(np.radians(1.0), rel=1e-12)
    assert sun_disk(direction, -1.0)[1] == 0.0
    # a sphere of radius 0.2 at 1 m subtends 11.5 deg >> the sun's 1 deg: a sharp umbra
    c = np.array([0.0, 0.0, 1.0])
    ray = -direction / np.linalg.norm(direction)
    p = np.array([c - 1.0 * ray, c - 1.0 * ray + [0, 0.5, 0]])
    v = cap_visibility(p, pos, r, c, 0.2)
    assert v[0] == 0.0 and v[1] == 1.0


# ------------------------------------------------------------------------------------------
# (4) spheres that cannot shadow
# ------------------------------------------------------------------------------------------

def test_sphere_behind_lamp_or_below_receiver_never_shadows():
    p = np.array([[0.0, 0.0, 0.0], [0.2, 0.1, 0.0]])
    lamp = np.array([0.0, 0.0, 2.0])
    # on the axis but beyond the lamp (its cap contains the lamp's from the receiver)
    assert np.all(cap_visibility(p, lamp, 0.3, np.array([0, 0, 4.0]), 1.0) == 1.0)
    # below the receivers' floor, right under them
    assert np.all(cap_visibility(p, lamp, 0.3, np.array([0, 0, -1.0]), 0.9) == 1.0)
    # both at once through the product
    v = sphere_visibility(p, lamp, 0.3, [[0, 0, 4.0], [0, 0, -1.0]], [1.0, 0.9])
    assert np.all(v == 1.0)
    # control: the same sphere between receiver and lamp does shadow
    assert np.all(cap_visibility(p, lamp, 0.3, np.array([0, 0, 1.0]), 0.5) < 0.5)


def test_to_local_inverts_the_matrix():
    m = np.eye(4)
    a = np.radians(30)
    m[:3, :3] = [[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]]
    m[:3, :3] *= 2.0
    m[:3, 3] = [1.0, -2.0, 0.5]
    local = np.array([[0.1, 0.2, 0.3], [-1.0, 0.0, 2.0]])
    world = local @ m[:3, :3].T + m[:3, 3]
    assert np.allclose(to_local(world, m), local, atol=1e-12)


# ------------------------------------------------------------------------------------------
# (5) fitting
# ------------------------------------------------------------------------------------------

def uv_sphere(radius=1.0, n_lat=32, n_lon=64):
    th = np.linspace(0, np.pi, n_lat + 1)
    ph = np.linspace(0, 2 * np.pi, n_lon + 1)
    T, P = np.meshgrid(th, ph, indexing="ij")
    v = radius * np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1)
    a, b, c, d = v[:-1, :-1], v[1:, :-1], v[1:, 1:], v[:-1, 1:]
    tri = np.concatenate([np.stack([a, b, c], -2).reshape(-1, 3, 3),
                          np.stack([a, c, d], -2).reshape(-1, 3, 3)])
    return tri           # pole triangles are degenerate (zero area): never sampled


def box(lo, hi):
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    v = np.array([[x, y, z] for z in (lo[2], hi[2]) for y in (lo[1], hi[1])
                  for x in (lo[0], hi[0])])
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    return np.array([v[[a, b, c]] for a, b, c, d in quads] + [v[[a, c, d]] for a, b, c, d in quads])


def test_one_sphere_on_a_sphere_mesh():
    # 5000 samples: the centroid's noise is ~1/sqrt(3 * 5000) = 0.008 per axis; the faceted
    # surface lies within 1 - cos(pi / 64) = 0.0012 of the unit sphere, so the sphere of its
    # volume has radius 1 within that
    c, r = fit_spheres(uv_sphere(), n=1, seed=3, samples_per_sphere=5000)
    assert c.shape == (1, 3) and r.shape == (1,)
    assert np.linalg.norm(c[0]) < 0.04
    assert r[0] == pytest.approx(1.0, abs=0.005)


def test_spheres_on_a_box_lie_inside_and_are_deterministic():
    lo, hi = np.array([1.0, -0.5, 0.0]), np.array([3.0, 0.5, 0.5])
    tri = box(lo, hi)
    c, r = fit_spheres(tri, n=16, seed=5)
    assert 1 <= len(c) <= 16 and len(r) == len(c)
    assert np.all(c >= lo - 1e-12) and np.all(c <= hi + 1e-12)   # centroids of inside points
    # the spheres fill the box: together they have its volume (each its cluster's share)
    assert (4 / 3 * np.pi * r ** 3).sum() == pytest.approx(np.prod(hi - lo), rel=1e-6)
    assert np.all(r > 0) and np.all(r < np.linalg.norm(hi - lo))
    # the samples of a cluster are near its centre: a few times the surface-per-sphere scale
    area = 2 * (2 * 1 + 2 * 0.5 + 1 * 0.5)
    assert np.all(r < 2 * np.sqrt(area / len(r)))
    c2, r2 = fit_spheres(tri, n=16, seed=5)
    assert np.array_equal(c, c2) and np.array_equal(r, r2)
    c3, _ = fit_spheres(tri, n=16, seed=6)
    assert not np.array_equal(c, c3)


def test_fit_follows_translation():
    """Spheres are fitted in object coordinates and moved with the object: fitting the moved
    mesh gives the moved spheres."""
    tri = box([0, 0, 0], [0.6, 0.4, 0.5])
    shift = np.array([2.0, -1.0, 0.25])
    c, r = fit_spheres(tri, n=8, seed=2)
    c2, r2 = fit_spheres(tri + shift, n=8, seed=2)
    assert np.allclose(c2, c + shift, atol=1e-9) and np.allclose(r2, r, atol=1e-9)


def test_a_mesh_without_volume_is_paved_like_the_seed():
    """A single quad has no inside: its spheres lie on it (seed 002's surface paving)."""
    quad = np.array([[[0, 0, 0], [1, 0, 0], [1, 1, 0]], [[0, 0, 0], [1, 1, 0], [0, 1, 0]]], float)
    c, r = fit_spheres(quad, n=4, seed=1)
    assert len(c) == 4 and np.allclose(c[:, 2], 0.0) and np.all((r > 0.1) & (r < 0.5))


def test_fit_rejects_an_empty_surface():
    with pytest.raises(ValueError):
        fit_spheres(np.zeros((2, 3, 3)), n=4)


# ------------------------------------------------------------------------------------------
# (6) degenerate inputs: finite values in [0, 1]
# ------------------------------------------------------------------------------------------

DEGENERATE = {
    # name: (points, lamp_pos, lamp_radius, centre, radius)
    "receiver at the sphere centre": ([[0, 0, 1.0]], [0, 0, 5.0], 0.2, [0, 0, 1.0], 1.0),
    "receiver on the sphere surface": ([[0, 0, 0.0]], [0, 0, 5.0], 0.2, [0, 0, 1.0], 1.0),
    "point lamp": ([[0, 0, 0.0], [3, 0, 0]], [0, 0, 5.0], 0.0, [0, 0, 1.0], 0.5),
    "lamp at the receiver": ([[0, 0, 0.0]], [0, 0, 0.0], 0.2, [0, 0, 1.0], 0.5),
    "point lamp at the receiver": ([[0, 0, 0.0]], [0, 0, 0.0], 0.0, [0, 0, 1.0], 0.5),
    "lamp inside the sphere": ([[0, 0, 0.0]], [0, 0, 1.0], 0.1, [0, 0, 1.0], 0.5),
    "huge distances": ([[1e5, -1e5, 0.0]], [0, 0, 1e5], 1e3, [0, 0, 5e4], 1e4),
    "sun": ([[0, 0, 0.0]], *sun_disk([0, 0, -1.0], np.radians(0.5)), [0, 0, 1.0], 0.1),
    "tiny sphere": ([[0, 0, 0.0]], [0, 0, 5.0], 0.2, [0, 0, 1.0], 1e-9),
    "tiny sphere, point lamp": ([[0, 0, 0.0]], [0, 0, 5.0], 0.0, [0, 0, 1.0], 1e-9),
    "tiny lamp": ([[0, 0, 0.0]], [0, 0, 5.0], 1e-9, [0, 0, 1.0], 0.5),
    "zero-radius sphere": ([[0, 0, 0.0]], [0, 0, 5.0], 0.2, [0, 0, 1.0], 0.0),
    "huge lamp": ([[0, 0, 0.0]], [0, 0, 5.0], 50.0, [0, 0, 1.0], 0.5),
}


@pytest.mark.parametrize("name", list(DEGENERATE))
def test_degenerate_inputs_are_finite(name):
    pts, lamp, lamp_r, c, r = DEGENERATE[name]
    with np.errstate(all="raise"):
        v = cap_visibility(np.array(pts, float), np.array(lamp, float), lamp_r,
                           np.array(c, float), r)
        vs = sphere_visibility(np.array(pts, float), np.array(lamp, float), lamp_r,
                               [c, c], [r, r])
    assert np.all(np.isfinite(v)) and np.all((v >= 0) & (v <= 1))
    assert np.all(np.isfinite(vs)) and np.all((vs >= 0) & (vs <= 1))


def test_sphere_visibility_without_spheres_is_one():
    v = sphere_visibility(np.zeros((3, 3)), np.array([0, 0, 1.0]), 0.1,
                          np.zeros((0, 3)), np.zeros(0))
    assert v.shape == (3,) and np.all(v == 1.0)


def test_receiver_inside_a_sphere_sees_nothing():
    lamp = np.array([0, 0, 5.0])
    p = np.array([[0, 0, 1.0], [0, 0, 1.5], [0.3, 0, 1.2]])
    assert np.all(cap_visibility(p, lamp, 0.2, np.array([0, 0, 1.0]), 1.0) == 0.0)


def test_silhouette_rule_counts_less_twice_what_aligned_spheres_hide():
    """Two spheres one behind the other subtend the same cap from the receiver: together they
    hide exactly what one hides.  The plain product counts it twice; the silhouette rule (the
    spheres independent within the part of the lamp the object can hide) much less."""
    p = np.zeros((1, 3))
    lamp, lamp_r = np.array([0, 0, 4.0]), 1.5                    # a large lamp
    centres, radii = np.array([[0, 0, 1.0], [0, 0, 2.0]]), np.array([0.2, 0.4])
    one = 1 - cap_visibility(p, lamp, lamp_r, centres[0], radii[0])[0]
    prod = 1 - sphere_visibility(p, lamp, lamp_r, centres, radii)[0]
    hull = (centres[0], 0.22)            # a silhouette a little larger than their common cap
    rule = 1 - sphere_visibility(p, lamp, lamp_r, centres, radii, hull)[0]
    assert prod == pytest.approx(1 - (1 - one) ** 2)
    assert one <= rule < prod and (rule - one) < 0.5 * (prod - one)


def test_silhouette_sphere_of_a_cube():
    """Cauchy: a convex body's mean projected area is a quarter of its surface area (a unit
    cube: 1.5, so pi r^2 = 1.5); centred on the cube's centre."""
    c, r = silhouette_sphere(box([1, 2, 3], [2, 3, 4]))
    assert np.allclose(c, [1.5, 2.5, 3.5]) and np.pi * r * r == pytest.approx(1.5)


def test_silhouette_rule_agrees_with_the_product_for_a_small_lamp():
    rng = np.random.default_rng(4)
    p = np.column_stack([rng.uniform(-1, 1, 400), rng.uniform(-1, 1, 400), np.zeros(400)])
    centres = rng.normal(0, 0.15, (8, 3)) + [0, 0, 1.0]
    radii = rng.uniform(0.05, 0.15, 8)
    hull = (np.array([0, 0, 1.0]), 0.3)
    a = sphere_visibility(p, [0.3, 0, 3.0], 0.01, centres, radii)
    b = sphere_visibility(p, [0.3, 0, 3.0], 0.01, centres, radii, hull)
    assert np.abs(a - b).max() < 0.02 and (a < 0.5).sum() > 10


def test_settled_images_are_dilated_across_uv_seams():
    """A settled shadow image is filtered bilinearly by the material: the texels around a UV
    island must carry the island's edge values (as the maps do), not the fill's 1, or a fully
    shadowed island shows a light rim.  Island: the middle half of a 32^2 image, V = 0.2."""
    from relight_addon.core.relight.maps import SEAM_PIXELS
    from relight_addon.core.relight.settled import visibility_images
    from relight_addon.core.texture.mapping import rasterize_patches
    a, b, c, d = [0.25, 0.25], [0.75, 0.25], [0.75, 0.75], [0.25, 0.75]
    tm = rasterize_patches(np.array([[a, b, c, c], [a, c, d, d]], float), [0, 0], [(32, 32)])
    cov = tm.images[0].coverage
    V = np.full((tm.n_texels, 2), 0.2)
    V[:, 1] = 1.0                              # a second lamp the object does not hide
    (img,) = visibility_images(tm, V)
    assert img.shape == (32, 32, 2) and img.dtype == np.float32
    rows, cols = np.nonzero(cov)
    r0, r1, c0, c1 = rows.min(), rows.max(), cols.min(), cols.max()
    ring = np.zeros_like(cov)
    ring[r0 - SEAM_PIXELS:r1 + SEAM_PIXELS + 1, c0 - SEAM_PIXELS:c1 + SEAM_PIXELS + 1] = True
    ring &= ~cov
    np.testing.assert_allclose(img[cov, 0], 0.2, atol=1e-6)
    np.testing.assert_allclose(img[ring, 0], 0.2, atol=1e-6)      # dilated, not 1
    far = ~cov & ~ring
    assert far.any() and np.all(img[far, 0] == 1.0)
    assert np.all(img[..., 1] == 1.0)


# ------------------------------------------------------------------------------------------
# (5) the reach test the relit materials branch on (sphere_nodes: out of reach, no sphere is
#     evaluated and V is taken as 1)
# ------------------------------------------------------------------------------------------

def _random_set(rng, m):
    centres = rng.normal(size=(m, 3)) * 0.3 + [0.0, 0.0, 1.0]
    return centres, rng.uniform(0.02, 0.3, m)


def test_bounding_sphere_holds_every_sphere():
    rng = np.random.default_rng(3)
    for m in (1, 2, 7, 64):
        c, r = _random_set(rng, m)
        mid, big = bounding_sphere(c, r)
        assert np.all(np.linalg.norm(c - mid, axis=1) + r <= big)
        assert big <= 1.01 * (np.linalg.norm(c - mid, axis=1) + r).max() + 1e-6   # not loose


@pytest.mark.parametrize("lamp_radius", [0.0, 0.01, 0.3, 1.5])
def test_out_of_reach_no_sphere_shadows(lamp_radius):
    """Where may_shadow is False the twin's V is exactly 1 (what the materials show there) and
    no ray from the point to the lamp's disk touches a sphere (Monte Carlo, analytic
    ray-sphere tests); the test culls most of a room and keeps the whole shadow."""
    rng = np.random.default_rng(int(lamp_radius * 100) + 11)
    culled = shadowed = 0
    for trial in range(40):
        c, r = _random_set(rng, int(rng.integers(1, 24)))
        bound = bounding_sphere(c, r)
        p = np.column_stack([rng.uniform(-3, 3, 3000), rng.uniform(-3, 3, 3000),
                             rng.uniform(-0.5, 2.5, 3000)])
        lamp = rng.normal(size=3) * 1.5 + [0.0, 0.0, 3.0]
        v = sphere_visibility(p, lamp, lamp_radius, c, r, hull=(bound[0], 0.7 * bound[1]))
        out = ~may_shadow(p, lamp, lamp_radius, bound)
        assert np.all(v[out] == 1.0)
        culled += out.sum()
        shadowed += (v < 1.0).sum()
        if trial < 4 and lamp_radius > 0:            # the geometry itself, not the twin
            for i in rng.choice(np.flatnonzero(out), min(40, int(out.sum())), replace=False):
                for cj, rj in zip(c, r):
                    assert mc_disk_visibility(p[i], lamp, lamp_radius, cj, rj, 200, rng) == 1.0
    assert culled > 0.25 * 40 * 3000 and shadowed > 1000


def test_reach_in_world_space_holds_the_object_frame_s_shadow():
    """The materials test the reach in world space (world_bound) and evaluate the spheres in the
    object's frame: rotated and unevenly scaled, every point the object's frame shadows passes."""
    rng = np.random.default_rng(5)
    culled = 0
    for trial in range(30):
        c, r = _random_set(rng, int(rng.integers(1, 16)))
        bound = bounding_sphere(c, r)
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        w, x, y, z = q
        rot = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
        scale = rng.uniform(0.3, 2.0, 3)
        m = np.eye(4)
        m[:3, :3] = rot * scale
        m[:3, 3] = rng.normal(size=3)
        p = rng.uniform(-4, 4, (3000, 3))
        lamp, lamp_r = rng.normal(size=3) * 2 + [0, 0, 4.0], rng.choice([0.0, 0.2, 1.0])
        v = sphere_visibility(to_local(p, m), to_local(lamp[None], m)[0],
                              lamp_r / scale.mean(), c, r)
        centre, radius, grow = world_bound(bound, m)
        out = ~may_shadow(p, lamp, lamp_r * grow, (centre, radius))
        assert np.all(v[out] == 1.0), trial
        culled += out.sum()
    assert culled > 0.3 * 30 * 3000
