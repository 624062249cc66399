"""`make demo` (part 2): relight the embedded, "photographed" office through the Blender operator.

Steps (all headless, bpy as a module):

1. Build the office of the shadow-free harness (``demo_scenes.office``, 2 lamps, 48^2 texels),
   bake its original lighting with Cycles (DIFFUSE, cached under .cache/bakes) and turn it into a
   photo-textured model: each surface object gets an image ``"<obj> photo"`` holding the bake (the
   outgoing radiance as the photo's linear texel value, float, packed), which replaces the true
   albedo as its material's Base Color image.  The true-albedo materials are kept aside as
   ``"<obj> truth material"`` (fake user) for the Cycles truth.
2. Register the add-on and run ``bpy.ops.relight.precompute(preset=...)`` (per-texel shadow
   removal: relit material = T_final x sum_k I_k M_k -> Emission, I_k driven by the lamp
   energy).
3. Keyframes on the light data ``energy`` (made constant where the action API allows; the
   values at the keyed frames are exact either way), P = 40 W, the original power of each:

   ======  ========  ========  ==========================
   frame   Lamp A    Lamp B    meaning
   ======  ========  ========  ==========================
   1       P         P         original lighting (= photo)
   2       0         P         lamp A off
   3       0         2 P       lamp A off, lamp B doubled
   ======  ========  ========  ==========================

   Frames 1..3 are rendered with EEVEE from the office camera -> out/frame_0001.png ...
4. Cycles truth for frames 1 and 3: the true-albedo Principled materials are swapped in, the lamps
   set to the frame's powers, Cycles renders (64 samples, 16 diffuse bounces as the bakes,
   OpenImageDenoise on by default: at 64 samples the raw render is grainy, mean |diff| of frame 1
   3.4/255 without vs 2.3/255 with it; ``--no-denoise`` for the raw one), then the relit
   materials are put back.
5. Frame 4: a virtual point lamp (not in the photo) and a virtual grey box (Exact shadows) are
   added and ``bpy.ops.relight.update()`` puts them into the maps (no new solve); lamp A off,
   lamp B at P, the virtual lamp on: EEVEE and its Cycles truth (the box really in the scene).
6. out/demo_side_by_side.png: original (EEVEE frame 1) | lamp A off, B doubled (frame 3) |
   virtual lamp and box (frame 4) | Cycles truth of frame 4 (``--results PATH`` copies it, e.g.
   to benchmarks/results/demo_office.png: `make demo-results`); out/demo_diff.png: |relit -
   truth| x 4 for frames 1, 3 and 4; out/demo.blend (everything packed, relit materials
   assigned, frame 1).  The demo writes under ``--out`` only.

The photo's shadows of lamp A are removed from T_final (per texel), so with lamp A off the
relit frames lose them as the Cycles truth does.  The frame-3 difference is the shadow removal's
and the radiosity solver's error, over a floor measured on frame 1 (photo texels vs pixels,
Cycles noise).

Colour: Standard view transform, exposure 0, no look; sRGB PNGs, 8 bits.  The relit materials are
emission-only, so EEVEE shows the texel values directly.
"""
from __future__ import annotations

import argparse
import os
import time

import numpy as np

from scenes.addon import register_repo_addon

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FRAMES = (1, 2, 3)
VIRTUAL_AT, VIRTUAL_W = (1.2, 2.6, 2.0), 80.0       # a virtual point lamp (frame 4)
BOX_AT, BOX_SIZE = (3.6, 1.0, 0.25), 0.5            # a virtual box on the floor (frame 4)


def lamp_schedule(powers):
    """{frame: {lamp: W}} for the three frames (see the module docstring)."""
    pa, pb = powers["Lamp A"], powers["Lamp B"]
    return {1: {"Lamp A": pa, "Lamp B": pb},
            2: {"Lamp A": 0.0, "Lamp B": pb},
            3: {"Lamp A": 0.0, "Lamp B": 2.0 * pb}}


def _eevee_engine(scene):
    before = scene.render.engine
    for e in ("BLENDER_EEVEE_NEXT", "BLENDER_EEVEE"):
        try:
            scene.render.engine = e
            return e
        except TypeError:
            continue
        finally:
            scene.render.engine = before
    return None


