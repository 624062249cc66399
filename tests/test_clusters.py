"""Patch clusters: the tree, the link partition, and accuracy against Mitsuba 3."""
import numpy as np
import pytest

from relight_addon.core.radiosity import clusters
from relight_addon.core.radiosity.clusters import (build_cluster_tree, cluster_operator,
                                                   cluster_transport, link_clusters)
from relight_addon.core.radiosity.hierarchy import Hierarchy
from relight_addon.core.radiosity.precompute import solve_radiosity
from relight_addon.core.radiosity.presets import PRESETS
from relight_addon.core.scene import SceneData, quads_from_boxes
from scenes.testscenes import cornell_box


def _random_quads(n, rng):
    centres = rng.random((n, 3)) * 10
    sizes = 0.05 + 0.3 * rng.random((n, 3))
    return np.concatenate([quads_from_boxes(c, s)[:1] for c, s in zip(centres, sizes)])


def test_tree_nodes_nest_and_bound_their_patches():
    corners = _random_quads(200, np.random.default_rng(0))
    tree = build_cluster_tree(corners, np.arange(len(corners)))
    assert sorted(tree.order) == list(range(200))
    inner = np.flatnonzero(tree.child[:, 0] >= 0)
    c0, c1 = tree.child[inner, 0], tree.child[inner, 1]
    assert np.all(tree.lo[c0] == tree.lo[inner]) and np.all(tree.hi[c1] == tree.hi[inner])
    assert np.all(tree.hi[c0] == tree.lo[c1])
    for node in range(tree.n):
        pts = corners[tree.order[tree.lo[node]:tree.hi[node]]].reshape(-1, 3)
        assert np.linalg.norm(pts - tree.centre[node], axis=1).max() <= tree.radius[node] * (1 + 1e-12)


@pytest.mark.parametrize("separation", [0.3, 0.6])
def test_links_cover_every_ordered_pair_of_patches_exactly_once(separation):
    corners = _random_quads(120, np.random.default_rng(1))
    tree = build_cluster_tree(corners, np.arange(len(corners)))
    cx, cy, cv, px, py = link_clusters(tree, separation)
    assert len(cx) > 0                                   # some pairs really are clustered
    cover = np.zeros((120, 120), int)
    np.add.at(cover, (px, py), 1)
    for x, y in zip(cx, cy):
        rx = tree.order[tree.lo[x]:tree.hi[x]]
        ry = tree.order[tree.lo[y]:tree.hi[y]]
        cover[np.ix_(rx, ry)] += 1
    off_diagonal = ~np.eye(120, dtype=bool)
    assert np.all(cover[off_diagonal] == 1)
    assert np.all(np.diag(cover) == 0)
    assert np.all(cv == 1.0)                              # no visibility oracle given


def test_cluster_link_transport_converges_to_the_point_kernel():
    """Two small parallel squares facing each other far apart: the separable cluster kernel
    tends to the exact form factor as the distance grows (error falls like (size/d)^2)."""
    from relight_addon.core.geometry.formfactor import patch_to_patch
    errors = []
    for d in (2.0, 4.0, 8.0):
        lo = quads_from_boxes([0, 0, 0], [1, 1, 1])[1:2]                  # faces +z at z=0.5
        hi = quads_from_boxes([0, 0, d], [1, 1, 1])[0:1]                  # faces -z at d-0.5
        corners = np.concatenate([lo, hi])
        scene = SceneData(corners, 0.5, [[0, 0, 0], [1, 1, 1]], [-1, 0], ["top"])
        h = Hierarchy(scene)
        tree = build_cluster_tree(corners, np.arange(2))
        # Treat the two single-patch children as a cluster link (receiver 1 = patch 0).
        single = tree.hi - tree.lo == 1
        X = np.flatnonzero(single & (tree.order[tree.lo] == 0))
        Y = np.flatnonzero(single & (tree.order[tree.lo] == 1))
        U, W = cluster_operator(tree, h, h.leaves(), X, Y, np.ones(1))
        F_cluster = (U @ (W @ np.array([0.0, 1.0])))[0]
        F_exact = patch_to_patch(corners[:1], corners[1:], 8)[0]
        errors.append(abs(F_cluster / F_exact - 1))
    assert errors[0] > errors[1] > errors[2]
    assert errors[2] < 0.02                                               # (r / d)^2 ~ 1 %
    assert errors[1] / errors[2] > 3                                      # about quadratic


