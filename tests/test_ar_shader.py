"""The viewport's sphere-shadow shader under an environment (blender/shaders/ar_shadow_*.glsl).

(a) both stages, wrapped by ar_shader.standalone_glsl(), compile with glslangValidator;
(b) the GLSL constants equal the numpy side's;
(c) the shader RUNS on a headless OpenGL context (moderngl, EGL, Mesa llvmpipe): a ground plane
    under Suzanne's 32 spheres and the studio map's lights, drawn top-down, read back in
    float32 and compared pixel by pixel with its numpy twin env_shadow_factor (default
    weighting) at the pixel centres.
"""
from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import tempfile

import numpy as np
import pytest

import ar_truth as T
from relight_addon.blender import ar_shader

GLSLANG = next((p for p in (os.path.join(os.path.dirname(sys.executable), "glslangValidator"),
                            shutil.which("glslangValidator")) if p and os.path.exists(p)), None)
HDRIS = T.bundled_hdris()


@pytest.mark.skipif(GLSLANG is None, reason="glslangValidator not found")
@pytest.mark.parametrize("stage", ["vert", "frag"])
def test_shader_compiles(stage):
    assert_compiles(stage, ar_shader.standalone_glsl(stage))


def assert_compiles(stage, source):
    """glslangValidator accepts ``source`` as a ``stage`` ('vert' or 'frag') shader."""
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "shader." + stage)
        with open(path, "w") as f:
            f.write(source)
        run = subprocess.run([GLSLANG, "-S", stage, path], capture_output=True, text=True,
                             timeout=60)
    assert run.returncode == 0, run.stdout + run.stderr


def test_constants_match_the_twin():
    from relight_addon.core.ar.cap_filter import CAP_ANGLES
    from relight_addon.core.ar.main_light import MAX_LIGHTS
    from relight_addon.core.ar.shader_data import MAX_SPHERES
    from relight_addon.core.relight.sphere_shadow import EPS_ANGLE, SUN_DISTANCE
    body = ar_shader.read_body("frag")
    const = dict(re.findall(r"const (?:int|float) (\w+) = ([^;]+);", body))
    assert int(const["MAX_SPHERES"]) == MAX_SPHERES == ar_shader.MAX_SPHERES
    assert int(const["MAX_LIGHTS"]) == MAX_LIGHTS == ar_shader.MAX_LIGHTS
    assert int(const["N_CAP"]) == len(CAP_ANGLES) == ar_shader.N_CAP
    assert float(const["EPS_ANGLE"]) == EPS_ANGLE
    assert float(const["SUN_DISTANCE"]) == SUN_DISTANCE
    for stage in ("vert", "frag"):
        code = re.sub(r"/\*.*?\*/|//[^\n]*", "", ar_shader.read_body(stage), flags=re.S)
        assert not re.search(r"^\s*(in|out|uniform|layout)\b", code, flags=re.M)


