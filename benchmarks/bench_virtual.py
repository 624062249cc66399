"""Virtual lamps (issue 11): insert time on the demo office and accuracy against Cycles truth.
Writes results/virtual_lamps.md.

The office of the demo (scenes.office, 2 lamps of 40 W, 48 texels per surface), photographed by
a 512-sample Cycles bake; precompute per preset (per texel); then each virtual lamp (a point, a
spot and an area light, added after the precompute) is inserted with
``core.relight.virtual.add_lamps`` (what Update runs: its direct light on every leaf, its basis,
its direct light per texel, its map) and timed.  Truth: Cycles bakes of the true-albedo office
with the virtual lamp alone (real lamps off) and with the real lamps too (seed 1, 512 samples).

    python benchmarks/bench_virtual.py [--presets draft,medium]
"""
from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, ROOT)

SIZE = 48
SAMPLES = 512
LUM = np.array([0.2126, 0.7152, 0.0722])
VIRTUAL = {
    "point": dict(type="POINT", energy=150.0, location=(3.8, 1.0, 1.6), radius=0.1),
    "spot": dict(type="SPOT", energy=400.0, location=(0.6, 3.6, 2.2), radius=0.05,
                 target=(1.6, 2.0, 0.7)),
    "area": dict(type="AREA", energy=60.0, location=(4.2, 3.0, 2.0), size=0.5,
                 target=(4.2, 3.0, 0.0)),
    "disk": dict(type="AREA", shape="DISK", energy=80.0, location=(1.2, 2.6, 2.4), size=0.6,
                 target=(1.6, 2.0, 0.0)),
    # an emissive mesh with Relight Role 'virtual' (both sides emit, as in Cycles); energy is
    # its Emission strength
    "panel": dict(type="EMISSIVE", energy=12.0, location=(3.6, 1.2, 2.3), size=(0.6, 0.4)),
}


def _panel(bpy, name, spec):
    """A plane facing down with an Emission-only material, Relight Role 'virtual'."""
    bpy.ops.mesh.primitive_plane_add(size=1.0, location=spec["location"])
    obj = bpy.context.active_object
    obj.name = name
    obj.scale = (*spec["size"], 1.0)
    obj.rotation_euler = (np.pi, 0.0, 0.0)
    mat = bpy.data.materials.new(name + "Glow")
    nt = mat.node_tree
    for n in list(nt.nodes):
        nt.nodes.remove(n)
    emit = nt.nodes.new("ShaderNodeEmission")
    emit.inputs["Strength"].default_value = spec["energy"]
    nt.links.new(emit.outputs[0], nt.nodes.new("ShaderNodeOutputMaterial").inputs["Surface"])
    obj.data.materials.append(mat)
    obj.relight_role = "virtual"
    bpy.context.view_layer.update()
    return obj


def _lamp_name(name, spec):
    return f"{name}/{name}Glow" if spec["type"] == "EMISSIVE" else name


