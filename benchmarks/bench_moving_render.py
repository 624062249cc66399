"""What a moving object's sphere shadows cost a render (issue 42 item 7, issue 44 item 10).

Scene: the demo office (scenes.office, seed 0, 2 lamps of 40 W, 48 texels per surface), its
photo a Cycles bake (bench_moving_objects' settings, cached), precomputed at ``medium`` through
``bpy.ops.relight.precompute``; Suzanne (size 0.5) on the desk under lamp A as in
bench_moving_objects, a moving virtual object ("Moving" shadows, settling off: the spheres'
shadow everywhere) inserted by ``bpy.ops.relight.update`` at each sphere count.  The baseline is
the same frame with Suzanne there, Relight Role "ignored" (no sphere shadow: the relit materials
as the precompute wrote them): the object's own shading is in both.

Each configuration is saved to a .blend and rendered in a fresh process without the extension
(its drivers are simple expressions), the render call alone timed:

* Cycles, CPU, the office camera at 640x360, few samples (--samples), no denoising, no adaptive
  sampling; the configurations are rendered in turn, --runs rounds, so that the machine's drift
  spreads over all of them; median seconds and the median of the per-round ratios to the
  baseline of the same round;
* culled (the wiring Update makes: each lamp term branches on the objects' reach, lamps without
  a direct part get no spheres) and unculled (``sphere_nodes.sync(cull=False)``: every lamp
  evaluates every sphere at every shading point, what the materials did before);
* EEVEE (``BLENDER_EEVEE``, headless through EGL), 640x360 at 1 sample, two frames in one
  process: the first holds the shader compilation; compile = first frame - the baseline's first
  frame of the same round (the second frames show the per-frame shading cost).

The load average of the machine is read before and after every render (other agents share its
two cores).  Writes benchmarks/results/moving_render.md and moving_render.png.

    python benchmarks/bench_moving_render.py [--counts 8,32,128] [--unculled 8,32]
        [--eevee 32,64] [--samples 4] [--runs 3] [--eevee-runs 2]
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, ROOT)
sys.path.insert(0, HERE)

RES = (640, 360)
TIMEOUT = 1800.0           # one render process at most (an unculled 128-sphere frame is slow)
OUT = os.path.join(HERE, "results", "moving_render.md")

CHILD = r"""
import json, os, sys, time
import bpy
path, engine, samples, frames = sys.argv[-4], sys.argv[-3], int(sys.argv[-2]), int(sys.argv[-1])
bpy.ops.wm.open_mainfile(filepath=path, load_ui=False)
scene = bpy.context.scene
scene.render.engine = engine
scene.cycles.samples = samples
scene.eevee.taa_render_samples = samples
out = []
for i in range(frames):
    load = os.getloadavg()[0]
    t0 = time.perf_counter()
    bpy.ops.render.render()
    out.append([time.perf_counter() - t0, load, os.getloadavg()[0]])
