"""Cycles references for the AR tests and benchmark, each in a fresh bpy process and cached on
disk like scenes/bake.py (``$RELIGHT_BAKE_CACHE`` or ``.cache/bakes``, key = the inputs, the
settings and bpy's version).

``cycles_ao_bake(triangles, uvs, size, samples)`` -> (image (H, W) float32 rows bottom first,
seconds): Cycles' own AO bake of the object (flat shaded, alone in the scene, AO distance 10 m),
the time of ``bpy.ops.object.bake`` alone.
"""
from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
import tempfile

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

_AO_SCRIPT = r'''
import json, sys, time
import bpy, numpy as np
args = json.loads(sys.argv[-1])
d = np.load(args["input"])
tri, uv = d["triangles"], d["uvs"]
H, W = args["size"]
bpy.ops.wm.read_factory_settings(use_empty=True)
sc = bpy.context.scene
sc.render.engine = "CYCLES"
sc.cycles.device = "CPU"
sc.cycles.samples = args["samples"]
sc.cycles.use_adaptive_sampling = False
sc.cycles.use_denoising = False
sc.cycles.seed = args["seed"]
world = bpy.data.worlds.new("w"); sc.world = world
world.light_settings.distance = args["distance"]
me = bpy.data.meshes.new("obj")
verts = tri.reshape(-1, 3)
faces = np.arange(len(verts)).reshape(-1, 3)
me.from_pydata(verts.tolist(), [], faces.tolist())
layer = me.uv_layers.new(name="UVMap")
layer.data.foreach_set("uv", uv.reshape(-1).astype(np.float32))
ob = bpy.data.objects.new("obj", me); sc.collection.objects.link(ob)
img = bpy.data.images.new("ao", W, H, float_buffer=True, alpha=False)
mat = bpy.data.materials.new("m"); mat.use_nodes = True; ob.data.materials.append(mat)
node = mat.node_tree.nodes.new("ShaderNodeTexImage"); node.image = img
mat.node_tree.nodes.active = node
bpy.context.view_layer.objects.active = ob; ob.select_set(True)
sc.render.bake.margin = 0
t = time.perf_counter()
bpy.ops.object.bake(type="AO")
sec = time.perf_counter() - t
px = np.empty(W * H * 4, np.float32); img.pixels.foreach_get(px)
np.savez(args["output"], image=px.reshape(H, W, 4)[..., 0], seconds=sec)
'''


def cache_dir():
    return os.environ.get("RELIGHT_BAKE_CACHE") or os.path.join(ROOT, ".cache", "bakes")


def _bpy_version():
    import importlib.metadata
    try:
        return importlib.metadata.version("bpy")
    except importlib.metadata.PackageNotFoundError:
        return "none"


def cycles_ao_bake(triangles, uvs, size, samples=256, seed=0, distance=10.0):
    tri = np.ascontiguousarray(triangles, np.float64)
    uv = np.ascontiguousarray(uvs, np.float64)
    h = hashlib.sha256()
    for a in (tri, uv):
        h.update(a.tobytes())
    h.update(json.dumps([list(size), samples, seed, distance, _bpy_version(), "ao1"]).encode())
    path = os.path.join(cache_dir(), f"ar_ao_{h.hexdigest()[:24]}.npz")
    if not os.path.exists(path):
        os.makedirs(cache_dir(), exist_ok=True)
        with tempfile.TemporaryDirectory() as tmp:
            inp = os.path.join(tmp, "in.npz")
            out = os.path.join(tmp, "out.npz")
            np.savez(inp, triangles=tri, uvs=uv)
            script = os.path.join(tmp, "bake.py")
            with open(script, "w") as f:
                f.write(_AO_SCRIPT)
            args = json.dumps({"input": inp, "output": out, "size": list(size),
                               "samples": samples, "seed": seed, "distance": distance})
            subprocess.run([sys.executable, script, args], check=True, capture_output=True,
                           timeout=1800)
            tmp_path = f"{path}.{os.getpid()}.tmp.npz"
            os.replace(out, tmp_path)
            os.replace(tmp_path, path)
    d = np.load(path)
    return d["image"].astype(np.float32), float(d["seconds"])


