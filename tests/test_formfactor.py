"""Unoccluded form factors (core.geometry.formfactor) and patch sampling (core.geometry.sampling).

References used here, all independent of the code under test:
  * closed forms from Howell's catalogue (point to parallel rectangle, C-11 parallel rectangles,
    C-14 perpendicular rectangles with a common edge, coaxial parallel disks);
  * pyviewfactor (double contour integral, SA-30 kernel) for random rectangle pairs;
  * brute-force double Gauss integration of cos cos / (pi r^2) over both patches.

Conventions: ``patch_to_patch(recv, src)`` is F(recv -> src), averaged over the receiver's area.
``pyviewfactor.compute_viewfactor(cell1, cell2)`` returns F(cell2 -> cell1), normalised by the
area of cell2 and with both cells' normals (right-handed winding) facing each other, so
F(recv -> src) = compute_viewfactor(src_cell, recv_cell).

The references and the pair generators (``facing_pairs``, ``straddling_pairs``) are in
``helpers/formfactors.py``, shared with ``benchmarks/bench_formfactor.py``.
"""
from __future__ import annotations

import numpy as np
import pytest

from relight_addon.core.geometry.formfactor import patch_to_patch, point_to_polygon
from relight_addon.core.geometry.sampling import (area_uniform_uv, quadrature, random_points,
                                                  stratified_unit_square)
from relight_addon.core.scene import bilinear_point, quad_area_normal, quads_from_boxes

from helpers.formfactors import (brute_force_ff, coaxial_disks, dedupe, facing_pairs,
                                 howell_c11, howell_c14, howell_point_to_rectangle, polygon_rule,
                                 pvf_ff, random_rotation, rectangle, relative_errors,
                                 straddling_pairs, visible_parts)


# ------------------------------------------------------------------------------------------
# Analytic values
# ------------------------------------------------------------------------------------------
UNIT = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)  # normal +z


def test_closed_forms_match_catalogue_values():
    assert howell_c11(1.0, 1.0, 1.0) == pytest.approx(0.199825, abs=5e-7)
    assert howell_c14(1.0, 1.0, 1.0) == pytest.approx(0.200044, abs=5e-7)
    assert coaxial_disks(1.0, 1.0, 1.0) == pytest.approx(0.381966, abs=5e-7)
    assert howell_point_to_rectangle(1.0, 1.0, 1.0) == pytest.approx(0.138532, abs=5e-7)
    # Reciprocity of the C-14 closed form: w F(w->h) = h F(h->w).
    assert 0.7 * howell_c14(0.7, 1.9, 1.3) == pytest.approx(1.9 * howell_c14(1.9, 0.7, 1.3), rel=1e-12)


def test_parallel_unit_squares():
    top = UNIT[[0, 3, 2, 1]] + [0, 0, 1]  # facing down
    assert patch_to_patch(UNIT[None], top[None], 8)[0] == pytest.approx(0.199825, abs=1e-6)


def test_perpendicular_unit_squares_common_edge():
    wall = np.array([[0, 0, 0], [0, 1, 0], [0, 1, 1], [0, 0, 1]], float)  # x = 0, normal +x
    assert quad_area_normal(wall)[1] == pytest.approx([1, 0, 0])
    assert patch_to_patch(UNIT[None], wall[None], 8)[0] == pytest.approx(0.200044, abs=1e-6)


def test_point_to_corner_aligned_unit_square():
    top = UNIT[[0, 3, 2, 1]] + [0, 0, 1]
    f = point_to_polygon(np.zeros((1, 3)), [[0, 0, 1.0]], top[None], [[0, 0, -1.0]])
    assert f[0] == pytest.approx(0.138532, abs=1e-6)