def _light(bpy, name, spec):
    from mathutils import Vector
    if spec["type"] == "EMISSIVE":
        return _panel(bpy, name, spec)
    light = bpy.data.lights.new(name, spec["type"])
    light.energy = spec["energy"]
    if spec["type"] in ("POINT", "SPOT"):
        light.shadow_soft_size = spec["radius"]
    if spec["type"] == "SPOT":
        light.spot_size, light.spot_blend = 1.0, 0.3
    if spec["type"] == "AREA":
        light.size = spec["size"]
        light.shape = spec.get("shape", "SQUARE")
    obj = bpy.data.objects.new(name, light)
    obj.location = spec["location"]
    if "target" in spec:
        d = Vector(spec["target"]) - Vector(spec["location"])
        obj.rotation_euler = d.to_track_quat("-Z", "Y").to_euler()
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.view_layer.update()
    return obj


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--presets", default="draft,medium")
    args = ap.parse_args(argv)
    import bpy

    from relight_addon.blender.read import read_scene
    from relight_addon.core.relight.shadowfree import ShadowFreeOptions, shadow_free
    from relight_addon.core.relight.virtual import add_lamps
    from relight_addon.core.texture.colour import delta_e_2000, linear_rgb_to_lab
    from scenes.addon import register_repo_addon
    from scenes.bake import bake_lighting
    from scenes.office import build_office
    from demo.office import make_photographed
    register_repo_addon()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    info = build_office(seed=0, n_lamps=2, texture_size=SIZE)
    power = dict(info.lamp_powers)
    off = {k: 0.0 for k in power}
    real_truth = {k: bake_lighting({j: (v if j == k else 0.0) for j, v in power.items()},
                                   samples=SAMPLES, seed=1, texture_size=SIZE) for k in power}
    photo = bake_lighting(power, samples=SAMPLES, seed=0, texture_size=SIZE)
    truth, objs = {}, {}
    for name, spec in VIRTUAL.items():
        objs[name] = _light(bpy, name, spec)
        truth[name] = bake_lighting({**off, **{n: 0.0 for n, o in objs.items() if
                                               o.type == "LIGHT"}, name: spec["energy"]},
                                    samples=SAMPLES, seed=1, texture_size=SIZE,
                                    objects=info.objects if spec["type"] == "EMISSIVE" else None)
        objs[name].hide_render = True                 # not read into the precompute
    make_photographed(bpy, info, photo)
    rows = []
    for preset in args.presets.split(","):
        for o in objs.values():
            o.hide_render = True
        data, _ = read_scene(bpy.context)
        t0 = time.perf_counter()
        res = shadow_free(data, ShadowFreeOptions(preset=preset))
        t_pre = time.perf_counter() - t0
        order = [im.name.replace(" photo", "") for im in data.images]
        tm = res.texel_map

        def tex(imgs):
            return tm.gather([np.asarray(imgs[n], np.float32) for n in order]).astype(np.float64)

        for name, spec in VIRTUAL.items():
            objs[name].hide_render = False
            bpy.context.view_layer.update()
            vdata, report = read_scene(bpy.context, virtual={name})
            k = vdata.lamp_names.index(_lamp_name(name, spec))
            sub = vdata.lights
            sel = np.flatnonzero(sub.lamp == k)
            import dataclasses
            rows_v = dataclasses.replace(sub, **{f.name: getattr(sub, f.name)[sel]
                                                 for f in dataclasses.fields(sub)})
            rows_v.lamp = np.zeros(len(sel), np.int32)
            t0 = time.perf_counter()
            res2 = add_lamps(res, rows_v, [_lamp_name(name, spec)])
            t_add = time.perf_counter() - t0
            objs[name].hide_render = True
            full = tex({n: sum(real_truth[k][n] for k in power) for n in order})
            tv = tex(truth[name])
            white = np.percentile((full + tv) @ LUM, 99)

            def de(x, y):
                return float(delta_e_2000(linear_rgb_to_lab(np.clip(x / white, 0, None)),
                                          linear_rgb_to_lab(np.clip(y / white, 0, None))).mean())
            figures = {}
            for label, I, want in (("real lamps off", [0.0, 0.0, 1.0], tv),
                                   ("real lamps on", [1.0, 1.0, 1.0], full + tv)):
                out = res2.relit(I)
                got = tm.gather([out[i] for i in range(len(order))]).astype(np.float64)
                figures[label] = (de(got, want), de(tex(photo) * (1 if label.endswith("on") else 0),
                                                     want))
            rows.append((preset, name, t_pre, t_add, figures))
            print(preset, name, f"precompute {t_pre:.1f} s, insert {t_add:.2f} s", figures,
                  flush=True)
    load = os.getloadavg()
    lines = ["# Virtual lamps: insert time and accuracy (office)", "",
             "Generated by `benchmarks/bench_virtual.py`: the demo office (48 texels per "
             "surface, 2 real lamps), photographed by a 512-sample Cycles bake; each virtual "
             "lamp inserted after the per-texel precompute with `add_lamps` (what Update runs) "
             "and compared with Cycles bakes of the true-albedo office (seed 1): the virtual "
             "lamp alone, and with the real lamps.  CIEDE2000 means; in brackets the photo "
             "unchanged (or black with the real lamps off).  Seed 000: a virtual lamp inserted "
             f"in 7.8 s.  Load average during the run: {load[0]:.1f} (2 cores).", "",
             "| preset | virtual lamp | precompute | insert | real lamps off | real lamps on |",
             "|---|---|---:|---:|---:|---:|"]
    for preset, name, t_pre, t_add, f in rows:
        a, b = f["real lamps off"], f["real lamps on"]
        lines.append(f"| {preset} | {name} | {t_pre:.1f} s | {t_add:.2f} s | {a[0]:.2f} "
                     f"({a[1]:.1f}) | {b[0]:.2f} ({b[1]:.1f}) |")
    with open(os.path.join(HERE, "results", "virtual_lamps.md"), "w") as f:
        f.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
