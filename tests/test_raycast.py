"""Ray casting backends: agreement between Embree, mathutils BVHTree and numpy brute force,
hand-made cases with exact answers, first-hit distances against a plane, and the auto fallback."""
import sys
import warnings

import numpy as np
import pytest

from relight_addon.core.geometry import raycast as rc


def _have_embree():
    try:
        import embreex.rtcore_scene  # noqa: F401
        return True
    except Exception:
        return False


def _have_bvhtree():
    try:
        import bpy  # noqa: F401
        from mathutils.bvhtree import BVHTree  # noqa: F401
        return True
    except Exception:
        return False


if _have_bvhtree():
    from relight_addon.blender.bvhtree import BVHTreeOccluder  # registers the fallback

BACKENDS = [
    pytest.param("embree", marks=pytest.mark.skipif(not _have_embree(), reason="no embreex")),
    pytest.param("bvhtree", marks=pytest.mark.skipif(not _have_bvhtree(), reason="no bpy")),
    "numpy",
]

SQUARE = np.array([[[0, 0, 0], [1, 0, 0], [1, 1, 0]],
                   [[0, 0, 0], [1, 1, 0], [0, 1, 0]]], float)


def _box(lo, hi):
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    c = np.array([[i & 1, (i >> 1) & 1, (i >> 2) & 1] for i in range(8)], float)
    v = lo + c * (hi - lo)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    return np.array([[v[a], v[b], v[c_]] for a, b, c_, _ in quads]
                    + [[v[a], v[c_], v[d]] for a, _, c_, d in quads])


@pytest.fixture(scope="module")
def random_scene():
    rng = np.random.default_rng(12345)
    centres = rng.uniform(0, 10, (300, 1, 3))
    tris = centres + rng.normal(0, 0.5, (300, 3, 3))
    tris = np.concatenate([tris, _box([1, 1, 1], [3, 2, 4]), _box([6, 5, 0], [9, 9, 2]),
                           _box([4, 0.5, 6], [5, 9.5, 6.2])])
    lo, hi = tris.min((0, 1)), tris.max((0, 1))
    n = 100_000
    return tris, rng.uniform(lo, hi, (n, 3)), rng.uniform(lo, hi, (n, 3))


@pytest.fixture(scope="module")
def random_results(random_scene):
    tris, o, e = random_scene
    out = {}
    if _have_embree():
        out["embree"] = rc.make_occluder(tris, "embree").segments_occluded(o, e)
    if _have_bvhtree():
        out["bvhtree"] = rc.make_occluder(tris, "bvhtree").segments_occluded(o, e)
    return out


# ------------------------------------------------------------------------------------------
# agreement on random scenes
# ------------------------------------------------------------------------------------------

def test_embree_and_bvhtree_agree(random_results):
    if len(random_results) < 2:
        pytest.skip("needs both embreex and bpy")
    a, b = random_results["embree"], random_results["bvhtree"]
    # not a degenerate scene: a healthy mix of blocked and free segments
    assert 0.2 < a.mean() < 0.95
    assert (a == b).mean() >= 0.999


@pytest.mark.parametrize("backend", BACKENDS)
def test_backends_agree_with_numpy_bruteforce(random_scene, random_results, backend):
    tris, o, e = random_scene
    m = 4000
    ref = rc.make_occluder(tris, "numpy").segments_occluded(o[:m], e[:m])
    got = (random_results[backend][:m] if backend in random_results
           else rc.make_occluder(tris, backend).segments_occluded(o[:m], e[:m]))
    assert 0.2 < ref.mean() < 0.95
    assert (got == ref).mean() >= 0.999


@pytest.mark.skipif(not _have_embree(), reason="no embreex")
def test_embree_threads_and_chunks_do_not_change_answers(random_scene, random_results):
    tris, o, e = random_scene
    one = rc.EmbreeOccluder(tris, threads=1).segments_occluded(o, e)
    many = rc.EmbreeOccluder(tris, threads=3, chunk=7001).segments_occluded(o, e)
    np.testing.assert_array_equal(one, random_results["embree"])
    np.testing.assert_array_equal(one, many)
    d = e - o
    t1 = rc.EmbreeOccluder(tris, threads=1).first_hit_distance(o, d)
    t3 = rc.EmbreeOccluder(tris, threads=3, chunk=7001).first_hit_distance(o, d)
    np.testing.assert_array_equal(t1, t3)


# ------------------------------------------------------------------------------------------
# hand-made cases on the unit square z = 0 (two triangles sharing the diagonal)
# ------------------------------------------------------------------------------------------