_GLOSSY_SCRIPT = r'''
import json, sys, time
import bpy, numpy as np
args = json.loads(sys.argv[-1])
bpy.ops.wm.read_factory_settings(use_empty=True)
sc = bpy.context.scene
sc.render.engine = "CYCLES"
sc.cycles.device = "CPU"
sc.cycles.samples = args["samples"]
sc.cycles.use_adaptive_sampling = False
sc.cycles.use_denoising = False
sc.cycles.max_bounces = 1
sc.cycles.glossy_bounces = 1
sc.view_settings.view_transform = "Standard"
sc.render.resolution_x = sc.render.resolution_y = args["res"]
sc.render.film_transparent = False
world = bpy.data.worlds.new("w"); sc.world = world; world.use_nodes = True
env = world.node_tree.nodes.new("ShaderNodeTexEnvironment")
env.image = bpy.data.images.load(args["hdri"])
world.node_tree.links.new(env.outputs[0], world.node_tree.nodes["Background"].inputs[0])
bpy.ops.mesh.primitive_uv_sphere_add(segments=128, ring_count=64, radius=1.0)
ob = bpy.context.active_object
bpy.ops.object.shade_smooth()
mat = bpy.data.materials.new("m"); mat.use_nodes = True; nt = mat.node_tree
for n in list(nt.nodes):
    if n.bl_idname != "ShaderNodeOutputMaterial":
        nt.nodes.remove(n)
g = nt.nodes.new("ShaderNodeBsdfAnisotropic")     # "Glossy BSDF"
g.distribution = "GGX"
g.inputs["Roughness"].default_value = args["roughness"]
g.inputs["Color"].default_value = (1, 1, 1, 1)
nt.links.new(g.outputs[0], nt.nodes["Material Output"].inputs[0])
ob.data.materials.append(mat)
cam = bpy.data.objects.new("cam", bpy.data.cameras.new("cam")); sc.collection.objects.link(cam)
sc.camera = cam
cam.data.type = "ORTHO"; cam.data.ortho_scale = 2.0
cam.location = (5.0, 0.0, 0.0); cam.rotation_euler = (np.pi / 2, 0.0, np.pi / 2)   # looks along -X
sc.render.image_settings.file_format = "OPEN_EXR"
sc.render.filepath = args["output"] + ".exr"
t = time.perf_counter()
bpy.ops.render.render(write_still=True)
sec = time.perf_counter() - t
im = bpy.data.images.load(args["output"] + ".exr")
px = np.array(im.pixels[:], np.float32).reshape(args["res"], args["res"], 4)[..., :3]
np.savez(args["output"], image=px, seconds=sec)
'''


def cycles_glossy_sphere(hdri, roughness, res=64, samples=256):
    """(image (res, res, 3) float32 rows bottom first, seconds): Cycles' render of a unit sphere
    with a white GGX Glossy BSDF of ``roughness`` under the World map ``hdri`` (a path), seen by
    an orthographic camera (2 m wide) on +X looking along -X (image right = +Y, up = +Z)."""
    h = hashlib.sha256()
    with open(hdri, "rb") as f:
        h.update(f.read())
    h.update(json.dumps([roughness, res, samples, _bpy_version(), "glossy1"]).encode())
    path = os.path.join(cache_dir(), f"ar_glossy_{h.hexdigest()[:24]}.npz")
    if not os.path.exists(path):
        os.makedirs(cache_dir(), exist_ok=True)
        with tempfile.TemporaryDirectory() as tmp:
            script = os.path.join(tmp, "render.py")
            with open(script, "w") as f:
                f.write(_GLOSSY_SCRIPT)
            out = os.path.join(tmp, "out")
            args = json.dumps({"hdri": hdri, "roughness": roughness, "res": res,
                               "samples": samples, "output": out})
            subprocess.run([sys.executable, script, args], check=True, capture_output=True,
                           timeout=1800)
            tmp_path = f"{path}.{os.getpid()}.tmp.npz"
            os.replace(out + ".npz", tmp_path)
            os.replace(tmp_path, path)
    d = np.load(path)
    return d["image"].astype(np.float32), float(d["seconds"])
