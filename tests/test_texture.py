"""Texel <-> patch/element mapping, element texture means, seam padding and colour spaces."""
import time

import numpy as np
import pytest

from relight_addon.core.radiosity.hierarchy import Hierarchy
from relight_addon.core.scene import SceneData, bilinear_point
from relight_addon.core.texture import colour as col
from relight_addon.core.texture.mapping import (
    dilate_seams, element_means, interpolate_corner_values, inverse_bilinear, inverse_triangle,
    pull_up_means, rasterize_patches, texel_elements, vertex_interpolate, vertex_values)

UNIT = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])


def texel_centres(h, w):
    y, x = np.mgrid[0:h, 0:w]
    return np.stack([(x + 0.5) / w, (y + 0.5) / h], axis=-1).reshape(-1, 2)


def grid_uv(nx, ny, jitter=0.0, seed=0, lo=0.0, hi=1.0):
    gx, gy = np.meshgrid(np.linspace(lo, hi, nx + 1), np.linspace(lo, hi, ny + 1))
    if jitter:
        rng = np.random.default_rng(seed)
        inner_x = (gx > lo) & (gx < hi)
        inner_y = (gy > lo) & (gy < hi)
        gx = gx + rng.uniform(-jitter, jitter, gx.shape) * (hi - lo) / nx * inner_x
        gy = gy + rng.uniform(-jitter, jitter, gy.shape) * (hi - lo) / ny * inner_y
    p = np.stack([gx, gy], -1)
    return np.stack([p[:-1, :-1], p[:-1, 1:], p[1:, 1:], p[1:, :-1]], axis=2).reshape(-1, 4, 2)


def scene_from_uv(uv, z=0.0):
    """A flat scene whose 3D corners are the uv corners (x, y, z), textured by image 0."""
    uv = np.asarray(uv, float)
    corners = np.concatenate([uv, np.full(uv.shape[:2] + (1,), z)], axis=-1)
    p = len(uv)
    return SceneData(corners=corners, rho=0.5, emission=0.0, lamp=-1, uv=uv,
                     image=np.zeros(p, np.int32))


# -- rasterisation --------------------------------------------------------------------------
def test_unit_quad_covers_every_texel_with_texel_centre_params():
    tm = rasterize_patches(UNIT[None], [0], [(16, 16)])
    im = tm[0]
    assert im.coverage.all() and len(im) == 256
    np.testing.assert_array_equal(im.texel_index, np.arange(256))
    np.testing.assert_array_equal(im.patch, 0)
    c = texel_centres(16, 16)
    np.testing.assert_allclose(im.u, c[:, 0], atol=1e-12)
    np.testing.assert_allclose(im.v, c[:, 1], atol=1e-12)


def test_non_square_image_and_shape_with_channels():
    tm = rasterize_patches(UNIT[None], [0], [(8, 20, 3)])
    im = tm[0]
    assert im.coverage.shape == (8, 20) and im.coverage.all()
    np.testing.assert_allclose(np.stack([im.u, im.v], -1), texel_centres(8, 20), atol=1e-12)


@pytest.mark.parametrize("lo,hi,size", [(0.0, 1.0, 16), (0.25, 0.75, 32), (0.1, 0.83, 37)])
def test_two_triangles_share_an_edge_without_gaps_or_double_ownership(lo, hi, size):
    a, b, c, d = [lo, lo], [hi, lo], [hi, hi], [lo, hi]
    uv = np.array([[a, b, c, c], [a, c, d, d]], float)
    tm = rasterize_patches(uv, [0, 0], [(size, size)])
    im = tm[0]
    centres = texel_centres(size, size)
    inside = np.all((centres >= lo) & (centres <= hi), axis=1)
    np.testing.assert_array_equal(im.coverage.reshape(-1), inside)
    assert im.n_overlap == 0
    assert len(np.unique(im.texel_index)) == len(im)
    # Owner on the correct side of the diagonal (either one exactly on it).
    p = centres[im.texel_index]
    side = p[:, 0] - p[:, 1]
    assert np.all(im.patch[side > 1e-12] == 0) and np.all(im.patch[side < -1e-12] == 1)
    # Duffy parameters round-trip for triangles too.
    back = bilinear_point(uv[im.patch], im.u, im.v)
    np.testing.assert_allclose(back, p, atol=1e-12)


