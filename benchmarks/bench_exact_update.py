"""How long Update takes to insert and move Exact virtual objects in one session (issue 42 item 6:
"about as fast as today", benchmarks/results/moving_objects.md: 0.86 s to insert the box and
Suzanne on the demo office).

The scene of bench_moving_objects.py: the demo office (scenes.office, seed 0, 2 lamps, 48 texels
per surface) photographed (its 512-sample Cycles bake as the textures, cached), precomputed at
medium through the operator; then the grey 0.6 m box on the open floor and Suzanne on the desk
(bench_moving_objects.add_objects) are made virtual (shadows Exact) and Update inserts them,
the box is moved 10 cm and Update runs again; both objects are set back to 'ignored' and Update
gives the room back.  REPEATS times; wall (perf_counter) and CPU (process_time) seconds of each
Update.  Prints one JSON line ``RELIGHT_EXACT_UPDATE {...}``; with --out, appends a row to a
markdown table (run it once per code version to compare: --label names the row).

    python benchmarks/bench_exact_update.py --label "this branch" --out results/exact_update.md
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path[:0] = [ROOT, HERE]

REPEATS = 5
SIZE = 48
SAMPLES = 512


def _timed(bpy):
    t0, c0 = time.perf_counter(), time.process_time()
    res = bpy.ops.relight.update()
    assert res == {"FINISHED"}, res
    return time.perf_counter() - t0, time.process_time() - c0


def run(preset="medium", repeats=REPEATS):
    import bpy

    from bench_moving_objects import add_objects, set_mode
    from demo.office import make_photographed
    from scenes.addon import register_repo_addon
    from scenes.bake import bake_lighting
    from scenes.office import build_office
    register_repo_addon()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    info = build_office(seed=0, n_lamps=2, texture_size=SIZE)
    photo = bake_lighting(dict(info.lamp_powers), samples=SAMPLES, seed=0, texture_size=SIZE)
    objs = add_objects(bpy)
    make_photographed(bpy, info, photo)
    set_mode(bpy, objs, "ignored")
    bpy.context.scene.relight.preset = preset
    t0 = time.perf_counter()
    assert bpy.ops.relight.precompute(preset=preset) == {"FINISHED"}
    t_pre = time.perf_counter() - t0
    box = objs[0]
    out = {"insert": [], "move": [], "restore": []}
    for _ in range(repeats):
        set_mode(bpy, objs, "virtual", "EXACT")
        out["insert"].append(_timed(bpy))
        box.location.x -= 0.1
        bpy.context.view_layer.update()
        out["move"].append(_timed(bpy))
        box.location.x += 0.1
        set_mode(bpy, objs, "ignored")
        out["restore"].append(_timed(bpy))
    med = {k: {"wall": statistics.median(w for w, _ in v), "cpu": statistics.median(c for _, c in v),
               "wall_all": [round(w, 3) for w, _ in v]} for k, v in out.items()}
    return {"precompute": t_pre, "updates": med, "load": os.getloadavg()[0]}


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--preset", default="medium")
    ap.add_argument("--repeats", type=int, default=REPEATS)
    ap.add_argument("--label", default="")
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    r = run(args.preset, args.repeats)
    print("RELIGHT_EXACT_UPDATE " + json.dumps(r), flush=True)
    if args.out:
        new = not os.path.exists(args.out)
        with open(args.out, "a") as f:
            if new:
                f.write("| code | preset | insert (wall / CPU) | move 10 cm | restore | "
                        "precompute | load |\n|---|---|---:|---:|---:|---:|---:|\n")
            u = r["updates"]
            f.write(f"| {args.label} | {args.preset} | {u['insert']['wall']:.2f} / "
                    f"{u['insert']['cpu']:.2f} s | {u['move']['wall']:.2f} / "
                    f"{u['move']['cpu']:.2f} s | {u['restore']['wall']:.2f} s | "
                    f"{r['precompute']:.1f} s | {r['load']:.1f} |\n")


if __name__ == "__main__":
    main()
