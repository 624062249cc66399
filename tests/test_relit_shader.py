"""The viewport's relit-preview shader (blender/shaders/relit_*.glsl after sphere_lamp.glsl).

(a) both stages, wrapped by relit_shader.standalone_glsl(), compile with glslangValidator;
(b) the GLSL constants equal the numpy side's (core/display/relit.py);
(c) the shader RUNS on a headless OpenGL context (moderngl, EGL, Mesa llvmpipe): a floor with
    a texture and two lamps' maps (alpha the direct part), under two moving objects' spheres
    (each with its silhouette sphere), drawn top-down, read back in float32 and compared pixel
    by pixel with its numpy twin (relit_colour, lamp_visibility) at the pixel centres; moving
    the spheres or a lamp's scale changes uniforms only.
"""
from __future__ import annotations

import re

import numpy as np
import pytest
from test_ar_shader import GLSLANG, assert_compiles

from relight_addon.blender import relit_shader
from relight_addon.core.display import relit
from relight_addon.core.relight.line_shadow import bilinear

@pytest.mark.skipif(GLSLANG is None, reason="glslangValidator not found")
@pytest.mark.parametrize("stage", ["vert", "frag"])
def test_shader_compiles(stage):
    assert_compiles(stage, relit_shader.standalone_glsl(stage))


def test_constants_match_the_twin():
    from relight_addon.core.relight.sphere_shadow import EPS_ANGLE
    body = relit_shader.read_body("frag")
    const = dict(re.findall(r"const (?:int|float) (\w+) = ([^;]+);", body))
    assert int(const["MAX_LAMPS"]) == relit.MAX_LAMPS
    assert int(const["MAX_OBJECTS"]) == relit.MAX_OBJECTS
    assert int(const["MAX_SPHERES"]) == relit.MAX_SPHERES
    assert float(const["EPS_ANGLE"]) == EPS_ANGLE
    for stage in ("vert", "frag"):
        code = re.sub(r"/\*.*?\*/|//[^\n]*", "", relit_shader.read_body(stage), flags=re.S)
        assert not re.search(r"^\s*(in|out|uniform|layout)\b", code, flags=re.M)


def _objects(shift=(0.0, 0.0, 0.0)):
    rng = np.random.default_rng(4)
    out = []
    for base in ((-0.4, 0.1, 0.5), (0.5, -0.3, 0.35)):
        c = np.asarray(base) + np.asarray(shift) + rng.normal(scale=0.12, size=(6, 3))
        r = rng.uniform(0.05, 0.15, 6)
        hull = (c.mean(axis=0), 0.25)
        out.append((c, r, hull))
    return out


class RelitRenderer:
    """The shader on a standalone EGL context, drawing a square floor (z = 0, uv 0-1 over it)
    seen from above over [-half, half]^2 into a float32 framebuffer, with the texture
    ``t_img`` (h, w, 4) and the maps ``maps`` (lamps, h, w, 4), rows bottom first."""

    def __init__(self, size, half, t_img, maps):
        import moderngl
        self.ctx = ctx = moderngl.create_standalone_context(backend="egl")
        self.prog = prog = ctx.program(vertex_shader=relit_shader.standalone_glsl("vert"),
                                       fragment_shader=relit_shader.standalone_glsl("frag"))
        h = half
        quad = np.array([[-h, -h, 0, 0, 0], [h, -h, 0, 1, 0], [h, h, 0, 1, 1],
                         [-h, -h, 0, 0, 0], [h, h, 0, 1, 1], [-h, h, 0, 0, 1]], "f4")
        self.vao = ctx.vertex_array(prog, [(ctx.buffer(quad.tobytes()), "3f 2f", "pos", "uv")])
        prog["ModelViewProjectionMatrix"].write(
            np.diag([1 / h, 1 / h, -1e-3, 1.0]).astype("f4").T.tobytes())
        self.size = size
        self.fbo = ctx.simple_framebuffer(size, components=4, dtype="f4")
        t_img, maps = np.asarray(t_img, "f4"), np.asarray(maps, "f4")
        self.tex = ctx.texture(t_img.shape[1::-1], 4, t_img.tobytes(), dtype="f4")
        self.arr = ctx.texture_array((maps.shape[2], maps.shape[1], maps.shape[0]), 4,
                                     maps.tobytes(), dtype="f4")
        for t in (self.tex, self.arr):
            t.filter = (moderngl.LINEAR, moderngl.LINEAR)
            t.repeat_x = t.repeat_y = False
        prog["t_image"].value, prog["maps"].value = 0, 1

    def draw(self, uniforms):
        for k, v in uniforms.items():
            if k not in self.prog:
                continue
            if np.ndim(v):
                dt = np.int32 if k == "object_end" else np.float32
                self.prog[k].write(np.ascontiguousarray(v, dt).tobytes())
            else:
                self.prog[k].value = int(v)
        self.tex.use(0)
        self.arr.use(1)
        self.fbo.use()
        self.fbo.clear()
        self.vao.render()
        self.ctx.finish()
        w, h = self.size
        return np.frombuffer(self.fbo.read(components=4, dtype="f4"), "f4").reshape(h, w, 4)