def test_quad_mesh_tiles_without_gaps_or_overlap():
    uv = grid_uv(7, 5, jitter=0.3, seed=3)
    tm = rasterize_patches(uv, np.zeros(len(uv), int), [(64, 48)])
    assert tm[0].coverage.all() and tm[0].n_overlap == 0
    back = bilinear_point(uv[tm[0].patch], tm[0].u, tm[0].v)
    np.testing.assert_allclose(back, tm[0].uv, atol=1e-12)


def mixed_mesh_uv(seed=4):
    """Jittered quads, every other one split into two triangles (a, b, c, c), (a, c, d, d)."""
    quads = grid_uv(9, 6, jitter=0.35, seed=seed)
    keep, split = quads[::2], quads[1::2]
    t1 = split[:, [0, 1, 2, 2]]
    t2 = split[:, [0, 2, 3, 3]]
    return np.concatenate([keep, t1, t2])


def test_mixed_mesh_is_chunk_invariant_and_complete():
    uv = mixed_mesh_uv()
    ref = rasterize_patches(uv, np.zeros(len(uv), int), [(50, 70)])
    assert ref[0].coverage.all() and ref[0].n_overlap == 0
    back = bilinear_point(uv[ref[0].patch], ref[0].u, ref[0].v)
    np.testing.assert_allclose(back, ref[0].uv, atol=1e-12)
    for chunk in (1, 97, 1000):          # tiny chunks also split big patches into row bands
        got = rasterize_patches(uv, np.zeros(len(uv), int), [(50, 70)], chunk_pairs=chunk)
        np.testing.assert_array_equal(got[0].texel_index, ref[0].texel_index)
        np.testing.assert_array_equal(got[0].patch, ref[0].patch)
        np.testing.assert_allclose(got[0].u, ref[0].u, atol=1e-15)
        np.testing.assert_allclose(got[0].v, ref[0].v, atol=1e-15)


def test_overlapping_uv_islands_are_counted_and_owned_once():
    uv = np.stack([UNIT, UNIT[[1, 2, 3, 0]]])           # same square, different parametrisation
    tm = rasterize_patches(uv, [0, 0], [(8, 8)])
    assert len(tm[0]) == 64 and len(np.unique(tm[0].texel_index)) == 64
    assert tm[0].n_overlap == 64
    back = bilinear_point(uv[tm[0].patch], tm[0].u, tm[0].v)
    np.testing.assert_allclose(back, tm[0].uv, atol=1e-12)


@pytest.mark.parametrize("mirror", [False, True])
def test_skewed_rotated_quad_inverse_bilinear_round_trip(mirror):
    quad = np.array([[0.0, 0.0], [1.0, 0.1], [0.8, 0.9], [-0.1, 0.6]])   # convex, non-parallelogram
    ang = np.radians(33.0)
    rot = np.array([[np.cos(ang), -np.sin(ang)], [np.sin(ang), np.cos(ang)]])
    quad = 0.5 + 0.45 * (quad - 0.45) @ rot.T
    if mirror:                                       # clockwise uv (mirrored UV island)
        quad = quad[::-1]
    h, w = 64, 80
    tm = rasterize_patches(quad[None], [0], [(h, w)])
    im = tm[0]
    back = bilinear_point(quad[None].repeat(len(im), 0), im.u, im.v)
    np.testing.assert_allclose(back, im.uv, atol=1e-9, rtol=0)
    # Coverage equals a convex-polygon half-plane test (texels closer than 1e-9 to an edge skipped).
    c = texel_centres(h, w)
    ccw = quad if not mirror else quad[::-1]
    e = np.roll(ccw, -1, axis=0) - ccw
    s = (e[None, :, 0] * (c[:, None, 1] - ccw[None, :, 1])
         - e[None, :, 1] * (c[:, None, 0] - ccw[None, :, 0])) / np.linalg.norm(e, axis=1)
    clear = np.all(np.abs(s) > 1e-9, axis=1)
    inside = np.all(s > 0, axis=1)
    np.testing.assert_array_equal(im.coverage.reshape(-1)[clear], inside[clear])
    assert im.coverage.sum() > 500