def test_point_to_parallel_rectangle_random_sizes():
    rng = np.random.default_rng(3)
    n = 200
    a, b, c = rng.uniform(0.05, 5, n), rng.uniform(0.05, 5, n), rng.uniform(0.05, 5, n)
    rot = np.array([random_rotation(rng) for _ in range(n)])
    origin = rng.uniform(-10, 10, (n, 3))
    local = np.zeros((n, 4, 3))
    local[:, 1, 0] = a
    local[:, 2, 0], local[:, 2, 1] = a, b
    local[:, 3, 1] = b
    local[..., 2] = c[:, None]
    local = local[:, [0, 3, 2, 1]]  # facing -z, towards the point
    poly = origin[:, None] + np.einsum("nij,nkj->nki", rot, local)
    normals = rot[:, :, 2]
    f = point_to_polygon(origin, normals, poly, -normals)
    np.testing.assert_allclose(f, howell_point_to_rectangle(a, b, c), rtol=1e-10)


def test_coaxial_disks_via_point_to_polygon():
    """Disks as 512-gons with the disk's area; receiver integrated over radius (axisymmetric)."""
    nv = 512
    s, w = np.polynomial.legendre.leggauss(24)
    s, w = 0.5 * (s + 1), 0.5 * w  # s = (r / r1)^2 is area-uniform on the receiver disk
    for r1, r2, h in [(1.0, 1.0, 1.0), (0.5, 2.0, 1.3), (2.0, 0.3, 0.7), (1.0, 1.5, 0.2)]:
        rc = r2 * np.sqrt(2 * np.pi / (nv * np.sin(2 * np.pi / nv)))  # equal-area polygon
        ang = -2 * np.pi * np.arange(nv) / nv  # clockwise from above: faces -z
        src = np.stack([rc * np.cos(ang), rc * np.sin(ang), np.full(nv, h)], axis=1)
        r = r1 * np.sqrt(s)
        pts = np.stack([r, np.zeros_like(r), np.zeros_like(r)], axis=1)
        f = point_to_polygon(pts, np.tile([0, 0, 1.0], (len(r), 1)), np.tile(src, (len(r), 1, 1)),
                             np.tile([0, 0, -1.0], (len(r), 1)))
        expected = coaxial_disks(r1, r2, h)
        assert w @ f == pytest.approx(expected, rel=2e-5), (r1, r2, h)
    assert coaxial_disks(1.0, 1.0, 1.0) == pytest.approx(0.381966, abs=1e-6)


def test_parallel_rectangles_c11_random():
    rng = np.random.default_rng(11)
    n = 60
    a, b = rng.uniform(0.2, 5, n), rng.uniform(0.2, 5, n)
    c = rng.uniform(0.25, 4, n) * np.maximum(a, b)
    recv = np.zeros((n, 4, 3))
    recv[:, 1, 0], recv[:, 2, 0], recv[:, 2, 1], recv[:, 3, 1] = a, a, b, b
    src = recv[:, [0, 3, 2, 1]].copy()
    src[..., 2] = c[:, None]
    np.testing.assert_allclose(patch_to_patch(recv, src, 8), howell_c11(a, b, c), rtol=1e-4)


def test_perpendicular_rectangles_c14_random():
    """Shared edge: the receiver integrand has a log-type singularity along the common edge, so
    the Gauss rule converges slowly there: m = 8 is within 1e-3, m = 16 within 1e-4 (aspect
    ratios 1:4 .. 4:1).  The hierarchy refines such links; this pins the accuracy down."""
    rng = np.random.default_rng(14)
    n = 60
    w, h, l = rng.uniform(0.5, 2, n), rng.uniform(0.5, 2, n), rng.uniform(0.5, 2, n)
    recv = np.zeros((n, 4, 3))  # z = 0, x in [0, w], y in [0, l], normal +z
    recv[:, 1, 0], recv[:, 2, 0], recv[:, 2, 1], recv[:, 3, 1] = w, w, l, l
    src = np.zeros((n, 4, 3))  # x = 0, y in [0, l], z in [0, h], normal +x
    src[:, 1, 1], src[:, 2, 1], src[:, 2, 2], src[:, 3, 2] = l, l, h, h
    exact = howell_c14(w, h, l)
    np.testing.assert_allclose(patch_to_patch(recv, src, 8), exact, rtol=1e-3)
    np.testing.assert_allclose(patch_to_patch(recv, src, 16), exact, rtol=1e-4)
    # Unit squares happen to be easy for the rule: 1e-11.
    assert patch_to_patch(recv[:1] * 0 + UNIT, np.array([[[0, 0, 0], [0, 1, 0], [0, 1, 1], [0, 0, 1]]]),
                          8)[0] == pytest.approx(howell_c14(1, 1, 1), rel=1e-9)


