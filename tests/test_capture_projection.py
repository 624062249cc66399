"""relight.project_photos on a small emission-only scene (quick): a 2 x 2 m floor whose
emission texture is known, a red box on it (an occluder), three cameras whose 320 x 240
Cycles photos (8-bit sRGB, the third one stop brighter) show the textures exactly.

Truth: the floor's texture itself.  The projected floor matches it on the texels some camera
sees; texels hidden by the box from one camera take the others' colours, never the box's red;
texels under the box (seen by none) are reported as holes and take the floor's colours; the
third photo's gain comes out at 1/2.  The office against a Cycles bake is
test_capture_office.py (slow).
"""
import importlib

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
pytest.importorskip("cv2")

from relight_addon.core.texture.colour import delta_e_2000, linear_rgb_to_lab  # noqa: E402
from helpers.blender import run_cancelled_at  # noqa: E402
from scenes import capture as sc  # noqa: E402
from scenes.addon import register_repo_addon  # noqa: E402


@pytest.fixture(scope="module")
def photos():
    register_repo_addon()
    return sc.projection_photos()


def _setup(photos, with_photos=3):
    scene, floor, box, cams = sc.projection_scene()
    bridge = importlib.import_module("relight_ext.relight_addon.blender.capture")
    for cam, path in list(zip(cams, photos))[:with_photos]:
        bridge.set_camera_photo(cam, path)
    for o in scene.objects:
        o.select_set(o is floor)
    bpy.context.view_layer.objects.active = floor
    return scene, floor, box, cams, bridge