def _occ(backend, tris, a, b, **kw):
    return bool(rc.make_occluder(tris, backend).segments_occluded(
        np.array([a], float), np.array([b], float), **kw)[0])


@pytest.mark.parametrize("backend", BACKENDS)
def test_square_exact_cases(backend):
    occ = rc.make_occluder(SQUARE, backend)
    cases = [  # (origin, end, expected)
        ([0.5, 0.3, 1], [0.5, 0.3, -1], True),           # straight through the middle
        ([0.2, 0.9, -2], [0.7, 0.1, 3], True),           # oblique, through
        ([0.5, 0.5, 1], [0.5, 0.5, -1], True),           # through the shared diagonal: no leak
        ([0.25, 0.25, 1], [0.75, 0.75, -1], True),       # crossing the diagonal edge obliquely
        ([0.5, 0.3, 1], [0.5, 0.3, 0], False),           # ends exactly on the square (eps trim)
        ([0.5, 0.3, 0], [0.2, 0.7, 1], False),           # starts on the square, leaves it
        ([0.5, 0.3, -1], [0.5, 0.3, 0], False),          # ends on it from below (two-sided)
        ([-1, 0.5, 1e-4], [2, 0.5, 1e-4], False),        # parallel, just above
        ([1.5, 0.5, 1], [1.5, 0.5, -1], False),          # through the plane, outside the square
        ([0.5, 0.3, 2], [0.5, 0.3, 1], False),           # stops short of the square
        # Grazing: a segment lying in the plane of the square, across it or along its edge, has
        # a zero determinant and is NOT occluded by any backend (a measure-zero configuration).
        ([-1, 0.5, 0], [2, 0.5, 0], False),
        ([-1, 0, 0], [2, 0, 0], False),
    ]
    o = np.array([c[0] for c in cases], float)
    e = np.array([c[1] for c in cases], float)
    want = np.array([c[2] for c in cases])
    got = occ.segments_occluded(o, e)
    assert got.dtype == bool and got.shape == (len(cases),)
    bad = [(cases[i][:2], bool(got[i])) for i in np.flatnonzero(got != want)]
    assert not bad, bad


@pytest.mark.parametrize("backend", BACKENDS)
def test_eps_controls_endpoint_hits(backend):
    # Without trimming, an end exactly on the surface is backend-dependent: numpy and Embree
    # include t = tfar (hit), BVHTree tests dist < tfar strictly (no hit).  Hence eps > 0.
    expected = {"bvhtree": False}.get(backend, True)
    assert _occ(backend, SQUARE, [0.5, 0.3, 1], [0.5, 0.3, 0], eps=0.0) == expected
    assert _occ(backend, SQUARE, [0.5, 0.3, 1], [0.5, 0.3, 0], eps=1e-6) is False
    # A large trim hides a genuine crossing close to the end.
    assert not _occ(backend, SQUARE, [0.5, 0.3, 1], [0.5, 0.3, -0.01], eps=0.05)
    assert _occ(backend, SQUARE, [0.5, 0.3, 1], [0.5, 0.3, -0.01], eps=1e-3)
    with pytest.raises(ValueError):
        _occ(backend, SQUARE, [0, 0, 1], [0, 0, -1], eps=0.5)


@pytest.mark.parametrize("backend", BACKENDS)
def test_endpoints_on_a_far_tilted_surface(backend):
    """Endpoints exactly on a tilted quad far from the world origin: float32 backends must not
    self-hit (they centre the scene before converting), and crossings still register."""
    rng = np.random.default_rng(7)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    offset = np.array([1000.0, -2000.0, 500.0])
    tris = SQUARE @ q.T + offset
    normal = q[:, 2]
    s = rng.uniform(0.05, 0.95, (500, 2))
    on = offset + s[:, :1] * q[:, 0] + s[:, 1:] * q[:, 1]
    away = on + normal * rng.uniform(0.2, 1.0, (500, 1)) + rng.normal(0, 0.1, (500, 3))
    occ = rc.make_occluder(tris, backend)
    assert not occ.segments_occluded(away, on).any()
    assert not occ.segments_occluded(on, away).any()
    below = on - 0.5 * (away - on)   # same line, continued through the square
    assert occ.segments_occluded(away, below).all()