def test_inverse_bilinear_direct_round_trip_random_convex_quads():
    rng = np.random.default_rng(1)
    n = 2000
    base = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    corners = base[None] + rng.uniform(-0.2, 0.2, (n, 4, 2))
    uv = rng.uniform(0, 1, (n, 2))
    p = bilinear_point(corners, uv[:, 0], uv[:, 1])
    u, v, valid = inverse_bilinear(corners, p)
    assert valid.all()
    np.testing.assert_allclose(u, uv[:, 0], atol=1e-9)
    np.testing.assert_allclose(v, uv[:, 1], atol=1e-9)
    # Parallelograms (k2 == 0, linear case) and exact rectangles.
    par = np.array([[[0, 0], [2, 1], [3, 3], [1, 2]]] * 5, float)
    pts = bilinear_point(par, uv[:5, 0], uv[:5, 1])
    u, v, valid = inverse_bilinear(par, pts)
    assert valid.all()
    np.testing.assert_allclose(np.stack([u, v], -1), uv[:5], atol=1e-12)
    # Triangles (a, b, c, c): Duffy parameters.
    tri = corners[:50, [0, 1, 2, 2]]
    pts = bilinear_point(tri, uv[:50, 0], uv[:50, 1])
    u, v, margin = inverse_triangle(tri, pts)
    assert np.all(margin >= -1e-12)
    np.testing.assert_allclose(bilinear_point(tri, u, v), pts, atol=1e-12)


def test_texels_outside_patches_are_uncovered():
    uv = np.array([[[0.25, 0.25], [0.5, 0.25], [0.5, 0.5], [0.25, 0.5]]])
    tm = rasterize_patches(uv, [0], [(16, 16), (8, 8)])
    cov = tm[0].coverage
    assert cov.sum() == 16 and cov[4:8, 4:8].all()
    assert not tm[1].coverage.any() and len(tm[1]) == 0      # image 1 has no patches
    # Patches without an image (-1) are ignored.
    tm2 = rasterize_patches(uv, [-1], [(16, 16)])
    assert len(tm2[0]) == 0


def test_multiple_images_concatenated_views_and_gather_scatter():
    uv = np.stack([UNIT, UNIT * 0.5])
    tm = rasterize_patches(uv, [0, 1], [(4, 4), (6, 6)])
    assert tm.n_texels == 16 + 9
    np.testing.assert_array_equal(tm.image, [0] * 16 + [1] * 9)
    np.testing.assert_array_equal(tm.patch, [0] * 16 + [1] * 9)
    imgs = [np.random.default_rng(0).random((4, 4, 3)), np.random.default_rng(1).random((6, 6, 3))]
    vals = tm.gather(imgs)
    assert vals.shape == (25, 3)
    out = tm.scatter(vals, fill=-1.0)
    np.testing.assert_array_equal(out[0], imgs[0])
    assert np.all(out[1][tm[1].coverage] == imgs[1][tm[1].coverage])
    assert np.all(out[1][~tm[1].coverage] == -1.0)


# -- elements ---------------------------------------------------------------------------------
def two_level_hierarchy():
    uv = np.array([[[0.0, 0.0], [0.5, 0.0], [0.5, 1.0], [0.0, 1.0]],
                   [[0.5, 0.0], [1.0, 0.0], [1.0, 1.0], [0.5, 1.0]]])
    scene = scene_from_uv(uv)
    hier = Hierarchy(scene)
    first = hier.split([0])                      # patch 0 -> 4 children (2..5)
    hier.split([first[0] + 2])                   # child 2 of patch 0 -> 4 grandchildren
    return scene, hier


def test_element_means_match_direct_means_on_two_level_hierarchy():
    scene, hier = two_level_hierarchy()
    h, w = 24, 32
    tm = rasterize_patches(scene.uv, scene.image, [(h, w)])
    img = np.random.default_rng(5).random((h, w, 3))
    vals = tm.gather([img])
    leaf = texel_elements(hier, tm)
    assert set(leaf) <= set(hier.leaves())
    # Roots are patches: a texel's leaf belongs to its patch.
    np.testing.assert_array_equal(hier.patch[leaf], tm.patch)
    means, counts = element_means(vals, leaf, hier.n, hierarchy=hier)
    # Direct: every element averages the texels of the leaves below it.
    rows, anc = hier.ancestor_pairs(hier.leaves())
    below = {e: set() for e in range(hier.n)}
    leaves = hier.leaves()
    for r, a in zip(rows, anc):
        below[int(a)].add(int(leaves[r]))
    for e in range(hier.n):
        sel = np.isin(leaf, list(below[e]))
        assert counts[e] == sel.sum() > 0
        np.testing.assert_allclose(means[e], vals[sel].mean(axis=0), rtol=1e-12)
    # Texels land in the element containing them in 3D (flat scene: 3D xy == uv).
    corners = hier.corners[leaf][:, :, :2]
    lo, hi = corners.min(axis=1), corners.max(axis=1)
    p = tm[0].uv
    assert np.all((p >= lo - 1e-12) & (p <= hi + 1e-12))


