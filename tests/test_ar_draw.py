"""AR mode's live viewport (blender/ar_draw.py): what its draw handler feeds the sphere-shadow
shader, from a scene after ``bpy.ops.relight.ar_setup()``, run on a headless OpenGL context.

* In background mode the handler is not installed (no gpu module there).
* frame_data(): the virtual object's spheres in world space follow the object (a move, a
  rotation, a scale) with no Update: against the fitted spheres stored at Set Up moved by
  mathutils' matrix_world, computed here.
* The shader (moderngl, EGL, llvmpipe) drawing the receivers' triangles (receiver_arrays)
  with those uniforms and the textures read back from the stored tables image
  (table_textures) gives, pixel by pixel, the numpy twin env_shadow_factor of the lighting
  prepared from the World's map, before and after a move of the object.
"""
from __future__ import annotations

import sys

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from helpers import ar as A  # noqa: E402
from helpers.fake_gpu import FakeGpu  # noqa: E402


# AR mode writes Blender 5.0's compositor (relight_addon/blender/ar.py AR_MIN_BLENDER); on the
# 4.5 LTS line only its refusal is tested (test_ar_setup.py)
BLENDER_5 = tuple(bpy.app.version) >= (5, 0, 0)
pytestmark = [pytest.mark.skipif("sunrise" not in A.HDRIS, reason="bundled HDRIs not found"),
              pytest.mark.skipif(not BLENDER_5, reason="AR mode needs Blender 5.0")]


def test_no_draw_handler_in_background_mode():
    ar_draw = A.ar_module("ar_draw")
    assert bpy.app.background
    assert ar_draw.register_draw() is False and not ar_draw.is_registered()


def _expected_spheres(ob, group):
    from mathutils import Vector
    a = np.asarray(group["relight_ar_spheres"], float).reshape(-1, 4)
    m = ob.matrix_world
    centres = np.array([list(m @ Vector(c)) for c in a[:, :3]])
    return centres, a[:, 3] * float(np.mean(m.to_scale()))


def _draw(uniforms, textures, pos, nor, half, size=64):
    """The shader drawing the triangles top-down over [-half, half]^2 (z up); float32 RGBA."""
    import moderngl
    from relight_addon.blender import ar_shader
    ctx = moderngl.create_standalone_context(backend="egl")
    prog = ctx.program(vertex_shader=ar_shader.standalone_glsl("vert"),
                       fragment_shader=ar_shader.standalone_glsl("frag"))
    vbo = ctx.buffer(np.concatenate([pos, nor], 1).astype("f4").tobytes())
    vao = ctx.vertex_array(prog, [(vbo, "3f 3f", "pos", "nor")])
    mvp = np.diag([1 / half, 1 / half, -1e-3, 1.0]).astype("f4")
    prog["ModelViewProjectionMatrix"].write(mvp.T.tobytes())
    for k, v in uniforms.items():
        if k in prog:
            if np.ndim(v):
                prog[k].write(np.ascontiguousarray(v, np.float32).tobytes())
            else:
                prog[k].value = v.item() if hasattr(v, "item") else v
    im, ct = textures["irradiance_map"], textures["cap_tables"]
    t0 = ctx.texture((im.shape[1], im.shape[0]), 3, np.ascontiguousarray(im, "f4").tobytes(),
                     dtype="f4")
    t1 = ctx.texture_array((ct.shape[2], ct.shape[1], ct.shape[0]), 3,
                           np.ascontiguousarray(ct, "f4").tobytes(), dtype="f4")
    for t in (t0, t1):
        t.repeat_x, t.repeat_y = True, False
        t.filter = (moderngl.LINEAR, moderngl.LINEAR)
    prog["irradiance_map"].value, prog["cap_tables"].value = 0, 1
    t0.use(0)
    t1.use(1)
    fbo = ctx.simple_framebuffer((size, size), components=4, dtype="f4")
    fbo.use()
    fbo.clear()
    vao.render()
    ctx.finish()
    img = np.frombuffer(fbo.read(components=4, dtype="f4"), "f4").reshape(size, size, 4)
    ctx.release()
    x = -half + (np.arange(size) + 0.5) / size * 2 * half
    X, Y = np.meshgrid(x, x)
    return img, np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], 1)