# ------------------------------------------------------------------------------------------
# pyviewfactor and brute-force oracles
# ------------------------------------------------------------------------------------------
def test_generators_are_well_formed():
    for (recv, src), straddle in ((facing_pairs(), False), (straddling_pairs(), True)):
        _, nr = quad_area_normal(recv)
        _, ns = quad_area_normal(src)
        ds = np.einsum("ijk,ik->ij", src - recv[:, :1], nr)  # source corners vs receiver plane
        dr = np.einsum("ijk,ik->ij", recv - src[:, :1], ns)  # receiver corners vs source plane
        assert np.all(ds.max(1) > 0) and np.all(dr.max(1) > 0)
        assert np.all(ds.min(1) < 0) if straddle else np.all(ds.min(1) > 0) and np.all(dr.min(1) > 0)


def test_brute_force_reference_on_analytic_cases():
    top = UNIT[[0, 3, 2, 1]] + [0, 0, 1]
    assert brute_force_ff(UNIT, top, 24) == pytest.approx(0.199825, abs=1e-6)
    a, b, c = 1.7, 0.6, 0.9
    r = np.array([[0, 0, 0], [a, 0, 0], [a, b, 0], [0, b, 0]])
    s = r[[0, 3, 2, 1]] + [0, 0, c]
    assert brute_force_ff(r, s, 24) == pytest.approx(howell_c11(a, b, c), rel=1e-6)


def test_pyviewfactor_orientation_and_direction():
    pvf = pytest.importorskip("pyviewfactor")  # noqa: F841
    top = UNIT[[0, 3, 2, 1]] + [0, 0, 1]
    assert pvf_ff(UNIT, top) == pytest.approx(0.199825, abs=1e-6)
    # Different areas: F(recv -> src) = A_s / A_r F(src -> recv).
    big = np.array([[0, 0, 1], [0, 2, 1], [1, 2, 1], [1, 0, 1]], float)
    ours = patch_to_patch(np.array([UNIT]), big[None], 8)[0]
    assert pvf_ff(UNIT, big) == pytest.approx(ours, rel=1e-6)
    assert pvf_ff(big, UNIT) == pytest.approx(ours / 2, rel=1e-6)


def test_against_pyviewfactor_random_facing_pairs():
    pytest.importorskip("pyviewfactor")
    recv, src = facing_pairs()
    ref = np.array([pvf_ff(r, s) for r, s in zip(recv, src)])
    assert np.all(ref > 1e-4)
    # The references agree with each other.
    dense = np.array([brute_force_ff(r, s, 16) for r, s in zip(recv[:5], src[:5])])
    np.testing.assert_allclose(dense, ref[:5], rtol=1e-6)
    err = {m: relative_errors(patch_to_patch(recv, src, m), ref) for m in (2, 4, 8)}
    # Measured mean / max: m = 2 0.25 % / 3.5 %, m = 4 3e-5 / 6e-4, m = 8 7e-8 / 2e-6.
    assert err[4].mean() <= 5e-3 and err[4].max() <= 5e-3
    assert err[8].mean() <= 1e-4 and err[8].max() <= 1e-3
    assert err[2].mean() <= 5e-2
    # The "high" preset's per-leaf quadrature meets the 0.5 % mean target on whole patches.
    from relight_addon.core.radiosity.presets import PRESETS
    m_high = PRESETS["high"].quadrature
    assert relative_errors(patch_to_patch(recv, src, m_high), ref).mean() <= 5e-3
    assert err[8].mean() < err[4].mean() < err[2].mean()