def test_pull_up_consistent_and_empty_elements_inherit():
    scene, hier = two_level_hierarchy()
    tm = rasterize_patches(scene.uv, scene.image, [(16, 16)])
    vals = tm.gather([np.random.default_rng(2).random((16, 16, 3))])
    leaf = texel_elements(hier, tm)
    leaf_means, leaf_counts = element_means(vals, leaf, hier.n)
    m1, c1 = element_means(vals, leaf, hier.n, hierarchy=hier)
    m2, c2 = pull_up_means(hier, leaf_means, leaf_counts)
    np.testing.assert_allclose(m1, m2, rtol=1e-12)
    np.testing.assert_array_equal(c1, c2)
    # Parent = count-weighted mean of its children.
    for e in np.flatnonzero(hier.first_child[: hier.n] >= 0):
        ch = hier.first_child[e] + np.arange(4)
        np.testing.assert_allclose(m1[e], (m1[ch] * c1[ch, None]).sum(0) / c1[ch].sum(), rtol=1e-12)
    # An element finer than the texels: no texel of its own, inherits its parent's mean.
    ids = np.array([leaf[0]])
    for _ in range(3):
        ids = (hier.split(ids)[:, None] + np.arange(4)).ravel()
    leaf = texel_elements(hier, tm)
    m3, c3 = element_means(vals, leaf, hier.n, hierarchy=hier)
    empty = np.flatnonzero(c3 == 0)
    assert len(empty) > 0
    np.testing.assert_allclose(m3[empty], m3[hier.parent[empty]])
    assert np.all(np.isfinite(m3))


# -- smooth display ---------------------------------------------------------------------------
def f_linear(p):
    return np.stack([1.0 + 2.0 * p[..., 0] - 3.0 * p[..., 1] + 0.5 * p[..., 2],
                     0.3 * p[..., 0] + 0.1], axis=-1)


def parallelogram_scene():
    uv = np.array([[[0.1, 0.1], [0.9, 0.1], [0.9, 0.9], [0.1, 0.9]]])
    corners = np.array([[[0.0, 0.0, 0.0], [2.0, 0.5, 0.2], [2.5, 1.5, 0.7], [0.5, 1.0, 0.5]]])
    return SceneData(corners=corners, rho=0.5, emission=0.0, lamp=-1, uv=uv, image=np.zeros(1, int))


def test_vertex_interpolation_reproduces_linear_function():
    scene = parallelogram_scene()
    hier = Hierarchy(scene)
    hier.split(hier.split([0]) + np.arange(4))    # 16 leaves, uniform
    hier.split([hier.leaves()[3]])                # plus a finer corner (non-uniform)
    tm = rasterize_patches(scene.uv, scene.image, [(40, 40)])
    leaves = hier.leaves()
    ids = texel_elements(hier, tm)
    p3 = bilinear_point(scene.corners[tm.patch], tm.u, tm.v)
    # Exact corner values -> exact linear function (bilinear on a parallelogram is affine).
    cv = f_linear(hier.corners[leaves])
    got = interpolate_corner_values(hier, cv, tm, ids)
    np.testing.assert_allclose(got, f_linear(p3), atol=1e-12)
    # Leaf values at centroids: area-weighted corner averages are exact at interior vertices
    # of a uniform region, so texels of leaves whose four corners are interior and regular
    # reproduce the function exactly.
    hier2 = Hierarchy(scene)
    hier2.split(hier2.split(hier2.split([0]) + np.arange(4)).repeat(4) + np.tile(np.arange(4), 4))
    leaves2 = hier2.leaves()
    vals = f_linear(hier2.centroid[leaves2])
    ids2 = texel_elements(hier2, tm)
    got2 = vertex_interpolate(hier2, vals, tm, ids2)
    param = hier2.param[ids2]
    interior = np.all((param > 1e-9) & (param < 1 - 1e-9), axis=(1, 2))
    assert interior.sum() > 100
    np.testing.assert_allclose(got2[interior], f_linear(p3)[interior], atol=1e-12)
    # Per-element-id input gives the same thing.
    full = np.zeros((hier2.n, 2))
    full[leaves2] = vals
    np.testing.assert_allclose(vertex_interpolate(hier2, full, tm, ids2), got2)