def test_the_handler_draws_the_twin_and_follows_a_move(tmp_path):
    pytest.importorskip("moderngl")
    sc, ob = A.build(tmp_path)
    assert bpy.ops.relight.ar_setup() == {"FINISHED"}
    ar, ar_draw, ar_nodes, ids = (A.ar_module(n) for n in ("ar", "ar_draw", "ar_nodes", "ids"))
    from relight_addon.core.ar.env_shadow import env_shadow_factor
    from relight_addon.core.ar.shader_data import shadow_textures
    st = ar.state(sc)
    lighting = ar._LIGHTING[st["env_hash"]]
    group = ar_nodes.shadow_groups(ids.scene_key(sc))[ob.name]
    # the stored tables image gives back the textures of the lighting (a half-float image:
    # relative steps of 2^-11)
    tex = ar_draw.table_textures(st)
    want = shadow_textures(lighting)
    for k in want:
        assert tex[k].shape == want[k].shape
        assert np.allclose(tex[k], want[k], rtol=1e-3, atol=1e-6), k
    pos, nor = ar_draw.receiver_arrays(sc, st, bpy.context.evaluated_depsgraph_get())
    assert len(pos) == 6 and np.allclose(nor, [0, 0, 1])
    try:
        import moderngl
        moderngl.create_standalone_context(backend="egl").release()
    except Exception as exc:                          # no EGL / no llvmpipe here
        pytest.skip(f"no headless OpenGL context: {exc}")
    for loc, rot, scale in (((0.0, 0.0, 0.0), (0, 0, 0), 1.0),
                            ((0.4, -0.3, 0.05), (0.2, -0.1, 0.7), 0.8)):
        ob.location, ob.rotation_euler, ob.scale = loc, rot, (scale,) * 3
        bpy.context.view_layer.update()
        (name, u), = ar_draw.frame_data(sc)
        centres, radii = _expected_spheres(ob, group)
        n = u["n_spheres"]
        assert name == ob.name and n == len(centres)
        assert np.abs(u["spheres"][:n, :3] - centres).max() < 1e-5
        assert np.abs(u["spheres"][:n, 3] - radii).max() < 1e-6
        img, P = _draw(u, tex, pos, nor, half=1.5)
        hull = (u["hull"][:3].astype(float), float(u["hull"][3]))
        twin = env_shadow_factor(P, np.tile([0.0, 0.0, 1.0], (len(P), 1)), centres, radii,
                                 lighting, hull).reshape(img.shape[0], img.shape[1], 3)
        assert twin.min() < 0.7                                   # a shadow in the frame
        d = np.abs(img[..., :3] - twin)
        assert d.max() < 1e-2 and d.mean() < 2e-4, (d.max(), d.mean())


def test_the_handler_frame_with_a_stand_in_gpu(tmp_path, monkeypatch):
    """The draw callback's frame, run against a stand-in of the gpu module: one shader built
    once, the receivers' batch once, one multiplicative draw per object whose spheres are the
    object's where it now is, the blend and depth state put back."""
    from types import SimpleNamespace

    from mathutils import Matrix
    sc, ob = A.build(tmp_path)
    assert bpy.ops.relight.ar_setup() == {"FINISHED"}
    ar_draw, ar_nodes, ids = (A.ar_module(n) for n in ("ar_draw", "ar_nodes", "ids"))
    fake = FakeGpu()
    monkeypatch.setitem(sys.modules, "gpu", fake.gpu)
    monkeypatch.setitem(sys.modules, "gpu_extras.batch", fake.batch)
    monkeypatch.setitem(ar_draw.cache, "shader", None)
    monkeypatch.setitem(ar_draw.cache, "batch", None)
    monkeypatch.setitem(ar_draw.cache, "textures", None)
    ctx = SimpleNamespace(scene=sc, region_data=SimpleNamespace(
        perspective_matrix=Matrix.Identity(4)),
        evaluated_depsgraph_get=bpy.context.evaluated_depsgraph_get)
    group = ar_nodes.shadow_groups(ids.scene_key(sc))[ob.name]
    for loc in ((0.0, 0.0, 0.0), (0.5, -0.2, 0.0)):
        ob.location = loc
        bpy.context.view_layer.update()
        fake.log.clear()
        ar_draw.draw_frame(ctx)
        draws = fake.draws()
        assert len(draws) == 1
        centres, radii = _expected_spheres(ob, group)
        assert np.abs(draws[0]["spheres"][:len(centres), :3] - centres).max() < 1e-5
        blends = [e[1] for e in fake.log if isinstance(e, tuple) and e[0] == "blend"]
        assert blends == ["MULTIPLY", "NONE"]
    assert fake.created == 1 and sum(e == "batch" for e in fake.log) == 0   # built once
    # moving a receiver's vertex changes no count: the batch is made again from its geometry's
    # update, and only then
    dh = A.ar_module("draw_handlers")
    receiver = sc.objects[ar_draw._ar_state(sc)["receivers"][0]]
    with dh.watching():
        receiver.data.vertices[0].co.z += 1e-3
        receiver.data.update()
        bpy.context.view_layer.update()
        for rebuilt in (1, 0):
            fake.log.clear()
            ar_draw.draw_frame(ctx)
            assert sum(e == "batch" for e in fake.log) == rebuilt
    # a failure stops the drawing; Update (new data) draws again, from a new batch
    callback = dh.guarded(ar_draw.cache, lambda: ar_draw.draw_frame(ctx), "the test's shadows")
    monkeypatch.setitem(ar_draw.cache, "failed", "RuntimeError: a test's failure")
    fake.log.clear()
    callback()
    assert fake.log == []
    assert bpy.ops.relight.update() == {"FINISHED"}
    assert ar_draw.cache["failed"] is None
    callback()
    assert "batch" in fake.log and len(fake.draws()) == 1
