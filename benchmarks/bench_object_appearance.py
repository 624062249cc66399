"""How a virtual object itself looks in the relit room, against Cycles truth (issue 11).

    python benchmarks/bench_object_appearance.py [--size 48] [--samples 512] [--no-eevee]

The demo office of bench_moving_objects.py (seed 0, 2 lamps, 48 texels, photographed by a
512-sample Cycles bake, precomputed at medium) with its two grey (albedo 0.5) virtual objects,
a box on the floor and Suzanne on the desk, inserted by Update (Shadows: Exact, so that the
renders cost nothing per shading point).  Rendered from the office camera at 320 x 240:

* the relit room in Cycles with the real lamps at the powers the user gave, and after
  Match Lamp Powers (each lamp at its estimated exitance): the relit surfaces are emission, so
  they light the objects with the relit room's light, the lamps light them directly;
* the same in EEVEE (fresh process, saved copy), which lets emission light other surfaces only
  through its light probes: without one, and after ``relight.eevee_light`` (an irradiance
  volume over the relit room, baked);
* truth: the office with its true-albedo materials and the true lamp powers, objects present,
  twice with different seeds (the noise floor).

Scored over the objects' pixels (a camera ray per pixel hits one of them, and so do its eight
neighbours: no anti-aliased edges): CIEDE2000, colours over the 99th percentile of the truth
frame's luminance (as the family benchmark), and the mean luminance ratio (relit / truth).
Writes results/object_appearance.md and object_appearance.png.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, ROOT)
sys.path.insert(0, HERE)

import bench_moving_objects as bmo  # noqa: E402

RES = (320, 240)
LUM = np.array([0.2126, 0.7152, 0.0722])
EEVEE_SAMPLES = 64
EEVEE_SCRIPT = r"""
import sys
import bpy
bpy.ops.wm.open_mainfile(filepath=sys.argv[-2], load_ui=False)
scene = bpy.context.scene
scene.render.engine = "BLENDER_EEVEE"
scene.eevee.taa_render_samples = %d
bpy.ops.render.render()
bpy.data.images["Render Result"].save_render(sys.argv[-1])
print("EEVEE_DONE")
""" % EEVEE_SAMPLES


def setup(bpy):
    bmo.setup_render(bpy)
    r = bpy.context.scene.render
    r.resolution_x, r.resolution_y = RES
    s = r.image_settings
    s.file_format, s.color_depth, s.color_mode = "OPEN_EXR", "32", "RGB"
    bpy.context.scene.view_settings.view_transform = "Standard"


def read_exr(bpy, path):
    img = bpy.data.images.load(path, check_existing=False)
    try:
        px = bmo._pixels(img)[::-1, :, :3].astype(np.float64).copy()
    finally:
        bpy.data.images.remove(img)
    return px


def cycles(bpy, tmp, tag, samples, seed=0):
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.samples = samples
    scene.cycles.seed = seed
    path = os.path.join(tmp, f"{tag}.exr")
    t0 = time.perf_counter()
    bpy.ops.render.render()
    dt = time.perf_counter() - t0
    bpy.data.images["Render Result"].save_render(path)
    return read_exr(bpy, path), dt


def eevee(bpy, tmp, tag):
    blend = os.path.join(tmp, f"{tag}.blend")
    path = os.path.join(tmp, f"eevee_{tag}.exr")
    bpy.ops.wm.save_as_mainfile(filepath=blend, copy=True)
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", EEVEE_SCRIPT, blend, path],
                          capture_output=True, text=True, timeout=900)
    dt = time.perf_counter() - t0
    if "EEVEE_DONE" not in proc.stdout:
        return None, dt, (proc.stdout[-300:] + proc.stderr[-300:]).replace("\n", " ")
    return read_exr(bpy, path), dt, ""


def object_mask(bpy, objs):
    """(H, W) bool, top row first: pixels whose camera ray (and their 8 neighbours') hits one of
    ``objs`` first."""
    from mathutils import Vector
    scene = bpy.context.scene
    cam = scene.camera
    dg = bpy.context.evaluated_depsgraph_get()
    w, h = RES
    frame = [cam.matrix_world @ v for v in cam.data.view_frame(scene=scene)]
    # view_frame: top right, bottom right, bottom left, top left
    tr, br, bl, tl = frame
    origin = cam.matrix_world.translation
    names = {o.name for o in objs}
    hit = np.zeros((h, w), bool)
    for y in range(h):
        fy = (y + 0.5) / h
        left = tl.lerp(bl, fy)
        right = tr.lerp(br, fy)
        for x in range(w):
            p = left.lerp(right, (x + 0.5) / w)
            ok, _, _, _, obj, _ = scene.ray_cast(dg, origin, (p - origin).normalized())
            hit[y, x] = ok and obj is not None and obj.name in names
    inner = hit.copy()
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            inner &= np.roll(np.roll(hit, dy, 0), dx, 1)
    return inner, Vector


def score(img, truth, mask, white, de):
    d = de(img[mask], truth[mask], white)
    lum = (img[mask] @ LUM).mean() / max((truth[mask] @ LUM).mean(), 1e-300)
    return {"mean": float(d.mean()), "p95": float(np.percentile(d, 95)), "lum_ratio": float(lum)}


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", type=int, default=48)
    ap.add_argument("--samples", type=int, default=512, help="photo / truth bake samples")
    ap.add_argument("--render-samples", type=int, default=512)
    ap.add_argument("--preset", default="medium")
    ap.add_argument("--no-eevee", action="store_true")
    ap.add_argument("--out", default=os.path.join(HERE, "results", "object_appearance.md"))
    args = ap.parse_args(argv)
    t_start = time.perf_counter()
    import importlib

    import bpy

    from demo.office import make_photographed
    from relight_addon.core.texture.colour import delta_e_2000, linear_rgb_to_lab
    from scenes.addon import register_repo_addon
    from scenes.bake import bake_lighting
    from scenes.office import build_office
    register_repo_addon()
    settings = importlib.import_module(bmo.PKG + ".relight_addon.blender.state")
    tmp = tempfile.mkdtemp(prefix="relight_bench_appearance_")

    def de(x, y, white):
        return delta_e_2000(linear_rgb_to_lab(np.clip(x / white, 0, None)),
                            linear_rgb_to_lab(np.clip(y / white, 0, None)))

    bpy.ops.wm.read_factory_settings(use_empty=True)
    info = build_office(seed=0, n_lamps=2, texture_size=args.size)
    power = dict(info.lamp_powers)
    photo = bake_lighting(power, samples=args.samples, seed=0, texture_size=args.size)
    objs = bmo.add_objects(bpy)
    truth_mats = make_photographed(bpy, info, photo)
    scene = bpy.context.scene
    setup(bpy)
    mask, _ = object_mask(bpy, objs)
    print(f"object pixels: {int(mask.sum())}", flush=True)

    # truth first (before the precompute touches the materials): true albedo, true powers
    slots = {n: bpy.data.objects[n].material_slots[0].material for n in info.objects}
    for n in info.objects:
        bpy.data.objects[n].material_slots[0].material = truth_mats[n]
    truth, t_truth = cycles(bpy, tmp, "truth", args.render_samples, seed=0)
    truth2, _ = cycles(bpy, tmp, "truth2", args.render_samples, seed=1)
    for n in info.objects:
        bpy.data.objects[n].material_slots[0].material = slots[n]
    white = float(np.percentile(truth @ LUM, 99))
    rows = {"noise floor (truth, another seed)": score(truth2, truth, mask, white, de)}
    frames = {"truth": truth}

    bmo.set_mode(bpy, objs, "ignored")
    scene.relight.preset = args.preset
    assert bpy.ops.relight.precompute(preset=args.preset) == {"FINISHED"}
    bmo.set_mode(bpy, objs, "virtual", "EXACT")
    assert bpy.ops.relight.update() == {"FINISHED"}
    scales = settings.status(scene).get("exitance_scale")
    times = {}
    img, times["cycles"] = cycles(bpy, tmp, "relit_user", args.render_samples)
    rows["Cycles, lamps at the user's powers"] = score(img, truth, mask, white, de)
    frames["cycles_user"] = img
    if not args.no_eevee:
        img, times["eevee"], why = eevee(bpy, tmp, "user")
        rows["EEVEE, lamps at the user's powers"] = (score(img, truth, mask, white, de)
                                                     if img is not None else {"failed": why})
        if img is not None:
            frames["eevee_user"] = img
    assert bpy.ops.relight.match_lamp_powers() == {"FINISHED"}
    img, _ = cycles(bpy, tmp, "relit_matched", args.render_samples)
    rows["Cycles, after Match Lamp Powers"] = score(img, truth, mask, white, de)
    frames["cycles_matched"] = img
    if not args.no_eevee:
        img, _, why = eevee(bpy, tmp, "matched")
        rows["EEVEE, after Match Lamp Powers"] = (score(img, truth, mask, white, de)
                                                  if img is not None else {"failed": why})
        if img is not None:
            frames["eevee_matched"] = img
        t0 = time.perf_counter()
        assert bpy.ops.relight.eevee_light() == {"FINISHED"}
        times["volume"] = time.perf_counter() - t0
        img, _, why = eevee(bpy, tmp, "matched_probe")
        rows["EEVEE, after Match Lamp Powers and Light Virtual Objects in EEVEE"] = (
            score(img, truth, mask, white, de) if img is not None else {"failed": why})
        if img is not None:
            frames["eevee_probe"] = img
    # what the objects get from the relit room's emission alone: the lamps hidden from the
    # render (not switched off: the relit surfaces' drivers follow their power)
    for lm in power:
        bpy.data.objects[lm].hide_render = True
    img, _ = cycles(bpy, tmp, "room_only", args.render_samples)
    for lm in power:
        bpy.data.objects[lm].hide_render = False
    share = (img[mask] @ LUM).mean() / max((frames["cycles_matched"][mask] @ LUM).mean(), 1e-300)

    write(args, rows, frames, mask, white, scales, times, t_truth, share, power,
          time.perf_counter() - t_start)


def write(args, rows, frames, mask, white, scales, times, t_truth, share, power, seconds):
    lines = [
        "# A virtual object's own appearance in the relit room, against Cycles truth",
        "",
        f"Generated by `benchmarks/bench_object_appearance.py` (see its docstring) in "
        f"{seconds / 60:.1f} min.  The demo office (seed 0, lamps {power} W, {args.size} texels, "
        f"photo baked at {args.samples} samples), precomputed at `{args.preset}`; the grey "
        f"box and Suzanne of bench_moving_objects.py inserted by Update (Shadows: Exact).  "
        f"{RES[0]} x {RES[1]} frames from the office camera, Cycles {args.render_samples} "
        f"samples, EEVEE {EEVEE_SAMPLES} samples; {int(mask.sum())} object pixels (edges "
        f"left out).  Exitance factors the precompute estimated: "
        f"{[round(float(s), 3) for s in (scales or [])]}.",
        "",
        "| render | mean CIEDE2000 | p95 | luminance relit / truth |",
        "|---|---:|---:|---:|"]
    for k, r in rows.items():
        if "failed" in r:
            lines.append(f"| {k} | failed: {r['failed'][:120]} | | |")
        else:
            lines.append(f"| {k} | {r['mean']:.2f} | {r['p95']:.2f} | {r['lum_ratio']:.3f} |")
    lines += [
        "",
        f"Share of the objects' light that comes from the relit room's emission (Cycles, lamps "
        f"hidden / shown after Match Lamp Powers, mean luminance over the object pixels): "
        f"{share:.3f}.  Render times: Cycles {times.get('cycles', 0):.1f} s, EEVEE (fresh "
        f"process, with start-up) {times.get('eevee', float('nan')):.1f} s; the truth frame "
        f"{t_truth:.1f} s; Light Virtual Objects in EEVEE (`relight.eevee_light`: the "
        f"irradiance volume placed and baked, 0.25 m spacing) "
        f"{times.get('volume', float('nan')):.1f} s.",
        "", "![frames](object_appearance.png)", "",
        "object_appearance.png: truth, Cycles (user's powers, matched), EEVEE (user's powers, "
        "matched); the object pixels scored are outlined in the truth panel.", ""]
    with open(args.out, "w") as f:
        f.write("\n".join(lines))
    json.dump({"rows": rows, "share": share, "scales": scales},
              open(args.out.replace(".md", "_raw.json"), "w"), indent=1)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    keys = [k for k in ("truth", "cycles_user", "cycles_matched", "eevee_user", "eevee_matched",
                        "eevee_probe")
            if k in frames]
    fig, axes = plt.subplots(1, len(keys), figsize=(3.2 * len(keys), 2.6))
    for ax, k in zip(np.atleast_1d(axes), keys):
        ax.imshow(np.clip(frames[k] / white, 0, 1) ** (1 / 2.2))
        if k == "truth":
            ax.contour(mask, levels=[0.5], colors="r", linewidths=0.5)
        ax.set_title(k, fontsize=8)
        ax.axis("off")
    fig.tight_layout()
    fig.savefig(args.out.replace(".md", ".png"), dpi=80)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