def test_vertex_values_shared_corners_and_across_patches():
    uv = grid_uv(2, 1)                            # two coplanar patches sharing an edge
    scene = scene_from_uv(uv)
    hier = Hierarchy(scene)
    hier.split([0, 1])
    leaves = hier.leaves()
    vals = np.arange(len(leaves), dtype=float)[:, None]
    cv = vertex_values(hier, vals)
    # Within patch 0 the centre corner (0.5, 0.5) is shared by its 4 equal children: their mean.
    p0 = leaves[hier.patch[leaves] == 0]
    centre = np.isclose(hier.param[p0], 0.5).all(-1)
    np.testing.assert_allclose(cv[np.searchsorted(leaves, p0)][centre], vals[:4].mean())
    # Across patches, the shared edge gets one value from both sides.
    cva = vertex_values(hier, vals, across_patches=True)
    pos = hier.corners[leaves].reshape(-1, 3)
    flat = cva.reshape(-1)
    on_edge = np.isclose(pos[:, 0], 0.5)
    for y in np.unique(np.round(pos[on_edge, 1], 9)):
        same = on_edge & np.isclose(pos[:, 1], y)
        assert np.ptp(flat[same]) < 1e-12 and same.sum() >= 2
    assert not np.allclose(flat[on_edge], cv.reshape(-1)[on_edge])


# -- seams -----------------------------------------------------------------------------------
def test_dilate_seams_fills_ring_without_touching_covered():
    h = w = 20
    cov = np.zeros((h, w), bool)
    cov[6:14, 6:14] = True
    rng = np.random.default_rng(0)
    img = rng.random((h, w, 3)).astype(np.float32)
    img[~cov] = 0.0
    out, cov2 = dilate_seams(img, cov, pixels=2)
    np.testing.assert_array_equal(out[cov], img[cov])
    ring = np.zeros_like(cov)
    ring[4:16, 4:16] = True
    np.testing.assert_array_equal(cov2, ring)
    assert np.all(out[ring & ~cov] > 0)
    np.testing.assert_array_equal(out[~ring], 0.0)
    # First ring: a texel next to an edge gets the mean of its covered neighbours.
    np.testing.assert_allclose(out[5, 10], img[6, 9:12].mean(axis=0), rtol=1e-6)
    # Constant image: padding is the constant.
    const = np.where(cov[..., None], 0.7, 0.0)
    outc, _ = dilate_seams(const, cov, pixels=4)
    np.testing.assert_allclose(outc[4:16, 4:16], 0.7)
    # 2D images work too.
    out2, _ = dilate_seams(const[..., 0], cov, pixels=1)
    assert out2.shape == (h, w) and np.isclose(out2[5, 5], 0.7)


# -- colour ----------------------------------------------------------------------------------
def test_srgb_round_trip_and_known_values():
    x = np.linspace(-0.1, 1.2, 10001)
    np.testing.assert_allclose(col.srgb_to_linear(col.linear_to_srgb(x)), x, atol=1e-7)
    np.testing.assert_allclose(col.linear_to_srgb(col.srgb_to_linear(x)), x, atol=1e-7)
    assert abs(col.srgb_to_linear(0.5) - 0.21404) < 1e-5
    assert abs(col.linear_to_srgb(0.21404114) - 0.5) < 1e-7
    assert col.srgb_to_linear(0.0) == 0 and abs(col.srgb_to_linear(1.0) - 1) < 1e-12
    assert abs(col.srgb_to_linear(0.04) - 0.04 / 12.92) < 1e-15
    x32 = np.linspace(0, 1, 11, dtype=np.float32)
    assert col.srgb_to_linear(x32).dtype == np.float32 and col.linear_to_srgb(x32).dtype == np.float32
    colour = pytest.importorskip("colour")
    np.testing.assert_allclose(col.srgb_to_linear(x[(x >= 0) & (x <= 1)]),
                               colour.models.eotf_sRGB(x[(x >= 0) & (x <= 1)]), atol=1e-12)