@pytest.mark.parametrize("backend", BACKENDS)
def test_degenerate_and_empty_inputs(backend):
    occ = rc.make_occluder(SQUARE, backend)
    p = np.array([[0.5, 0.5, 0.0], [0.3, 0.3, 1.0], [np.nan, 0, 0], [np.inf, 0, 0]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        got = occ.segments_occluded(p, p)
        assert got.tolist() == [False] * 4
        t = occ.first_hit_distance(p, np.zeros_like(p))
        assert np.all(t == np.inf)
        e = occ.segments_occluded(np.zeros((0, 3)), np.zeros((0, 3)))
        assert e.shape == (0,) and e.dtype == bool
        assert occ.first_hit_distance(np.zeros((0, 3)), np.zeros((0, 3)), 1.0).shape == (0,)
    with pytest.raises(ValueError):
        occ.segments_occluded(np.zeros((2, 3)), np.zeros((3, 3)))

    empty = rc.make_occluder(np.zeros((0, 3, 3)), backend)
    o = np.array([[0.5, 0.5, 1.0]])
    assert empty.segments_occluded(o, -o).tolist() == [False]
    assert empty.first_hit_distance(o, -o).tolist() == [np.inf]


# ------------------------------------------------------------------------------------------
# first-hit distances
# ------------------------------------------------------------------------------------------

@pytest.mark.parametrize("backend", BACKENDS)
def test_first_hit_distance_to_a_plane(backend):
    rng = np.random.default_rng(3)
    n_hat = np.array([0.3, -0.2, 1.0])
    n_hat /= np.linalg.norm(n_hat)
    q = np.linalg.qr(np.column_stack([n_hat, rng.normal(size=(3, 2))]))[0]
    t1, t2 = q[:, 1], q[:, 2]
    centre = np.array([2.0, -1.0, 3.0])
    corners = [centre + 100 * (a * t1 + b * t2) for a, b in [(-1, -1), (1, -1), (1, 1), (-1, 1)]]
    tris = np.array([[corners[0], corners[1], corners[2]], [corners[0], corners[2], corners[3]]])
    m = 400
    o = centre + rng.uniform(-5, 5, (m, 1)) * t1 + rng.uniform(-5, 5, (m, 1)) * t2
    o += n_hat * rng.uniform(0.5, 5, (m, 1))                  # all above the plane
    d = rng.normal(size=(m, 3))
    d -= n_hat * (np.abs(d @ n_hat) + 0.3)[:, None]          # all head into the plane
    d *= rng.uniform(0.1, 10, (m, 1))                         # length must not matter
    d[::4] *= -1                                              # ... except these, heading away
    u = d / np.linalg.norm(d, axis=1, keepdims=True)
    exact = ((centre - o) @ n_hat) / (u @ n_hat)
    exact[exact < 0] = np.inf
    assert np.isinf(exact[::4]).all() and np.isfinite(exact[1::4]).all()

    occ = rc.make_occluder(tris, backend)
    got = occ.first_hit_distance(o, d)
    assert np.array_equal(np.isinf(got), np.isinf(exact))
    fin = np.isfinite(exact)
    np.testing.assert_allclose(got[fin], exact[fin], rtol=1e-5, atol=1e-4)
    # tmax cuts hits beyond it (scalar and per ray)
    tmax = np.where(np.arange(m) % 2 == 0, exact * 0.9, exact * 1.1)
    got = occ.first_hit_distance(o, d, tmax)
    assert np.array_equal(np.isfinite(got), fin & (np.arange(m) % 2 == 1))
    assert np.isinf(occ.first_hit_distance(o, d, 0.4)).all()
    # tmin skips hits closer than it, and distances still count from the origin
    h = (o - centre) @ n_hat
    down = np.broadcast_to(-n_hat, o.shape)
    np.testing.assert_allclose(occ.first_hit_distance(o, down, tmin=0.9 * h.min()), h,
                               rtol=1e-5, atol=1e-4)
    assert np.isinf(occ.first_hit_distance(o, down, tmin=1.01 * h.max())).all()
    # an origin on the plane: a hit at ~0 or a miss (round-off decides), never anything else;
    # tmin leaves the surface reliably
    on = o - n_hat * h[:, None]
    t0 = occ.first_hit_distance(on, np.broadcast_to(n_hat, o.shape))
    assert np.all((t0 < 1e-4) | np.isinf(t0))
    assert np.isinf(occ.first_hit_distance(on, np.broadcast_to(n_hat, o.shape), tmin=1e-4)).all()


# ------------------------------------------------------------------------------------------
# backend selection
# ------------------------------------------------------------------------------------------

def _block(monkeypatch, *mods):
    for mod in mods:
        monkeypatch.setitem(sys.modules, mod, None)  # import now raises ImportError


def test_auto_falls_back_to_bvhtree(monkeypatch, random_scene, random_results):
    pytest.importorskip("bpy")
    tris, o, e = random_scene
    _block(monkeypatch, "embreex", "embreex.rtcore_scene", "embreex.mesh_construction")
    assert rc.active_backend_name() == "bvhtree"
    assert rc.available_backends() == ["bvhtree", "numpy"]
    occ = rc.make_occluder(tris)
    assert isinstance(occ, BVHTreeOccluder) and occ.name == "bvhtree"
    got = occ.segments_occluded(o[:20000], e[:20000])
    ref = random_results.get("embree", random_results["bvhtree"])[:20000]
    assert (got == ref).mean() >= 0.999
    with pytest.raises(ImportError):
        rc.make_occluder(tris, "embree")


def test_auto_prefers_embree():
    if not _have_embree():
        pytest.skip("no embreex")
    assert rc.active_backend_name() == "embree"
    assert rc.available_backends()[0] == "embree"
    assert isinstance(rc.make_occluder(SQUARE), rc.EmbreeOccluder)


def test_auto_without_any_backend_raises(monkeypatch):
    _block(monkeypatch, "embreex", "embreex.rtcore_scene", "embreex.mesh_construction",
           "mathutils", "mathutils.bvhtree")
    assert rc.active_backend_name() is None
    assert rc.available_backends() == ["numpy"]
    with pytest.raises(RuntimeError, match="(?s)embreex.*mathutils"):
        rc.make_occluder(SQUARE)
    with pytest.raises(ValueError):
        rc.make_occluder(SQUARE, "optix")
    # numpy stays usable on demand
    assert rc.make_occluder(SQUARE, "numpy").segments_occluded([[0.5, 0.5, 1]], [[0.5, 0.5, -1]])[0]


def test_core_never_imports_bpy_or_mathutils():
    """The fallback lives in the bridge: core modules import neither bpy nor mathutils, and a
    whole precompute in a fresh interpreter leaves both unimported."""
    import ast
    import glob
    import os
    import subprocess
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    bad = []
    for path in glob.glob(os.path.join(root, "relight_addon", "core", "**", "*.py"), recursive=True):
        for node in ast.walk(ast.parse(open(path, encoding="utf-8").read())):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import) else
                     [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            bad += [f"{path}: {n}" for n in names if n.split(".")[0] in ("bpy", "mathutils")]
    assert not bad, bad
    code = ("import sys; from scenes.testscenes import cornell_box; "
            "from relight_addon.core.radiosity.precompute import solve_radiosity; "
            "solve_radiosity(cornell_box(), 'draft'); "
            "print(sorted(m for m in sys.modules if m.split('.')[0] in ('bpy', 'mathutils')))")
    out = subprocess.run([sys.executable, "-c", code], cwd=root, capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]", out.stdout


@pytest.mark.parametrize("backend", BACKENDS)
def test_first_hit_names_the_nearest_triangle(backend, random_scene):
    """first_hit: the distance of first_hit_distance and the index of the triangle hit (the
    numpy brute force is the reference), -1 and inf for rays that miss."""
    tris, o, e = random_scene
    m = 3000
    d = e[:m] - o[:m]
    t_ref, i_ref = rc.make_occluder(tris, "numpy").first_hit(o[:m], d)
    t, i = rc.make_occluder(tris, backend).first_hit(o[:m], d)
    assert 0.2 < (i_ref >= 0).mean() < 0.99 and np.all(np.isinf(t_ref) == (i_ref < 0))
    same = i == i_ref
    assert same.mean() >= 0.999                      # float32 backends may split near-ties
    np.testing.assert_allclose(t[same & (i >= 0)], t_ref[same & (i_ref >= 0)], rtol=1e-4,
                               atol=1e-5)
    np.testing.assert_array_equal(rc.make_occluder(tris, backend).first_hit_distance(
        o[:m], d)[same], t[same])


def test_a_scenes_size_is_its_bounding_box_and_never_zero():
    """Ray offsets and matching grids scale with the scene (core/geometry/extent.py): a box of
    sides 1, 2, 2 turned into quads' corners, then the degenerate cases that must not give a
    zero tolerance."""
    from relight_addon.core.geometry.extent import bounding_diagonal, longest_side
    corners = np.array([[[0, 0, 0], [1, 0, 0], [1, 2, 0], [0, 2, 0]],
                        [[0, 0, 2], [1, 0, 2], [1, 2, 2], [0, 2, 2]]], float) - 5.0
    assert bounding_diagonal(corners) == pytest.approx(3.0)
    assert longest_side(corners) == pytest.approx(2.0)
    for none in (np.zeros((0, 4, 3)), np.ones((1, 3))):
        assert bounding_diagonal(none) == 1.0 and longest_side(none) == 1.0