def _setup_render(scene, res, eevee_samples, cycles_samples, denoise):
    r = scene.render
    r.resolution_x, r.resolution_y = res
    r.resolution_percentage = 100
    r.film_transparent = False
    r.use_compositing = False
    r.use_sequencer = False
    r.use_file_extension = True
    ims = r.image_settings
    ims.file_format = "PNG"
    ims.color_mode = "RGB"
    ims.color_depth = "8"
    vs = scene.view_settings
    vs.view_transform = "Standard"
    vs.look = "None"
    vs.exposure = 0.0
    vs.gamma = 1.0
    scene.frame_start, scene.frame_end = FRAMES[0], FRAMES[-1]
    scene.eevee.taa_render_samples = int(eevee_samples)
    c = scene.cycles
    c.device = "CPU"
    c.samples = int(cycles_samples)
    c.use_adaptive_sampling = False
    c.use_denoising = bool(denoise)
    c.seed = 0
    c.use_animated_seed = False
    c.diffuse_bounces = c.max_bounces = 16          # as the bakes (bake.py)
    c.sample_clamp_direct = c.sample_clamp_indirect = 0.0


def make_photographed(bpy, info, bakes):
    """Photo images replace the albedo in each object's material; returns {obj: truth material}."""
    from scenes.office import _new_image
    truth = {}
    for obj_name in info.objects:
        mat = bpy.data.materials[info.materials[obj_name]]
        keep = mat.copy()
        keep.name = f"{obj_name} truth material"
        keep.use_fake_user = True
        truth[obj_name] = keep
        photo = _new_image(bpy, f"{obj_name} photo", np.asarray(bakes[obj_name], np.float32))
        tex = mat.node_tree.nodes["Albedo"]
        tex.image = photo
        tex.name = tex.label = "Photo"
    return truth


def _set_energies(bpy, powers):
    for name, p in powers.items():
        bpy.data.objects[name].data.energy = float(p)


def _read_png(bpy, path):
    img = bpy.data.images.load(path, check_existing=False)
    try:
        w, h = img.size
        px = np.empty(w * h * 4, np.float32)
        img.pixels.foreach_get(px)
    finally:
        bpy.data.images.remove(img)
    return px.reshape(h, w, 4)[::-1, :, :3].copy()       # top row first, sRGB-encoded [0, 1]