def test_lab_white_and_against_colour_science():
    colour = pytest.importorskip("colour")
    np.testing.assert_allclose(col.linear_rgb_to_lab([1.0, 1.0, 1.0]), [100.0, 0.0, 0.0], atol=0.02)
    np.testing.assert_allclose(col.linear_rgb_to_lab([0.0, 0.0, 0.0]), [0.0, 0.0, 0.0], atol=1e-9)
    rgb = np.array([[0.2, 0.5, 0.1], [0.9, 0.3, 0.4]])
    ref = colour.XYZ_to_Lab(colour.sRGB_to_XYZ(col.linear_to_srgb(rgb)))
    np.testing.assert_allclose(col.linear_rgb_to_lab(rgb), ref, atol=1e-9)
    np.testing.assert_allclose(col.srgb_to_lab(col.linear_to_srgb(rgb)), ref, atol=1e-9)
    assert col.linear_rgb_to_lab(np.zeros((4, 5, 3))).shape == (4, 5, 3)


def test_lab_distance_and_delta_e_2000_sharma():
    # Sharma, Wu, Dalal (2005), CIEDE2000 test data, rows 1, 2, 3, 7, 17, 25, 34.
    pairs = np.array([
        [50.0000, 2.6772, -79.7751, 50.0000, 0.0000, -82.7485, 2.0425],
        [50.0000, 3.1571, -77.2803, 50.0000, 0.0000, -82.7485, 2.8615],
        [50.0000, 2.8361, -74.0200, 50.0000, 0.0000, -82.7485, 3.4412],
        [50.0000, 0.0000, 0.0000, 50.0000, -1.0000, 2.0000, 2.3669],
        [50.0000, 2.5000, 0.0000, 73.0000, 25.0000, -18.0000, 27.1492],
        [60.2574, -34.0099, 36.2677, 60.4626, -34.1751, 39.4387, 1.2644],
        [22.7233, 20.0904, -46.6940, 23.0331, 14.9730, -42.5619, 2.0373],
    ])
    np.testing.assert_allclose(col.delta_e_2000(pairs[:, :3], pairs[:, 3:6]), pairs[:, 6], atol=1e-4)
    np.testing.assert_allclose(col.lab_distance(pairs[:, :3], pairs[:, 3:6]),
                               np.linalg.norm(pairs[:, :3] - pairs[:, 3:6], axis=1))
    assert col.lab_distance([50, 0, 0], [53, 4, 0]) == pytest.approx(5.0)
    assert col.rgb_lab_distance([0.5, 0.5, 0.5], [0.5, 0.5, 0.5]) == pytest.approx(0.0)
    assert col.rgb_lab_distance([0.2, 0.5, 0.1], [0.25, 0.5, 0.1], method="CIE 2000") > 0


# -- speed -----------------------------------------------------------------------------------
def test_rasterize_speed_1024_2000_patches():
    uv = grid_uv(50, 40, jitter=0.3, seed=7)
    # Half of them as triangle pairs would change the count; keep quads plus a triangle strip.
    assert len(uv) == 2000
    rasterize_patches(uv[:10], np.zeros(10, int), [(64, 64)])        # warm-up
    t0 = time.perf_counter()
    tm = rasterize_patches(uv, np.zeros(len(uv), int), [(1024, 1024)])
    dt = time.perf_counter() - t0
    print(f"\nrasterize 1024x1024, 2000 patches: {dt:.3f} s")
    assert tm[0].coverage.all() and tm[0].n_overlap == 0
    assert dt < 10.0


def test_dilate_seams_numpy_fallback_matches_opencv(monkeypatch):
    from relight_addon.core.texture import mapping
    rng = np.random.default_rng(3)
    img = rng.random((30, 40, 5))                    # > 4 channels: OpenCV path splits them
    cov = rng.random((30, 40)) > 0.8
    with_cv, cov_cv = dilate_seams(img, cov, pixels=3)
    monkeypatch.setattr(mapping, "_cv2", lambda: None)
    with_np, cov_np = dilate_seams(img, cov, pixels=3)
    np.testing.assert_array_equal(cov_cv, cov_np)
    np.testing.assert_allclose(with_cv, with_np, rtol=1e-12)
    np.testing.assert_array_equal(with_np[cov], img[cov])