def test_cluster_transport_streamed_equals_the_factors_product(monkeypatch):
    """conserve reads what the cluster links carry without building U and W (memory): block by
    block it must give U @ (W @ B), here with blocks of 64 entries cutting links apart."""
    corners = _random_quads(150, np.random.default_rng(4))
    scene = SceneData(corners, 0.5, np.zeros((len(corners), 3)), np.full(len(corners), -1), [])
    h = Hierarchy(scene)
    tree = build_cluster_tree(corners, np.arange(len(corners)))
    X, Y, _, _, _ = link_clusters(tree, 1.0)
    V = np.random.default_rng(5).random(len(X))
    B = np.random.default_rng(6).random(len(h.leaves()))
    monkeypatch.setattr(clusters, "OPERATOR_BLOCK", 64)
    U, W = cluster_operator(tree, h, h.leaves(), X, Y, V)
    assert U.nnz > 20 * 64                                # many blocks, links cut between them
    np.testing.assert_allclose(cluster_transport(tree, h, h.leaves(), X, Y, V, B), U @ (W @ B),
                               rtol=1e-12)


def test_the_leaf_gather_takes_the_cluster_links_a_few_columns_at_a_time(monkeypatch):
    """W @ B has a row per cluster link: with every lamp's channels at once it held 0.83 GB on
    RenderPark's classroom, so the gather takes it a few columns at a time; the sum must be the
    whole product's."""
    from relight_addon.core.radiosity import solver
    from relight_addon.core.radiosity.solver import LeafSystem
    corners = _random_quads(150, np.random.default_rng(4))
    scene = SceneData(corners, 0.5, np.zeros((len(corners), 3)), np.full(len(corners), -1), [])
    h = Hierarchy(scene)
    tree = build_cluster_tree(corners, np.arange(len(corners)))
    X, Y, _, _, _ = link_clusters(tree, 1.0)
    U, W = cluster_operator(tree, h, h.leaves(), X, Y, np.ones(len(X)))
    none = np.zeros(0, np.int64)
    system = LeafSystem.from_links(h, none, none, np.zeros(0), scene.rho).add_clusters(U, W)
    monkeypatch.setattr(solver, "CLUSTER_GATHER_BYTES", 8 * len(X) * 2)    # 2 columns a time
    B = np.random.default_rng(7).random((system.n_leaves, 7))
    np.testing.assert_allclose(system.gather(B), U @ (W @ B), rtol=1e-12)
    assert np.abs(U @ (W @ B)).max() > 0


def test_clustered_cornell_box_matches_mitsuba():
    pytest.importorskip("mitsuba")
    from reference.mitsuba_ref import patch_radiosity
    ref = patch_radiosity(cornell_box(), spp=1 << 20)       # same surfaces, one patch per face
    n = 3
    scene = cornell_box(subdivide=n)
    sol = solve_radiosity(scene, PRESETS["medium"].with_(cluster_above=0))
    assert sol.counts["cluster_links"] > 100
    face = np.arange(scene.n_patches) // (n * n)
    area = scene.area_normal()[0]
    B = sol.patch_radiosity()
    per_face = np.stack([np.bincount(face, area * B[:, c], 17) for c in range(3)], axis=1)
    per_face /= np.bincount(face, area, 17)[:, None]
    rel = np.abs(per_face - ref) / ref
    print(f"clustered Cornell box: mean rel err {rel[:16].mean():.4f}, max {rel[:16].max():.4f}")
    assert rel[:16].mean() < 0.04
    assert np.all(np.isfinite(B))


def test_a_scene_of_lamp_patches_only_is_still_clustered():
    """Lamp patches link to every patch outside the clusters, unless there are too many or
    there is nothing else: a closed furnace whose 486 faces all emit (one lamp) is clustered
    as before and stays exact (B = E / (1 - rho))."""
    from scenes.testscenes import closed_cube
    scene = closed_cube(rho=0.5, emission=1.0, n=9)
    assert scene.n_patches > PRESETS["draft"].cluster_above and np.all(scene.lamp >= 0)
    sol = solve_radiosity(scene, "draft")
    assert sol.counts["cluster_links"] > 1000
    assert np.abs(sol.patch_radiosity() / 2.0 - 1.0).max() < 0.01