class Renderer:
    """The shader on a standalone EGL context, drawing a square receiver (z = 0, normal +z)
    seen from above over [-half, half]^2 into a float32 framebuffer."""

    def __init__(self, size, half):
        import moderngl
        self.moderngl = moderngl
        self.ctx = moderngl.create_standalone_context(backend="egl")
        self.prog = self.ctx.program(vertex_shader=ar_shader.standalone_glsl("vert"),
                                     fragment_shader=ar_shader.standalone_glsl("frag"))
        h = half
        quad = np.array([[-h, -h, 0, 0, 0, 1], [h, -h, 0, 0, 0, 1], [h, h, 0, 0, 0, 1],
                         [-h, -h, 0, 0, 0, 1], [h, h, 0, 0, 0, 1], [-h, h, 0, 0, 0, 1]], "f4")
        self.vbo = self.ctx.buffer(quad.tobytes())
        self.vao = self.ctx.vertex_array(self.prog, [(self.vbo, "3f 3f", "pos", "nor")])
        mvp = np.diag([1 / h, 1 / h, -1e-3, 1.0]).astype("f4")
        self.prog["ModelViewProjectionMatrix"].write(mvp.T.tobytes())
        self.size = size
        self.fbo = self.ctx.simple_framebuffer(size, components=4, dtype="f4")
        self.half = half

    def set(self, uniforms, textures):
        mgl = self.moderngl
        for k, v in uniforms.items():
            if k not in self.prog:
                continue
            if np.ndim(v):
                self.prog[k].write(np.ascontiguousarray(v, np.float32).tobytes())
            else:
                self.prog[k].value = v.item() if hasattr(v, "item") else v
        im, ct = textures["irradiance_map"], textures["cap_tables"]
        self.t0 = self.ctx.texture((im.shape[1], im.shape[0]), 3, im.tobytes(), dtype="f4")
        self.t1 = self.ctx.texture_array((ct.shape[2], ct.shape[1], ct.shape[0]), 3,
                                         ct.tobytes(), dtype="f4")
        for t in (self.t0, self.t1):
            t.repeat_x, t.repeat_y = True, False
            t.filter = (mgl.LINEAR, mgl.LINEAR)
        self.prog["irradiance_map"].value = 0
        self.prog["cap_tables"].value = 1
        self.t0.use(0)
        self.t1.use(1)

    def draw(self):
        self.fbo.use()
        self.fbo.clear()
        self.vao.render()
        self.ctx.finish()
        w, h = self.size
        return np.frombuffer(self.fbo.read(components=4, dtype="f4"), "f4").reshape(h, w, 4)

    def pixel_points(self):
        w, h = self.size
        x = -self.half + (np.arange(w) + 0.5) / w * 2 * self.half
        y = -self.half + (np.arange(h) + 0.5) / h * 2 * self.half
        X, Y = np.meshgrid(x, y)
        return np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], 1)


@pytest.mark.skipif(not HDRIS, reason="the bpy wheel's HDRIs are not installed")
def test_shader_draws_its_numpy_twin():
    moderngl = pytest.importorskip("moderngl")
    import ar_scenes as S
    from relight_addon.core.ar.env_shadow import env_shadow_factor
    from relight_addon.core.ar.lighting import prepare_environment
    from relight_addon.core.ar.shader_data import shadow_textures, shadow_uniforms
    from relight_addon.core.relight.spheres import fit_spheres, silhouette_sphere
    try:
        r = Renderer((96, 96), 1.6)
    except Exception as exc:                          # no EGL / no llvmpipe here
        pytest.skip(f"no headless OpenGL context: {exc}")
    del moderngl
    lit = prepare_environment(T.load_exr(HDRIS["studio"]))   # four lights near the horizon
    tri = S.suzanne()
    c, rad = fit_spheres(tri, 32, seed=0)
    hull = silhouette_sphere(tri)
    P = r.pixel_points()
    N = np.tile([0.0, 0.0, 1.0], (len(P), 1))
    r.set(shadow_uniforms(lit, c, rad, hull), shadow_textures(lit))
    img = r.draw()
    twin = env_shadow_factor(P, N, c, rad, lit, hull).reshape(96, 96, 3)
    assert twin.min() < 0.6 and len(lit.lights) >= 2            # a real shadow, real lights
    d = np.abs(img[..., :3] - twin)
    # float32 against float64: measured max 1.9e-3 (at a light's penumbra edge), mean 1.1e-5
    assert d.max() < 5e-3 and d.mean() < 1e-4
    assert np.all(img[..., 3] == 1.0)
    # spheres are uniforms: move them, no recompilation, the twin follows
    c2 = c + [0.3, -0.2, 0.0]
    r.set(shadow_uniforms(lit, c2, rad, (hull[0] + [0.3, -0.2, 0.0], hull[1])),
          shadow_textures(lit))
    img2 = r.draw()
    twin2 = env_shadow_factor(P, N, c2, rad, lit, (hull[0] + [0.3, -0.2, 0.0], hull[1]))
    assert np.abs(img2[..., :3] - twin2.reshape(96, 96, 3)).mean() < 1e-4
    # no spheres: no shadow
    r.set(shadow_uniforms(lit, np.zeros((0, 3)), np.zeros(0)), shadow_textures(lit))
    assert np.abs(r.draw()[..., :3] - 1.0).max() < 1e-5