def srgb_to_linear(c):
    c = np.asarray(c, np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def side_by_side(panels, titles, note, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    h, w = panels[0].shape[:2]
    scale = 1.0 / 100
    fig = plt.figure(figsize=(len(panels) * w * scale + 0.1 * (len(panels) + 1),
                              h * scale + 0.75), dpi=100)
    for i, (img, title) in enumerate(zip(panels, titles)):
        left = (0.1 + i * (w * scale + 0.1)) / fig.get_figwidth()
        ax = fig.add_axes([left, 0.45 / fig.get_figheight(), w * scale / fig.get_figwidth(),
                           h * scale / fig.get_figheight()])
        ax.imshow(np.clip(img, 0, 1), interpolation="nearest")
        ax.set_axis_off()
        ax.set_title(title, fontsize=9)
    fig.text(0.5, 0.04, note, ha="center", va="bottom", fontsize=7.5)
    fig.savefig(path, dpi=100, facecolor="white")
    plt.close(fig)


def main(argv=None):
    parser = argparse.ArgumentParser(description="Relight the photographed office (EEVEE) and "
                                                 "compare with Cycles truth.")
    parser.add_argument("--out", default="out")
    parser.add_argument("--preset", default="medium")
    parser.add_argument("--texture-size", type=int, default=48)
    parser.add_argument("--bake-samples", type=int, default=256)
    parser.add_argument("--res", default="320x240")
    parser.add_argument("--eevee-samples", type=int, default=8)
    parser.add_argument("--cycles-samples", type=int, default=64)
    parser.add_argument("--no-denoise", dest="denoise", action="store_false",
                        help="Cycles truth without the OpenImageDenoise pass (noisier)")
    parser.add_argument("--json", default="",
                        help="also write the timings and differences there (JSON)")
    parser.add_argument("--results", default="",
                        help="also copy the side-by-side picture there (e.g. "
                             "benchmarks/results/demo_office.png)")
    args = parser.parse_args(argv)
    res = tuple(int(v) for v in args.res.lower().split("x"))

    import bpy

    from scenes.bake import bake_lighting
    from scenes.office import build_office

    times = {}
    out = os.path.abspath(args.out)
    os.makedirs(out, exist_ok=True)
    t_all = time.perf_counter()

    # 1. The photographed office.
    bpy.ops.wm.read_factory_settings(use_empty=True)
    t0 = time.perf_counter()
    info = build_office(seed=0, n_lamps=2, texture_size=args.texture_size, variant="small")
    scene = bpy.context.scene
    powers0 = dict(info.lamp_powers)
    bakes = bake_lighting(powers0, samples=args.bake_samples, seed=0,
                          texture_size=args.texture_size)
    truth_mats = make_photographed(bpy, info, bakes)
    times["build + bake (cached after the first run)"] = time.perf_counter() - t0

    # 2. Precompute through the operator.
    register_repo_addon()
    t0 = time.perf_counter()
    result = bpy.ops.relight.precompute(preset=args.preset)
    times[f"precompute operator ({args.preset})"] = time.perf_counter() - t0
    if "FINISHED" not in result:
        raise SystemExit(f"relight.precompute returned {result}")
    relit = {o: bpy.data.objects[o].material_slots[0].material for o in info.objects}
    n_relit = sum(1 for m in relit.values() if m is not None and m.name.endswith(".relight"))
    n_maps = sum(1 for im in bpy.data.images if im.get("relight_generated"))
    print(f"precompute: {n_relit}/{len(info.objects)} objects relit, {n_maps} images (T_final and maps)")

    # 3. Keyframes and EEVEE frames.
    sched = lamp_schedule(powers0)
    for f in FRAMES:
        for name, p in sched[f].items():
            light = bpy.data.objects[name].data
            light.energy = p
            light.keyframe_insert("energy", frame=f)
    for name in sched[1]:
        ad = bpy.data.objects[name].data.animation_data
        try:
            for fc in ad.action.fcurves:
                for kp in fc.keyframe_points:
                    kp.interpolation = "CONSTANT"
        except AttributeError:      # layered actions (5.x): the default BEZIER is exact at keys
            pass
    eevee = _eevee_engine(scene)
    if eevee is None:
        raise SystemExit("no EEVEE render engine in this bpy build")
    _setup_render(scene, res, args.eevee_samples, args.cycles_samples, args.denoise)
    scene.render.engine = eevee
    scene.render.filepath = os.path.join(out, "frame_")
    t0 = time.perf_counter()
    bpy.ops.render.render(animation=True)
    times["EEVEE, 3 frames"] = time.perf_counter() - t0
    frames = {f: os.path.join(out, f"frame_{f:04d}.png") for f in FRAMES}
    for f, p in frames.items():
        if not os.path.exists(p):
            raise SystemExit(f"EEVEE wrote no {p}")

    # 4. Cycles truth (true albedo, Principled) for frames 1 and 3.
    truth = {}
    scene.render.engine = "CYCLES"
    t0 = time.perf_counter()
    try:
        for o, m in truth_mats.items():
            bpy.data.objects[o].material_slots[0].material = m
        for f in (1, 3):
            scene.frame_set(f)
            _set_energies(bpy, sched[f])       # keyframes already give these; explicit anyway
            truth[f] = os.path.join(out, f"truth_{f:04d}.png")
            scene.render.filepath = truth[f]
            bpy.ops.render.render(write_still=True)
    finally:
        for o, m in relit.items():
            bpy.data.objects[o].material_slots[0].material = m
    times["Cycles truth, 2 frames"] = time.perf_counter() - t0

    # 5. A virtual lamp and a virtual box, through Update (no new solve).
    from scenes.materials import grey_diffuse
    scene.frame_set(3)
    light = bpy.data.lights.new("Virtual lamp", "POINT")
    light.energy = VIRTUAL_W
    light.shadow_soft_size = 0.1
    lamp = bpy.data.objects.new("Virtual lamp", light)
    lamp.location = VIRTUAL_AT
    scene.collection.objects.link(lamp)
    bpy.ops.mesh.primitive_cube_add(size=BOX_SIZE, location=BOX_AT)
    box = bpy.context.active_object
    box.name = "Virtual box"
    box.data.materials.append(grey_diffuse(bpy))
    box.relight_role = "virtual"
    bpy.context.view_layer.update()
    t0 = time.perf_counter()
    result = bpy.ops.relight.update()
    times["update: virtual lamp and box"] = time.perf_counter() - t0
    if "FINISHED" not in result:
        raise SystemExit(f"relight.update returned {result}")
    # Update wrote new relit materials (the former ones are removed): the slots hold them now
    relit = {o: bpy.data.objects[o].material_slots[0].material for o in info.objects}
    for f, p in ((1, 0.0), (3, 0.0), (4, VIRTUAL_W)):     # on at frame 4 only
        light.energy = p
        light.keyframe_insert("energy", frame=f)
    frame4 = {"Lamp A": 0.0, "Lamp B": powers0["Lamp B"]}
    for name, p in frame4.items():
        bpy.data.objects[name].data.energy = p
        bpy.data.objects[name].data.keyframe_insert("energy", frame=4)
    scene.frame_set(4)
    scene.render.engine = eevee
    frames[4] = os.path.join(out, "frame_0004.png")
    scene.render.filepath = frames[4]
    bpy.ops.render.render(write_still=True)
    scene.render.engine = "CYCLES"
    try:
        for o, m in truth_mats.items():
            bpy.data.objects[o].material_slots[0].material = m
        truth[4] = os.path.join(out, "truth_0004.png")
        scene.render.filepath = truth[4]
        bpy.ops.render.render(write_still=True)
    finally:
        for o, m in relit.items():
            bpy.data.objects[o].material_slots[0].material = m
    times["frame 4: EEVEE and Cycles truth"] = time.perf_counter() - t0

    # 6. Pictures and numbers.
    img = {f"relit{f}": _read_png(bpy, p) for f, p in frames.items()}
    img.update({f"truth{f}": _read_png(bpy, p) for f, p in truth.items()})
    diffs = {}
    for f in (1, 3, 4):
        a, b = img[f"relit{f}"], img[f"truth{f}"]
        la, lb = srgb_to_linear(a), srgb_to_linear(b)
        diffs[f] = dict(srgb255=float(np.abs(a - b).mean() * 255),
                        linear_rel=float(np.abs(la - lb).mean() / max(lb.mean(), 1e-12)))
    note = ("Relit = T_final x sum_k I_k M_k: T_final is the photo with the real lamps' shadows "
            "removed per texel, M_k lamp k's share of the light.")
    side = os.path.join(out, "demo_side_by_side.png")
    pa, pb = powers0["Lamp A"], powers0["Lamp B"]
    side_by_side([img["relit1"], img["relit3"], img["relit4"], img["truth4"]],
                 [f"original photo (A {pa:g} W, B {pb:g} W)",
                  f"relit, EEVEE (A off, B {2 * pb:g} W)",
                  f"relit, EEVEE: A off, a virtual lamp ({VIRTUAL_W:g} W) and box",
                  "Cycles truth of the virtual lamp and box"], note, side)
    diff_png = os.path.join(out, "demo_diff.png")
    side_by_side([np.clip(4 * np.abs(img["relit1"] - img["truth1"]), 0, 1),
                  np.clip(4 * np.abs(img["relit3"] - img["truth3"]), 0, 1),
                  np.clip(4 * np.abs(img["relit4"] - img["truth4"]), 0, 1)],
                 ["|relit - truth| x 4, frame 1 (original lighting)",
                  "|relit - truth| x 4, frame 3 (A off, B doubled)",
                  "|relit - truth| x 4, frame 4 (virtual lamp and box)"],
                 f"sRGB-encoded difference; frame 1 = floor ({args.texture_size}^2-texel photo vs per-pixel "
                 "render, noise).", diff_png)
    if args.results:
        import shutil
        os.makedirs(os.path.dirname(os.path.abspath(args.results)), exist_ok=True)
        shutil.copyfile(side, args.results)

    scene.frame_set(1)
    scene.render.engine = eevee
    scene.render.filepath = os.path.join("//", "frame_")
    bpy.ops.file.pack_all()
    blend = os.path.join(out, "demo.blend")
    bpy.context.preferences.filepaths.save_version = 0      # no demo.blend1 backup
    bpy.ops.wm.save_as_mainfile(filepath=blend, compress=True)
    times["total"] = time.perf_counter() - t_all

    print(f"\nRelight office demo ({len(info.objects)} objects, {args.texture_size}^2 texels, "
          f"2 lamps of {pa:g} W; {res[0]}x{res[1]}, EEVEE {args.eevee_samples} samples, Cycles "
          f"{args.cycles_samples} samples, denoise {'on' if args.denoise else 'off'})")
    for k, v in times.items():
        print(f"  {k:45s} {v:7.1f} s")
    print("  keyframes (energy): frame 1 A=P B=P | frame 2 A=0 B=P | frame 3 A=0 B=2P")
    print("  frame 4: A=0 B=P, a virtual lamp and a virtual box (Update, no new solve)")
    for f in (1, 3, 4):
        print(f"  frame {f}: relit (EEVEE) vs Cycles truth: mean |diff| {diffs[f]['srgb255']:.1f}"
              f"/255 (sRGB), {100 * diffs[f]['linear_rel']:.1f} % of the mean (linear)")
    print(f"  Frame 1 is the floor: the photo is a {args.texture_size}^2-texel Cycles bake (Closest filtering, texel "
          "blocks and\n  edges) against a per-pixel Cycles render.  Frame 3 adds the error of the "
          "shadow removal\n  (benchmarks/results/shadowfree.md measures it on the textures).")
    print(f"  -> {side}, {blend}, {', '.join(os.path.basename(p) for p in frames.values())}")
    summary = dict(times=times, diffs=diffs, side=side, blend=blend)
    if args.json:
        import json
        with open(args.json, "w") as f:
            json.dump(summary, f, indent=1)
    return summary


if __name__ == "__main__":
    main()