def _texture(obj):
    mat = obj.material_slots[0].material
    node = next(n for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeTexImage")
    img = node.image
    w, h = img.size
    px = np.empty(w * h * 4, np.float32)
    img.pixels.foreach_get(px)
    return px.reshape(h, w, 4)[..., :3], mat


def _de(a, b):
    return delta_e_2000(linear_rgb_to_lab(np.clip(a, 0, None)), linear_rgb_to_lab(np.clip(b, 0, None)))


def test_project_photos_onto_the_floor(photos):
    scene, floor, box, cams, bridge = _setup(photos)
    n = sc.FLOOR_TEXELS
    bpy.ops.relight.project_photos(texture_size=n)
    tex, mat = _texture(floor)
    truth = sc.floor_texture(n)
    # which floor texels some camera sees: ray casts of our own are not the truth here, the box's
    # footprint is (a texel under the box is seen by nobody)
    y, x = (np.mgrid[0:n, 0:n] + 0.5) / n * 2 - 1
    bx, by = box.location[0], box.location[1]
    under = (np.abs(x - bx) < 0.25) & (np.abs(y - by) < 0.25)
    border = (np.abs(x - bx) < 0.29) & (np.abs(y - by) < 0.29) & ~under
    de = _de(tex, truth)
    assert np.mean(de[~under & ~border]) < 1.5, np.mean(de[~under & ~border])
    red = np.array(sc.BOX_RGB, np.float32)
    de_red = _de(tex, np.broadcast_to(red, tex.shape))
    near = (np.abs(x - bx) < 0.5) & (np.abs(y - by) < 0.5)
    # no floor texel near the box takes its colour: each is nearer the floor's than the box's
    assert np.all(de[near] < de_red[near]), (de[near].max(), de_red[near].min())
    assert np.mean(de[under]) < 12                  # filled from the floor around
    # the node tree Precompute reads: Principled base colour <- the new image, the UV map
    bsdf = next(nd for nd in mat.node_tree.nodes if nd.bl_idname == "ShaderNodeBsdfPrincipled")
    assert bsdf.inputs["Base Color"].links[0].from_node.image.name == "Floor Photo"
    assert floor.material_slots[0].link == "OBJECT"
    assert floor.data.materials[0].name == "Floor"          # the mesh keeps its material
    read = importlib.import_module("relight_ext.relight_addon.blender.read")
    data, report = read.read_scene(bpy.context)
    assert any(im.name == "Floor Photo" for im in data.images)


def test_exposure_gains_and_holes(photos):
    """The core's result: the third photo (one stop brighter) gets a gain of 1/2, and the
    texels under the box are the holes."""
    from relight_addon.core.capture import projection
    scene, floor, box, cams, bridge = _setup(photos)
    views = bridge.posed_views(bpy.context.scene)[0]
    dg = bpy.context.evaluated_depsgraph_get()
    tris, uvs = bridge.mesh_triangles(floor, dg, "UVMap")
    res = projection.project([projection.Target("Floor", tris, uvs, (64, 64))], views,
                             *bridge.scene_triangles(dg))
    g = res.gains
    np.testing.assert_allclose(g["Cam0"], 1.0)
    np.testing.assert_allclose(g["Cam1"], 1.0, atol=0.02)
    np.testing.assert_allclose(g["Cam2"], 0.5, rtol=0.03)
    m = res.meshes[0]
    y, x = (np.mgrid[0:64, 0:64] + 0.5) / 64 * 2 - 1
    under = (np.abs(x - box.location[0]) < 0.24) & (np.abs(y - box.location[1]) < 0.24)
    around = (np.abs(x - box.location[0]) < 0.4) & (np.abs(y - box.location[1]) < 0.4)
    holes = m.covered & ~m.seen
    inner = np.zeros_like(holes)
    inner[2:-2, 2:-2] = True          # the floor's outer texels border the black world
    # hidden under the box: holes; the others are seen, but for a band where every view has
    # the box's silhouette within the texel's footprint
    assert holes[under].all() and not (holes & inner & ~around).any()
    assert "holes" in res.summary()


def test_unwraps_a_mesh_without_uvs(photos):
    scene, floor, box, cams, bridge = _setup(photos)
    box.select_set(True)
    bpy.ops.relight.project_photos(texture_size=32)
    assert "RelightUV" in box.data.uv_layers
    tex, _ = _texture(box)
    lit = tex[tex.max(axis=2) > 0.05]
    # the faces the cameras see are the box's red
    assert np.median(_de(lit, np.broadcast_to(np.array(sc.BOX_RGB, np.float32), lit.shape))) < 5


def _state(scene):
    return (sorted(m.name for m in bpy.data.materials), sorted(i.name for i in bpy.data.images),
            {o.name: [s.material.name if s.material else "" for s in o.material_slots]
             for o in scene.objects},
            {o.name: len(o.data.uv_layers) for o in scene.objects if o.type == "MESH"})


def test_project_photos_bad_input(photos, tmp_path):
    scene, floor, box, cams, bridge = _setup(photos, with_photos=2)
    state = _state(scene)
    cams[2].select_set(True)                       # a selected camera without a photo
    box.select_set(True)                           # (and a mesh without UVs: not unwrapped)
    with pytest.raises(RuntimeError, match="Camera 'Cam2' has no photo"):
        bpy.ops.relight.project_photos(texture_size=32)
    cams[2].select_set(False)
    import cv2
    wide = str(tmp_path / "wide.png")
    cv2.imwrite(wide, np.zeros((100, 300, 3), np.uint8))
    bridge.set_camera_photo(cams[2], wide)
    state = _state(scene)
    with pytest.raises(RuntimeError, match="does not have the render frame's shape"):
        bpy.ops.relight.project_photos(texture_size=32)
    bridge.set_camera_photo(cams[2], photos[2])
    state = _state(scene)
    with pytest.raises(RuntimeError, match="no UV map 'Nope'"):
        bpy.ops.relight.project_photos(texture_size=32, uv_map="Nope")
    for o in scene.objects:
        o.select_set(False)
    with pytest.raises(RuntimeError, match="Select the meshes to texture"):
        bpy.ops.relight.project_photos(texture_size=32)
    assert _state(scene) == state


def test_automatic_texture_size(photos):
    """texture_size=0: about one texel a photo pixel where a camera sees the floor best; the
    nearest camera is ~2.9 m from the floor's centre with f = 213 px (24 mm on 36 mm at 320 px),
    about 1.2-1.4 cm a pixel on the floor seen at 45-50 degrees: 2 m / 1.3 cm ~ 150 texels."""
    scene, floor, box, cams, bridge = _setup(photos)
    bpy.ops.relight.project_photos()
    tex, _ = _texture(floor)
    assert 128 <= tex.shape[0] <= 256 and tex.shape[0] == tex.shape[1]


def test_a_failed_or_cancelled_projection_changes_nothing(photos, monkeypatch):
    """A mesh without UVs is unwrapped before the projection reads it; when the projection then
    fails (here: the core raises) or is cancelled (Esc: the worker's progress raises), the new
    UV map goes again and nothing else is written."""
    from relight_addon.core.capture import CaptureError
    scene, floor, box, cams, bridge = _setup(photos)
    box.select_set(True)                           # no UVs: gets an xatlas atlas first
    state = _state(scene)
    projection = importlib.import_module("relight_ext.relight_addon.core.capture.projection")

    def fails(*args, **kwargs):
        raise CaptureError("the projection failed")
    with monkeypatch.context() as m:
        m.setattr(projection, "project", fails)
        with pytest.raises(RuntimeError, match="the projection failed"):
            bpy.ops.relight.project_photos(texture_size=32)
    assert _state(scene) == state and "RelightUV" not in box.data.uv_layers
    # the modal path: the job prepared as invoke prepares it, its worker cancelled midway,
    # then what the operator does on Esc
    capture_ops = importlib.import_module("relight_ext.operators.capture")
    precompute = importlib.import_module("relight_ext.operators.precompute")
    op = type("Op", (), dict(uv_map="", supersample=0, match_exposure=True, fill_holes=True,
                             texture_size=32))()
    job = capture_ops.ProjectionJob(op, bpy.context)
    assert "RelightUV" in box.data.uv_layers
    solve = precompute.SolveJob(job)
    seen = run_cancelled_at(solve, 0.3)
    assert solve.state == "cancelled" and solve.result is None
    assert seen and max(seen) < 1.0
    assert solve.label == "projection"          # what the busy buttons name
    job.abandon()                               # what the operator does on Esc
    assert _state(scene) == state