def test_straddling_pairs_clip_correctly():
    """Sources partly behind the receiver plane (and receivers partly behind the source plane).

    pyviewfactor alone is wrong here (its double contour integral assumes full mutual
    visibility), so both references integrate the mutually visible parts only."""
    recv, src = straddling_pairs()
    dense = np.array([brute_force_ff(r, s, 24) for r, s in zip(recv, src)])
    assert np.all(dense > 0)
    err8 = relative_errors(patch_to_patch(recv, src, 8), dense)
    err4 = relative_errors(patch_to_patch(recv, src, 4), dense)
    # Receivers cut by the source plane make the receiver integrand kinked: Gauss is slower
    # (measured mean / max: m = 4 0.7 % / 11 %, m = 8 0.2 % / 2.7 %, m = 16 0.03 % / 0.4 %).
    assert err8.mean() <= 5e-3 and err4.mean() <= 2e-2
    # Every pair's receiver point is exact: a dense receiver rule converges to the reference.
    ours_dense = np.array([_receiver_integral(r, s, 24) for r, s in zip(recv, src)])
    np.testing.assert_allclose(ours_dense, dense, rtol=1e-6)
    if pytest.importorskip("pyviewfactor"):
        ref = np.array([pvf_ff(r, s) for r, s in zip(recv[:5], src[:5])])
        np.testing.assert_allclose(ref, dense[:5], rtol=1e-6)


def _receiver_integral(recv, src, m):
    """F(recv -> src) with point_to_polygon integrated over the receiver's visible part only."""
    area_r, nr = quad_area_normal(recv)
    _, ns = quad_area_normal(src)
    vr, _ = visible_parts(recv, src)
    pts, w = polygon_rule(vr, m)
    f = point_to_polygon(pts, np.tile(nr, (len(pts), 1)), np.tile(src, (len(pts), 1, 1)),
                         np.tile(ns, (len(pts), 1)))
    return float(w @ f) / area_r


# ------------------------------------------------------------------------------------------
# Reciprocity and closure
# ------------------------------------------------------------------------------------------
def test_reciprocity_random_pairs():
    recv, src = facing_pairs(40, seed=99)
    # Make some sources triangles and some receivers non-rectangular planar quads.
    src[::3, 3] = src[::3, 2]
    recv[1::3, 2] = recv[1::3, 1] + 0.5 * (recv[1::3, 2] - recv[1::3, 1])  # trapezoid-ish
    ar, _ = quad_area_normal(recv)
    as_, _ = quad_area_normal(src)
    fwd = patch_to_patch(recv, src, 8)
    bwd = patch_to_patch(src, recv, 8)
    np.testing.assert_allclose(ar * fwd, as_ * bwd, rtol=1e-4)


def _inward_box_faces(center, size):
    return quads_from_boxes(center, size)[:, ::-1].copy()  # reversed winding: normals inward


def _split_faces(faces, rng):
    """Each quad face -> two triangles (a, b, c, c), (a, c, d, d) and two planar trapezoids."""
    out = []
    for f in faces:
        a, b, c, d = f
        out += [np.array([a, b, c, c]), np.array([a, c, d, d])]
        s, t = rng.uniform(0.2, 0.8, 2)  # a slanted cut from edge ab to edge dc
        p, q = a + s * (b - a), d + t * (c - d)
        out += [np.array([a, p, q, d]), np.array([p, b, c, q])]
    return np.array(out)