def test_shader_draws_its_numpy_twin():
    pytest.importorskip("moderngl")
    size, half = 80, 1.5
    rng = np.random.default_rng(0)
    t_img = rng.uniform(0.2, 1.0, (6, 6, 4)).astype("f4")           # rows bottom first
    maps = rng.uniform(0.0, 1.0, (2, 6, 6, 4)).astype("f4")         # alpha: the direct part
    lamps = [(np.array([0.3, 0.6, 2.2]), 0.25), (np.array([-0.8, -0.5, 1.8]), 0.0)]
    try:
        r = RelitRenderer((size, size), half, t_img, maps)
    except Exception as exc:                          # no EGL / no llvmpipe here
        pytest.skip(f"no headless OpenGL context: {exc}")
    draw = r.draw

    x = -half + (np.arange(size) + 0.5) / size * 2 * half
    X, Y = np.meshgrid(x, x)
    P = np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], 1)
    u, v = (X.ravel() + half) / (2 * half), (Y.ravel() + half) / (2 * half)

    def twin(scales, objects):
        t = bilinear(t_img, u * 6, v * 6)[:, :3]
        m = np.stack([bilinear(maps[k], u * 6, v * 6) for k in range(2)])
        vis = np.stack([relit.lamp_visibility(P, p, r, objects) for p, r in lamps])
        return relit.relit_colour(t, m, scales, vis).reshape(size, size, 3), vis

    scales = [(1.0, 0.9, 0.8), (0.5, 0.5, 0.5)]
    objects = _objects()
    img = draw(relit.pack_uniforms(lamps, scales, objects))
    want, vis = twin(scales, objects)
    assert vis.min() < 0.2 and (vis > 0.999).mean() > 0.5          # real shadows, lit floor
    d = np.abs(img[..., :3] - want)
    off = (d.max(axis=-1) > 5e-3).sum()
    print(f"relit preview: |shader - twin| max {d.max():.2e}, mean {d.mean():.2e}, "
          f"{off} pixels over 5e-3")
    # float32 against float64: the point lamp's shadow edge is EPS_ANGLE wide, so a pixel on
    # it may fall on either side (measured: one pixel, 2e-2); elsewhere the AR shader's bound
    assert off <= 3 and d.max() < 0.1 and d.mean() < 1e-4 and np.all(img[..., 3] == 1.0)
    # uniforms only: spheres moved, a lamp dimmed, one object gone
    scales2 = [(0.2, 0.2, 0.2), (1.5, 1.0, 0.5)]
    objects2 = _objects((0.3, 0.2, 0.0))[:1]
    img2 = draw(relit.pack_uniforms(lamps, scales2, objects2))
    assert np.abs(img2[..., :3] - twin(scales2, objects2)[0]).mean() < 1e-4
    # a lamp with no place (radius < 0): that lamp unshadowed, the other still shadowed
    lamps_np = [lamps[0], (lamps[1][0], -1.0)]
    u4 = relit.pack_uniforms(lamps_np, scales, objects)
    t4 = bilinear(t_img, u * 6, v * 6)[:, :3]
    m4 = np.stack([bilinear(maps[k], u * 6, v * 6) for k in range(2)])
    vis4 = np.stack([relit.lamp_visibility(P, p, r, objects) for p, r in lamps_np])
    assert (vis4[1] == 1.0).all() and vis4[0].min() < 0.2
    want4 = relit.relit_colour(t4, m4, scales, vis4).reshape(size, size, 3)
    assert np.abs(draw(u4)[..., :3] - want4).mean() < 1e-4
    # whole objects only: one that does not fit the sphere slots is left out, not cut
    big = [(np.zeros((relit.MAX_SPHERES - 3, 3)), np.full(relit.MAX_SPHERES - 3, 0.1), None),
           objects[0]]
    packed = relit.pack_uniforms(lamps, scales, big)
    assert packed["n_objects"] == 1 and packed["object_end"][0] == relit.MAX_SPHERES - 3
    # no object: the relit colour without shadow, the maps' sum
    img3 = draw(relit.pack_uniforms(lamps, scales, []))
    t_only, _ = twin(scales, [])
    assert np.abs(img3[..., :3] - t_only).max() < 1e-4