px = bpy.data.images["Render Result"]
px.save_render(path.replace(".blend", f"_{engine}.png"))
print("RENDER_TIMES " + json.dumps(out))
"""


def build(args, tmp):
    """Save one .blend per configuration: {tag: path}."""
    import bpy
    from bench_moving_objects import PKG, add_objects, set_mode, setup_render
    from demo.office import make_photographed
    from scenes.addon import register_repo_addon
    from scenes.bake import bake_lighting
    from scenes.office import build_office
    register_repo_addon()
    import importlib
    sn = importlib.import_module(PKG + ".relight_addon.blender.sphere_nodes")
    bpy.ops.wm.read_factory_settings(use_empty=True)
    info = build_office(seed=0, n_lamps=2, texture_size=48)
    photo = bake_lighting(dict(info.lamp_powers), samples=512, seed=0, texture_size=48)
    box, monkey = add_objects(bpy)
    bpy.data.objects.remove(box)
    make_photographed(bpy, info, photo)
    set_mode(bpy, [monkey], "ignored")
    scene = bpy.context.scene
    scene.relight.preset = "medium"
    assert bpy.ops.relight.precompute(preset="medium") == {"FINISHED"}
    scene.relight.settle = False
    setup_render(bpy)
    scene.render.resolution_x, scene.render.resolution_y = RES
    paths, info_out = {}, {}

    def save(tag):
        paths[tag] = os.path.join(tmp, f"{tag}.blend")
        bpy.ops.wm.save_as_mainfile(filepath=paths[tag], copy=True)

    save("none")
    counts = sorted(set(args.counts) | set(args.unculled) | set(args.eevee))
    for n in counts:
        set_mode(bpy, [monkey], "virtual", "SPHERES", n)
        t0 = time.perf_counter()
        assert bpy.ops.relight.update() == {"FINISHED"}
        info_out[n] = dict(update=time.perf_counter() - t0)
        mats = [m for m in bpy.data.materials if m.name.endswith(".relight")]
        lamps = sn.lamp_groups(sn.scene_key(scene))
        info_out[n]["terms"] = sum(len(sn.shadowed_terms(m, lamps)) for m in mats)
        info_out[n]["terms_all"] = sum(len(sn.shadowed_terms(m, lamps, cull=False)) for m in mats)
        info_out[n]["materials"] = len(mats)
        save(f"cull{n}")
        if n in args.unculled:
            sn.sync(scene, settle_shadows=False, cull=False)
            save(f"nocull{n}")
            sn.sync(scene, settle_shadows=False)
    return paths, info_out


def render(path, engine, samples, frames):
    """[[seconds, load before, load after] per frame] of a fresh process, or None (why)."""
    try:
        proc = subprocess.run([sys.executable, "-c", CHILD, path, engine, str(samples),
                               str(frames)], capture_output=True, text=True, timeout=TIMEOUT)
    except subprocess.TimeoutExpired:
        return None, f"> {TIMEOUT:.0f} s"
    line = [ln for ln in proc.stdout.splitlines() if ln.startswith("RENDER_TIMES ")]
    if not line:
        return None, (proc.stdout[-300:] + proc.stderr[-300:]).replace("\n", " ")
    return json.loads(line[0].split(" ", 1)[1]), ""


def measure(args, paths):
    cycles_tags = ["none"] + [f"cull{n}" for n in args.counts] + [f"nocull{n}"
                                                                 for n in args.unculled]
    eevee_tags = ["none"] + [f"cull{n}" for n in args.eevee]
    cyc = {t: [] for t in cycles_tags}
    eev = {t: [] for t in eevee_tags}
    for r in range(args.runs):
        for t in cycles_tags:
            times, why = render(paths[t], "CYCLES", args.samples, 1)
            cyc[t].append(times[0] if times else None)
            print(f"cycles round {r} {t}: {times or why}", flush=True)
    for r in range(args.eevee_runs):
        for t in eevee_tags:
            times, why = render(paths[t], "BLENDER_EEVEE", 1, 2)
            eev[t].append(times)
            print(f"eevee round {r} {t}: {times or why}", flush=True)
    return cyc, eev


def _med(xs):
    xs = [x for x in xs if x is not None]
    return statistics.median(xs) if xs else float("nan")


def write(args, info, cyc, eev, meta):
    rows = []
    base = cyc["none"]
    loads = [x for v in cyc.values() for t in v if t for x in t[1:]]
    lines = [
        "# Moving-object sphere shadows: render cost (culled and unculled)",
        "",
        f"Generated by `benchmarks/bench_moving_render.py` ({meta['when']}, HEAD {meta['head']}, "
        f"{meta['machine']}).  Scene: the demo office at `medium`, Suzanne (size 0.5) on the "
        "desk under lamp A as a moving virtual object (settling off), inserted by Update at each "
        "sphere count; baseline = the same frame with Suzanne 'ignored' (no sphere shadow).  "
        f"Each configuration saved to a .blend and rendered in a fresh process (no extension), "
        f"the render call alone timed.  Cycles: CPU, {RES[0]}x{RES[1]}, {args.samples} samples, "
        f"no denoising; {args.runs} rounds, configurations in turn; median seconds and the median "
        "of each round's ratio to the same round's baseline.  Culled = the wiring Update makes "
        "(each lamp term a Mix Shader on the objects' reach, Cycles' SVM jumps over the spheres "
        "out of reach; lamps whose map has no direct part get no spheres); unculled = "
        "`sphere_nodes.sync(cull=False)` (every lamp, every sphere, every shading point).",
        "",
        f"Machine load (1-minute load average, 2 cores shared with other agents) read before and "
        f"after each Cycles render: median {_med(loads):.1f}, range {min(loads):.1f}-"
        f"{max(loads):.1f}.",
        "",
        "| configuration | spheres | lamp terms with spheres (of all) | Update (s) | Cycles "
        "render (s), median | min-max | ratio to baseline (median) |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for tag, v in cyc.items():
        secs = [t[0] for t in v if t]
        if not secs:
            lines.append(f"| {tag} | | | | failed | | |")
            continue
        ratios = [a[0] / b[0] for a, b in zip(v, base) if a and b]
        n = int(tag.replace("nocull", "").replace("cull", "")) if tag != "none" else 0
        name = {"none": "baseline (no sphere shadow)"}.get(
            tag, ("culled" if tag.startswith("cull") else "unculled"))
        i = info.get(n, {})
        terms = "" if not n else (f"{i['terms']} of {i['terms_all']}" if tag.startswith("cull")
                                  else f"{i['terms_all']} of {i['terms_all']}")
        upd = f"{i['update']:.2f}" if n and tag.startswith("cull") else ""
        lines.append(f"| {name} | {n or '-'} | {terms} | {upd} | {_med(secs):.2f} | "
                     f"{min(secs):.2f}-{max(secs):.2f} | {_med(ratios):.2f} |")
        rows.append((name, n, _med(secs), _med(ratios)))
    lines += ["", f"EEVEE (`BLENDER_EEVEE`, headless EGL), {RES[0]}x{RES[1]}, 1 sample, two frames "
              f"per process, {args.eevee_runs} rounds.  Compile = first frame - the same round's "
              "baseline first frame.", "",
              "| configuration | spheres | 1st frame (s), median | 2nd frame (s), median | "
              "compile (s), median | min-max |", "|---|---:|---:|---:|---:|---:|"]
    eb = eev["none"]
    for tag, v in eev.items():
        ok = [t for t in v if t]
        if not ok:
            lines.append(f"| {tag} | | failed | | | |")
            continue
        n = 0 if tag == "none" else int(tag[4:])
        comp = [a[0][0] - b[0][0] for a, b in zip(v, eb) if a and b]
        lines.append(f"| {'baseline' if not n else 'culled'} | {n or '-'} | "
                     f"{_med([t[0][0] for t in ok]):.1f} | {_med([t[1][0] for t in ok]):.1f} | "
                     + ("" if not n else f"{_med(comp):.1f} | {min(comp):.1f}-{max(comp):.1f}")
                     + (" | |" if not n else " |"))
    lines += ["", "Raw (seconds, load before, load after per render):", "", "```",
              json.dumps({"cycles": cyc, "eevee": eev, "info": {str(k): v for k, v in
                                                               info.items()}}), "```", ""]
    if meta.get("note"):
        lines += [meta["note"], ""]
    lines += ["![render cost](moving_render.png)", "",
              "moving_render.png: Cycles render seconds (median, log scale) against the sphere "
              "count, culled and unculled, the baseline as a line.", ""]
    with open(args.out, "w") as f:
        f.write("\n".join(lines))
    write_figure(args, cyc)


def write_figure(args, cyc):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6, 4), dpi=100)
    for prefix, label, style in (("cull", "culled (Update's wiring)", "o-"),
                                 ("nocull", "unculled (cull=False)", "s--")):
        pts = sorted((int(t[len(prefix):]), _med([x[0] for x in v if x]))
                     for t, v in cyc.items() if t.startswith(prefix)
                     and t[len(prefix):].isdigit())
        if pts:
            ax.plot(*zip(*pts), style, label=label)
    base = _med([x[0] for x in cyc["none"] if x])
    ax.axhline(base, color="k", lw=1, label="no sphere shadow")
    ax.axhline(2 * base, color="k", lw=1, ls=":", label="2x no sphere shadow (target)")
    ax.set_xscale("log", base=2)
    ax.set_yscale("log")
    ax.set_xlabel("spheres (Suzanne)")
    ax.set_ylabel("Cycles render seconds (median)")
    ax.set_title(f"Office, {RES[0]}x{RES[1]}, {args.samples} samples, CPU")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.splitext(args.out)[0] + ".png")


def main(argv=None):
    ap = argparse.ArgumentParser()
    ints = lambda s: [int(x) for x in s.split(",") if x]            # noqa: E731
    ap.add_argument("--counts", type=ints, default=[8, 32, 128])
    ap.add_argument("--unculled", type=ints, default=[8, 32])
    ap.add_argument("--eevee", type=ints, default=[32, 64])
    ap.add_argument("--samples", type=int, default=4)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--eevee-runs", type=int, default=2)
    ap.add_argument("--out", default=OUT)
    ap.add_argument("--note", default="")
    args = ap.parse_args(argv)
    head = subprocess.run(["git", "-C", ROOT, "rev-parse", "--short", "HEAD"],
                          capture_output=True, text=True).stdout.strip()
    meta = dict(when=time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), head=head,
                machine=f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores",
                note=args.note)
    tmp = tempfile.mkdtemp(prefix="relight_bench_moving_render_")
    paths, info = build(args, tmp)
    print("built", paths, info, flush=True)
    cyc, eev = measure(args, paths)
    write(args, info, cyc, eev, meta)
    print("wrote", args.out)


if __name__ == "__main__":
    main()