def test_closed_cube_point_sums_to_one():
    rng = np.random.default_rng(5)
    faces = _inward_box_faces([0.3, -0.2, 1.0], [2.0, 1.5, 3.0])
    n = 200
    pts = np.array([0.3, -0.2, 1.0]) + rng.uniform(-0.999, 0.999, (n, 3)) * [1.0, 0.75, 1.5]
    normals = rng.normal(size=(n, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    _, fn = quad_area_normal(faces)

    def total(polys, pn):
        k = len(polys)
        f = point_to_polygon(np.repeat(pts, k, 0), np.repeat(normals, k, 0),
                             np.tile(polys, (n, 1, 1)), np.tile(pn, (n, 1)))
        return f.reshape(n, k).sum(1)

    np.testing.assert_allclose(total(faces, fn), 1.0, atol=1e-9)
    split = _split_faces(faces, rng)
    halves = split.reshape(6, 4, 4, 3)
    tri = halves[:, :2].reshape(-1, 4, 3)
    trap = halves[:, 2:].reshape(-1, 4, 3)
    np.testing.assert_allclose(total(tri, quad_area_normal(tri)[1]), 1.0, atol=1e-9)
    np.testing.assert_allclose(total(trap, quad_area_normal(trap)[1]), 1.0, atol=1e-9)


def test_closed_box_patch_sums():
    rng = np.random.default_rng(6)
    faces = _inward_box_faces([0, 0, 0], [2.0, 1.0, 1.5])
    tri_faces = _split_faces(faces, rng).reshape(6, 4, 4, 3)[:, :2].reshape(-1, 4, 3)
    for sources in (faces, tri_faces):
        # A patch floating inside the box, random orientation, and one lying on a wall.
        rot = random_rotation(rng)
        floating = rectangle([0.1, -0.05, 0.2], rot[:, 0], rot[:, 1], 0.5, 0.3)
        for recv in (floating, faces[0], faces[3]):
            k = len(sources)
            f = patch_to_patch(np.repeat(recv[None], k, 0), sources, 8)
            assert f.sum() <= 1 + 1e-9
            assert f.sum() == pytest.approx(1.0, abs=1e-9)


# ------------------------------------------------------------------------------------------
# Edge cases: never NaN/Inf, zero when nothing is visible
# ------------------------------------------------------------------------------------------
def _ptp(points, normals, polys, src_normals=None):
    f = point_to_polygon(np.atleast_2d(points), np.atleast_2d(normals), np.asarray(polys, float)[None]
                         if np.ndim(polys) == 2 else polys,
                         None if src_normals is None else np.atleast_2d(src_normals))
    assert np.all(np.isfinite(f)) and np.all((f >= 0) & (f <= 1))
    return f


def test_point_on_source_edge_or_corner():
    wall = np.array([[0, 0, 0], [0, 1, 0], [0, 1, 1], [0, 0, 1]], float)  # normal +x
    for p in ([0, 0, 0], [0, 0.5, 0], [0, 1, 1], [0, 0.3, 1], [0, 0.5, 0.5]):
        for n in ([0, 0, 1.0], [1.0, 0, 0], [0.6, 0, 0.8], [-0.6, 0.0, 0.8]):
            _ptp(p, n, wall)
            # The point lies in the source's plane: it sees the source edge-on.
            assert _ptp(p, n, wall, [1.0, 0, 0])[0] == 0.0
    # Points just off the common edge of perpendicular plates see about half the hemisphere.
    f = _ptp([1e-9, 0.5, 0], [0, 0, 1.0], wall, [1.0, 0, 0])[0]
    assert 0.45 < f <= 0.5
    # A receiver point exactly at a vertex of the clipped contour (source crosses the plane).
    tilted = np.array([[0, 0, -1], [0, 1, -1], [0, 1, 1], [0, 0, 1]], float) + [1, 0, 0]
    _ptp([1, 0, 0], [0, 0, 1.0], tilted)
    _ptp([1, 0.5, 0], [0, 0, 1.0], tilted, [1.0, 0, 0])


def test_source_behind_receiver_plane_is_zero():
    below = UNIT - [0, 0, 1]
    assert _ptp([0.5, 0.5, 0], [0, 0, 1.0], below)[0] == 0.0
    assert _ptp([0.5, 0.5, 0], [0, 0, 1.0], below[::-1])[0] == 0.0
    # Touching the plane from behind (one edge on it) is still zero.
    wedge = np.array([[0, 0, 0], [1, 0, 0], [1, 1, -1], [0, 1, -1]], float) + [2, 0, 0]
    assert _ptp([0, 0, 0], [0, 0, 1.0], wedge)[0] == 0.0


def test_source_facing_away_is_zero():
    top_up = UNIT + [0, 0, 1]  # normal +z, the point below sees its back
    assert _ptp([0.5, 0.5, 0], [0, 0, 1.0], top_up, [0, 0, 1.0])[0] == 0.0
    assert _ptp([0.5, 0.5, 0], [0, 0, 1.0], top_up)[0] > 0.2  # two-sided without normals
    assert patch_to_patch(UNIT[None], top_up[None], 4)[0] == 0.0


def test_coplanar_source_is_zero():
    far = UNIT + [2, 0, 0]
    assert _ptp([0.5, 0.5, 0], [0, 0, 1.0], far)[0] == 0.0
    assert _ptp([0.5, 0.5, 0], [0, 0, 1.0], far, [0, 0, 1.0])[0] == 0.0
    # The point lies on the coplanar source itself (e.g. a lamp flush with a ceiling).
    assert _ptp([0.5, 0.5, 0], [0, 0, 1.0], UNIT)[0] == 0.0
    assert _ptp([0.5, 0.5, 0], [0, 0, 1.0], UNIT, [0, 0, 1.0])[0] == 0.0
    rot = random_rotation(np.random.default_rng(0))
    moved = UNIT @ rot.T + [3.3, -1.7, 0.2]
    p = np.array([0.4, 0.6, 0]) @ rot.T + [3.3, -1.7, 0.2]
    assert _ptp(p, rot[:, 2], moved, rot[:, 2])[0] == 0.0
    assert _ptp(p, rot[:, 2], moved)[0] == 0.0
    assert patch_to_patch(UNIT[None], (UNIT * 0.5 + 0.25)[None], 4)[0] == 0.0
    assert patch_to_patch(UNIT[None], (UNIT + [1, 0, 0])[None], 4)[0] == 0.0


def test_degenerate_polygons_are_zero():
    p, n = [0.5, 0.5, 0], [0, 0, 1.0]
    point = np.tile([0.2, 0.3, 1.0], (4, 1))
    segment = np.array([[0, 0, 1], [1, 1, 1], [1, 1, 1], [0, 0, 1]], float)
    collinear = np.array([[0, 0, 1], [0.5, 0.5, 1], [1, 1, 1], [1, 1, 1]], float)
    for poly in (point, segment, collinear):
        assert _ptp(p, n, poly)[0] == pytest.approx(0.0, abs=1e-15)
        assert patch_to_patch(UNIT[None], poly[None], 4)[0] == 0.0
        f = patch_to_patch(poly[None], (UNIT + [0, 0, 1])[None], 4)
        assert np.all(np.isfinite(f)) and f[0] == 0.0
    # Zero-length receiver normal (degenerate receiver point).
    assert np.isfinite(_ptp(p, [0, 0, 0.0], UNIT + [0, 0, 1])[0])


@pytest.mark.parametrize("scale", [1e-6, 1e4])
def test_tiny_and_huge_geometry(scale):
    recv, src = facing_pairs(20, seed=42)
    ref = patch_to_patch(recv, src, 4)
    offset = np.array([0.3, -0.7, 0.2]) * scale
    scaled = patch_to_patch(recv * scale + offset, src * scale + offset, 4)
    assert np.all(np.isfinite(scaled))
    np.testing.assert_allclose(scaled, ref, rtol=1e-8)
    top = UNIT[[0, 3, 2, 1]] + [0, 0, 1]
    assert patch_to_patch(UNIT[None] * scale, top[None] * scale, 8)[0] == pytest.approx(0.199825, abs=1e-6)


def test_small_or_distant_sources_keep_precision():
    # Sources from 1e-6 to 1e4 times smaller than their distance: relative accuracy holds.
    for a in (1e-6, 1e-4, 1e-2, 1.0, 1e2, 1e4):
        poly = np.array([[0, 0, 1], [0, a, 1], [a, a, 1], [a, 0, 1]], float)
        f = _ptp([0, 0, 0], [0, 0, 1.0], poly, [0, 0, -1.0])[0]
        assert f == pytest.approx(howell_point_to_rectangle(a, a, 1.0), rel=1e-6), a
    # Huge scene coordinates far from the origin.
    poly = np.array([[0, 0, 1], [0, 1, 1], [1, 1, 1], [1, 0, 1]], float) + 1e4
    f = _ptp([1e4, 1e4, 1e4], [0, 0, 1.0], poly, [0, 0, -1.0])[0]
    assert f == pytest.approx(0.138532, abs=1e-6)


def test_batch_of_random_garbage_is_finite():
    rng = np.random.default_rng(8)
    n = 5000
    pts = rng.normal(size=(n, 3))
    normals = rng.normal(size=(n, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    polys = rng.normal(size=(n, 4, 3))
    polys[::7, 3] = polys[::7, 2]
    polys[::11, 1] = polys[::11, 0]
    polys[::13] = pts[::13, None]  # collapsed onto the receiver point
    polys[::17, 0] = pts[::17]  # one vertex on the receiver point
    f = point_to_polygon(pts, normals, polys)
    assert np.all(np.isfinite(f)) and np.all((f >= 0) & (f <= 1))
    g = point_to_polygon(pts, normals, polys, rng.normal(size=(n, 3)))
    assert np.all(np.isfinite(g)) and np.all(g <= f + 1e-15)


# ------------------------------------------------------------------------------------------
# Sampling
# ------------------------------------------------------------------------------------------
def _embed(poly2d, rng):
    """Planar 2D polygons (n, 4, 2) placed in 3D by random rigid motions; returns corners and
    the frames (origin, e1, e2) to map points back."""
    n = len(poly2d)
    rot = np.array([random_rotation(rng) for _ in range(n)])
    origin = rng.uniform(-5, 5, (n, 3))
    corners = origin[:, None] + poly2d[..., :1] * rot[:, None, :, 0] + poly2d[..., 1:] * rot[:, None, :, 1]
    return corners, origin, rot[:, :, 0], rot[:, :, 1]


def _shoelace(p):
    x, y = p[:, 0], p[:, 1]
    return 0.5 * (x @ np.roll(y, -1) - y @ np.roll(x, -1))


def _random_convex_quads(n, rng):
    ang = np.sort(rng.uniform(0, 2 * np.pi, (n, 4)), axis=1)
    gaps = np.diff(np.concatenate([ang, ang[:, :1] + 2 * np.pi], axis=1), axis=1)
    ok = gaps.max(axis=1) < np.pi - 0.1  # strictly convex, no tiny sliver
    ang = ang[ok]
    ax = rng.uniform(0.2, 3, (len(ang), 2))
    return np.stack([ax[:, :1] * np.cos(ang), ax[:, 1:] * np.sin(ang)], axis=-1)


def test_quadrature_weights_sum_to_area():
    rng = np.random.default_rng(1)
    quads = _random_convex_quads(300, rng)
    tris = quads.copy()
    tris[:, 3] = tris[:, 2]
    for shapes in (quads, tris):
        corners, origin, e1, e2 = _embed(shapes, rng)
        exact = np.array([_shoelace(dedupe(s)) for s in shapes])
        assert np.all(exact > 0)
        np.testing.assert_allclose(quad_area_normal(corners)[0], exact, rtol=1e-12)
        for m in (1, 2, 3, 4, 8):
            pts, w = quadrature(corners, m)
            assert pts.shape == (len(shapes), m * m, 3) and np.all(w >= 0)
            np.testing.assert_allclose(w.sum(1), exact, rtol=1e-12)
            if m >= 2:  # exact for linear integrands too: the weighted mean is the centroid
                centroid = np.einsum("nk,nki->ni", w, pts) / w.sum(1, keepdims=True)
                x = np.einsum("ni,ni->n", centroid - origin, e1)
                y = np.einsum("ni,ni->n", centroid - origin, e2)
                exp = np.array([_polygon_centroid(dedupe(s)) for s in shapes])
                np.testing.assert_allclose(np.stack([x, y], 1), exp, atol=1e-11)


def _polygon_centroid(p):
    x, y = p[:, 0], p[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cr = x * yn - xn * y
    a = 0.5 * cr.sum()
    return np.array([((x + xn) * cr).sum(), ((y + yn) * cr).sum()]) / (6 * a)


def _clip2d(poly, axis, value, keep_below):
    out = []
    d = (value - poly[:, axis]) if keep_below else (poly[:, axis] - value)
    for i in range(len(poly)):
        j = (i + 1) % len(poly)
        if d[i] >= 0:
            out.append(poly[i])
        if (d[i] >= 0) != (d[j] >= 0):
            out.append(poly[i] + d[i] / (d[i] - d[j]) * (poly[j] - poly[i]))
    return np.array(out).reshape(-1, 2)


def _cell_areas(poly, xs, ys):
    areas = np.zeros((len(xs) - 1, len(ys) - 1))
    for i in range(len(xs) - 1):
        for j in range(len(ys) - 1):
            p = poly
            for axis, v, below in ((0, xs[i], False), (0, xs[i + 1], True),
                                   (1, ys[j], False), (1, ys[j + 1], True)):
                if len(p):
                    p = _clip2d(p, axis, v, below)
            areas[i, j] = _shoelace(p) if len(p) >= 3 else 0.0
    return areas


def _chi2_uniformity(shape2d, points2d, bins=6):
    xs = np.linspace(shape2d[:, 0].min(), shape2d[:, 0].max(), bins + 1)
    ys = np.linspace(shape2d[:, 1].min(), shape2d[:, 1].max(), bins + 1)
    expected = _cell_areas(dedupe(shape2d), xs, ys).ravel()
    expected = expected / expected.sum() * len(points2d)
    counts, _, _ = np.histogram2d(points2d[:, 0], points2d[:, 1], bins=[xs, ys])
    counts = counts.ravel()
    used = expected > 0
    assert counts[~used].sum() == 0
    return float((((counts - expected) ** 2)[used] / expected[used]).sum()), int(used.sum() - 1)


@pytest.mark.parametrize("name", ["triangle", "trapezoid", "quad"])
def test_random_points_area_uniform(name):
    from scipy.stats import chi2

    shape = {"triangle": np.array([[0, 0], [3, 0.5], [1, 2], [1, 2]], float),
             "trapezoid": np.array([[0, 0], [4, 0], [3, 1], [1.5, 1]], float),
             "quad": np.array([[0, 0], [2, -0.5], [2.5, 2], [-0.5, 1]], float)}[name]
    rng = np.random.default_rng(1234)
    n, k = 40, 250
    corners, origin, e1, e2 = _embed(np.tile(shape, (n, 1, 1)), rng)
    pts = random_points(corners, k, np.random.default_rng(99))
    assert pts.shape == (n, k, 3) and np.all(np.isfinite(pts))
    rel = pts - origin[:, None]
    p2 = np.stack([np.einsum("nki,ni->nk", rel, e1), np.einsum("nki,ni->nk", rel, e2)], -1).reshape(-1, 2)
    stat, dof = _chi2_uniformity(shape, p2)
    assert stat < chi2.ppf(1 - 1e-4, dof), (stat, dof)
    # Same test has power: uniform in (u, v) (no Jacobian) is rejected for non-parallelograms.
    u, v = stratified_unit_square(n, k, np.random.default_rng(99))
    naive = bilinear_point(corners[:, None], u, v) - origin[:, None]
    q2 = np.stack([np.einsum("nki,ni->nk", naive, e1), np.einsum("nki,ni->nk", naive, e2)], -1)
    assert _chi2_uniformity(shape, q2.reshape(-1, 2))[0] > chi2.ppf(1 - 1e-4, dof)
    # A half-plane's share of the points matches its share of the area (4 sigma).
    cut = 0.5 * (shape[:, 0].min() + shape[:, 0].max())
    frac = _shoelace(_clip2d(dedupe(shape), 0, cut, True)) / _shoelace(dedupe(shape))
    got = np.mean(p2[:, 0] <= cut)
    assert abs(got - frac) < 4 * np.sqrt(frac * (1 - frac) / len(p2))


def test_area_uniform_uv_maps_into_unit_square_and_is_monotone():
    rng = np.random.default_rng(2)
    quads = _random_convex_quads(50, rng)
    corners, *_ = _embed(quads, rng)
    xi = np.linspace(0, 1, 101)
    u, v = area_uniform_uv(corners, np.tile(0.5, (len(corners), 101)), np.tile(xi, (len(corners), 1)))
    assert np.all((u >= 0) & (u <= 1) & (v >= 0) & (v <= 1))
    assert np.all(np.diff(v, axis=1) >= 0)
    np.testing.assert_allclose(v[:, [0, -1]], np.tile([0.0, 1.0], (len(corners), 1)), atol=1e-12)
