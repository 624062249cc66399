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
