"""Bad input: relight.unwrap_missing (xatlas atlas for meshes without UVs) and
relight.precompute's refusal of a scene over the memory limit (the estimate itself:
test_memory_estimate.py).

The add-on is registered from the checkout (helpers.blender, package ``relight_ext``) and the
suite's test room (helpers.room) is used for the precompute check.
"""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
pytest.importorskip("xatlas")

from helpers.blender import PKG, addon  # noqa: E402
from helpers.room import build_scene  # noqa: E402


CUBE_V = [(x, y, z) for z in (0, 1) for y in (0, 1) for x in (0, 1)]
CUBE_F = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]


def _cube(name, location=(0, 0, 0), scale=(1, 1, 1), uv=False):
    me = bpy.data.meshes.new(name)
    me.from_pydata(CUBE_V, [], CUBE_F)
    if uv:
        layer = me.uv_layers.new(name="UVMap")
        for i, d in enumerate(layer.data):
            d.uv = (0.1 * (i % 4), 0.05 * (i // 4))
    obj = bpy.data.objects.new(name, me)
    obj.location, obj.scale = location, scale
    bpy.context.scene.collection.objects.link(obj)
    return obj


def _co(me):
    co = np.empty(len(me.vertices) * 3, np.float32)
    me.vertices.foreach_get("co", co)
    return co.reshape(-1, 3)


def _uv_triangles(me, name):
    me.calc_loop_triangles()
    loops = np.empty(len(me.loop_triangles) * 3, np.int32)
    me.loop_triangles.foreach_get("loops", loops)
    uv = np.empty(len(me.loops) * 2, np.float32)
    me.uv_layers[name].data.foreach_get("uv", uv)
    uv = uv.reshape(-1, 2)
    return uv, uv[loops].reshape(-1, 3, 2)


def _signed_area(t):
    return 0.5 * ((t[:, 1, 0] - t[:, 0, 0]) * (t[:, 2, 1] - t[:, 0, 1])
                  - (t[:, 2, 0] - t[:, 0, 0]) * (t[:, 1, 1] - t[:, 0, 1]))


def _coverage(tris, res=256):
    """How many triangles cover each pixel centre of a res x res grid over [0, 1]^2."""
    g = (np.arange(res) + 0.5) / res
    px, py = np.meshgrid(g, g)
    count = np.zeros_like(px, dtype=int)
    for a, b, c in tris:
        def edge(p, q):
            return (q[0] - p[0]) * (py - p[1]) - (q[1] - p[1]) * (px - p[0])
        e = np.stack([edge(a, b), edge(b, c), edge(c, a)])
        count += (np.all(e > 0, axis=0) | np.all(e < 0, axis=0))
    return count


@pytest.fixture
def scene():
    addon()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    yield bpy.context.scene


def test_unwrap_missing_adds_valid_atlas(scene):
    bare = _cube("Bare", scale=(2.0, 1.0, 0.5))
    textured = _cube("Textured", location=(3, 0, 0), uv=True)
    co0, n_loops = _co(bare.data).copy(), len(bare.data.loops)
    n_poly, n_edge = len(bare.data.polygons), len(bare.data.edges)
    uv_before, _ = _uv_triangles(textured.data, "UVMap")
    uv_before = uv_before.copy()
    for o in bpy.data.objects:
        o.select_set(False)     # nothing selected: every visible mesh is considered

    assert bpy.ops.relight.unwrap_missing() == {'FINISHED'}

    me = bare.data
    assert [l.name for l in me.uv_layers] == ["RelightUV"]
    # geometry untouched
    assert len(me.vertices) == 8 and np.array_equal(_co(me), co0)
    assert (len(me.loops), len(me.polygons), len(me.edges)) == (n_loops, n_poly, n_edge)
    uv, tris = _uv_triangles(me, "RelightUV")
    assert np.isfinite(uv).all() and uv.min() >= 0.0 and uv.max() <= 1.0
    area = np.abs(_signed_area(tris))
    assert (area > 1e-4).all(), area
    # no overlaps: no pixel centre is covered twice, and the atlas is not degenerate
    cover = _coverage(tris)
    assert cover.max() == 1
    assert cover.mean() > 0.3
    # world-space, uniform texel density: UV area / world area equal over the triangles
    m = np.array(bare.matrix_world)
    w = (_co(me) @ m[:3, :3].T)
    vi = np.empty(len(me.loop_triangles) * 3, np.int32)
    me.loop_triangles.foreach_get("vertices", vi)
    wt = w[vi].reshape(-1, 3, 3)
    warea = 0.5 * np.linalg.norm(np.cross(wt[:, 1] - wt[:, 0], wt[:, 2] - wt[:, 0]), axis=1)
    density = area / warea
    assert density.max() / density.min() < 1.05, density
    # the object with a UV map is untouched
    assert [l.name for l in textured.data.uv_layers] == ["UVMap"]
    uv_after, _ = _uv_triangles(textured.data, "UVMap")
    assert np.array_equal(uv_after, uv_before)


def test_unwrap_only_selected_and_idempotent(scene):
    a, b = _cube("A"), _cube("B", location=(3, 0, 0))
    for o in bpy.data.objects:
        o.select_set(o is a)
    bpy.context.view_layer.objects.active = a
    assert bpy.ops.relight.unwrap_missing() == {'FINISHED'}
    assert "RelightUV" in a.data.uv_layers and len(b.data.uv_layers) == 0
    before = _uv_triangles(a.data, "RelightUV")[0].copy()
    # already has a UV map: the operator is disabled, and says why
    assert not bpy.ops.relight.unwrap_missing.poll()
    with pytest.raises(RuntimeError, match="has a UV map"):
        bpy.ops.relight.unwrap_missing()
    assert len(a.data.uv_layers) == 1
    assert np.array_equal(_uv_triangles(a.data, "RelightUV")[0], before)


def test_precompute_refused_over_memory_limit(scene):
    build_scene()
    addon = bpy.context.preferences.addons.get(PKG)
    added = addon is None
    if added:
        addon = bpy.context.preferences.addons.new()
        addon.module = PKG
    try:
        addon.preferences.memory_limit_gb = 1e-6
        counts = {k: len(getattr(bpy.data, k)) for k in ("images", "materials", "meshes", "objects")}
        slots = {o.name: [s.material.name if s.material else "" for s in o.material_slots]
                 for o in bpy.data.objects}
        reports = []
        with pytest.raises(RuntimeError) as info:   # bpy.ops raises on an ERROR report
            bpy.ops.relight.precompute(preset="draft")
        reports.append(str(info.value))
        assert "GB" in reports[0] and "memory limit" in reports[0]
        assert {k: len(getattr(bpy.data, k)) for k in counts} == counts
        assert {o.name: [s.material.name if s.material else "" for s in o.material_slots]
                for o in bpy.data.objects} == slots
        assert not any(im.get("relight_generated") for im in bpy.data.images)
    finally:
        if added:
            bpy.context.preferences.addons.remove(addon)


def test_unwrap_non_planar_quads_stay_whole(scene):
    """Suzanne's non-planar quads: xatlas may split a quad's triangles between charts; every
    polygon still gets one coherent UV face, in [0, 1], with (almost) no overlap."""
    bpy.ops.mesh.primitive_monkey_add()
    obj = bpy.context.active_object
    obj.data.uv_layers.remove(obj.data.uv_layers[0]) if obj.data.uv_layers else None
    n_verts = len(obj.data.vertices)
    assert bpy.ops.relight.unwrap_missing() == {'FINISHED'}
    assert len(obj.data.vertices) == n_verts
    uv, tris = _uv_triangles(obj.data, "RelightUV")
    assert uv.min() >= 0.0 and uv.max() <= 1.0
    assert (np.abs(_signed_area(tris)) > 0).all()
    cover = _coverage(tris, 512)
    assert (cover > 1).sum() < 0.01 * (cover > 0).sum()
