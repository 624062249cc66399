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

* Cycles at 16x16, 1 sample: the frame's fixed cost (scene sync and shader compilation), which
  few-sample frames are dominated by;
* the share of the 320x180 frame in each lamp's reach (the Mix Shaders' factors rendered as an
  emission): the pixels that evaluate the spheres.

The load average of the machine is read before and after every render (other agents share its
two cores).  Writes benchmarks/results/moving_render.md and moving_render.png.

    python benchmarks/bench_moving_render.py [--counts 8,32,128] [--unculled 8,32]
        [--eevee 32,64] [--samples 4] [--runs 3] [--eevee-runs 2]
    python benchmarks/bench_moving_render.py --reuse DIR --phases tiny,reach
        # DIR: the .blend files a run left (printed); the other phases' figures are read back
        # from the raw block of the markdown at --out
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
# Mesa (llvmpipe) keeps compiled shaders on disk: a second process compiling the same EEVEE
# material found them there (measured: 32 spheres 147 s, then 30 s), so every run compiles afresh
NO_SHADER_CACHE = dict(os.environ, MESA_SHADER_CACHE_DISABLE="true",
                       MESA_GLSL_CACHE_DISABLE="true")

CHILD = r"""
import json, os, sys, time
import bpy
path, engine, samples, frames = sys.argv[-4], sys.argv[-3], int(sys.argv[-2]), int(sys.argv[-1])
bpy.ops.wm.open_mainfile(filepath=path, load_ui=False)
scene = bpy.context.scene
scene.render.engine = engine
scene.cycles.samples = samples
scene.eevee.taa_render_samples = samples
if os.environ.get("BENCH_OUT_OF_REACH"):   # every point out of reach: Fac = (Reach > 2) = 0
    for m in bpy.data.materials:
        nt = m.node_tree
        for n in list(nt.nodes) if nt else ():
            if n.name.startswith("Relight Shadow Branch") and n.inputs["Fac"].is_linked:
                g = nt.nodes.new("ShaderNodeMath")
                g.operation = "GREATER_THAN"
                g.inputs[1].default_value = 2.0
                nt.links.new(n.inputs["Fac"].links[0].from_socket, g.inputs[0])
                nt.links.new(g.outputs[0], n.inputs["Fac"])
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

REACH_CHILD = r"""
import json, sys
import numpy as np
import bpy
bpy.ops.wm.open_mainfile(filepath=sys.argv[-2], load_ui=False)
scene = bpy.context.scene
scene.render.engine = "CYCLES"
scene.cycles.samples = 1
scene.render.resolution_x, scene.render.resolution_y = 320, 180
prefix = "Relight Shadow Branch "
lamps = sorted({n.name[len(prefix):].rsplit(" ", 1)[0] for m in bpy.data.materials
                if m.node_tree for n in m.node_tree.nodes if n.name.startswith(prefix)})
share = {}
for lamp in lamps + ["any lamp"]:
    for m in bpy.data.materials:
        nt = m.node_tree
        out = nt and next((n for n in nt.nodes if n.bl_idname == "ShaderNodeOutputMaterial"
                           and n.is_active_output), None)
        if out is None or not m.name.endswith(".relight"):
            continue
        facs = [n.inputs["Fac"].links[0].from_socket for n in nt.nodes
                if n.name.startswith(prefix) and n.inputs["Fac"].is_linked
                and (lamp == "any lamp" or n.name.startswith(prefix + lamp + " "))]
        e = nt.nodes.get("_reach") or nt.nodes.new("ShaderNodeEmission")
        e.name = "_reach"
        for link in list(e.inputs["Color"].links):
            nt.links.remove(link)
        e.inputs["Color"].default_value = (0, 0, 0, 1)
        acc = facs[0] if facs else None
        for f in facs[1:]:
            mx = nt.nodes.new("ShaderNodeMath")
            mx.operation = "MAXIMUM"
            nt.links.new(acc, mx.inputs[0])
            nt.links.new(f, mx.inputs[1])
            acc = mx.outputs[0]
        if acc is not None:
            nt.links.new(acc, e.inputs["Color"])
        nt.links.new(e.outputs[0], out.inputs["Surface"])
    bpy.ops.render.render()
    path = sys.argv[-1].replace(".exr", f"_{lamp}.exr")
    bpy.data.images["Render Result"].save_render(path)
    img = bpy.data.images.load(path)
    px = np.empty(len(img.pixels), np.float32)
    img.pixels.foreach_get(px)
    share[lamp] = float((px.reshape(-1, 4)[:, 0] > 0.5).mean())
print("REACH " + json.dumps(share))
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
    scene.relight.cycles_shadows = "SPHERES"     # Cycles as EEVEE (bench_ray_shadow: the rays)
    scene.relight.eevee_shadows = "SPHERES"      # (bench_eevee_shadow: EEVEE's shadow maps)
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
        # Cycles' rays (bench_ray_shadow), EEVEE's shadow maps (bench_eevee_shadow): the
        # setting switched for one Update and one file, then back to the spheres
        # defaults: both settings as a new scene has them (Cycles' rays, EEVEE's shadow maps)
        for tag, settings in (("rays", {"cycles_shadows": "RAYS"}),
                              ("maps", {"eevee_shadows": "MAPS"}),
                              ("defaults", {"cycles_shadows": "RAYS", "eevee_shadows": "MAPS"})):
            if n not in getattr(args, tag, ()):
                continue
            for setting, value in settings.items():
                setattr(scene.relight, setting, value)
            t0 = time.perf_counter()
            assert bpy.ops.relight.update() == {"FINISHED"}
            info_out.setdefault(tag, {})[n] = time.perf_counter() - t0
            save(f"{tag}{n}")
            for setting in settings:
                setattr(scene.relight, setting, "SPHERES")
            assert bpy.ops.relight.update() == {"FINISHED"}
    return paths, info_out


def render(path, engine, samples, frames, res=None, out_of_reach=False):
    """[[seconds, load before, load after] per frame] of a fresh process, or None (why).
    ``res``: (x, y) instead of the file's resolution."""
    child = CHILD if res is None else CHILD.replace(
        "out = []", f"scene.render.resolution_x, scene.render.resolution_y = {res}\nout = []")
    try:
        proc = subprocess.run([sys.executable, "-c", child, path, engine, str(samples),
                               str(frames)], capture_output=True, text=True, timeout=TIMEOUT,
                              env=dict(NO_SHADER_CACHE, BENCH_OUT_OF_REACH="1" if out_of_reach
                                       else ""))
    except subprocess.TimeoutExpired:
        return None, f"> {TIMEOUT:.0f} s"
    line = [ln for ln in proc.stdout.splitlines() if ln.startswith("RENDER_TIMES ")]
    if not line:
        return None, (proc.stdout[-300:] + proc.stderr[-300:]).replace("\n", " ")
    return json.loads(line[0].split(" ", 1)[1]), ""


def reach_share(path):
    """{lamp: share of the 320x180 frame in its reach, "any lamp": in some lamp's}."""
    proc = subprocess.run([sys.executable, "-c", REACH_CHILD, path,
                           path.replace(".blend", "_reach.exr")],
                          capture_output=True, text=True, timeout=TIMEOUT)
    line = [ln for ln in proc.stdout.splitlines() if ln.startswith("REACH ")]
    return json.loads(line[0].split(" ", 1)[1]) if line else None


def measure_fixed(args, paths):
    """16x16 1-sample Cycles frames (the fixed cost), --runs rounds; the culled files' reach."""
    tags = [t for t in paths if not t.startswith("nocull") or int(t[6:]) in args.unculled]
    tiny = {t: [] for t in tags}
    for r in range(args.runs):
        for t in tags:
            times, why = render(paths[t], "CYCLES", 1, 1, res=(16, 16))
            tiny[t].append(times[0] if times else None)
            print(f"tiny round {r} {t}: {times or why}", flush=True)
    reach = {t: reach_share(paths[t]) for t in tags if t.startswith("cull")}
    print("reach", reach, flush=True)
    return tiny, reach


def measure_out_of_reach(args, paths):
    """Cycles frames (as measure's) of the baseline, the culled files and the same with every
    point taken out of reach (the Mix factors forced to 0 after the reach is computed): what
    the points out of reach pay, --runs rounds in turn."""
    tags = [t for t in ("none", *(f"cull{n}" for n in args.counts)) if t in paths]
    out = {t: [] for t in tags}
    out.update({f"{t} out of reach": [] for t in tags if t != "none"})
    for r in range(args.runs):
        for t in tags:
            for oor in ((False,) if t == "none" else (False, True)):
                times, why = render(paths[t], "CYCLES", args.samples, 1, out_of_reach=oor)
                out[f"{t} out of reach" if oor else t].append(times[0] if times else None)
                print(f"out-of-reach round {r} {t} {oor}: {times or why}", flush=True)
    return out


def measure(args, paths, phases=("cycles", "eevee"), old=None):
    cycles_tags = ["none"] + [f"cull{n}" for n in args.counts] + [f"nocull{n}"
                                                                 for n in args.unculled]
    eevee_tags = ["none"] + [f"cull{n}" for n in args.eevee]
    cyc = {t: [] for t in cycles_tags}
    eev = {t: [] for t in eevee_tags}
    if "cycles" not in phases:
        cyc, cycles_tags = old["cycles"], []
    if "eevee" not in phases:
        eev, eevee_tags = old["eevee"], []
    for r in range(args.runs if cycles_tags else 0):
        for t in cycles_tags:
            times, why = render(paths[t], "CYCLES", args.samples, 1)
            cyc[t].append(times[0] if times else None)
            print(f"cycles round {r} {t}: {times or why}", flush=True)
    for r in range(args.eevee_runs if eevee_tags else 0):
        for t in eevee_tags:
            times, why = render(paths[t], "BLENDER_EEVEE", 1, 2)
            eev[t].append(times)
            print(f"eevee round {r} {t}: {times or why}", flush=True)
    return cyc, eev


def _med(xs):
    xs = [x for x in xs if x is not None]
    return statistics.median(xs) if xs else float("nan")


def write(args, info, cyc, eev, meta, tiny=None, reach=None, oor=None):
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
    el = [x for v in eev.values() for t in v if t for f in t for x in f[1:]]
    lines += ["", f"EEVEE (`BLENDER_EEVEE`, headless EGL, Mesa llvmpipe, its disk shader cache "
              f"off), {RES[0]}x{RES[1]}, 1 sample, two frames per process, "
              f"{len(eev.get('none', []))} rounds (load {min(el, default=0):.1f}-"
              f"{max(el, default=0):.1f}).  Compile = first frame - the same round's baseline "
              "first frame.", "",
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
    if tiny:
        tl = [x for v in tiny.values() for t in v if t for x in t[1:]]
        lines += ["", "Fixed cost of a frame (scene sync and shader compilation): Cycles at "
                  f"16x16, 1 sample, {args.runs} rounds (load {min(tl):.1f}-{max(tl):.1f}); the "
                  "share of the 320x180 frame in reach (culled wiring: the pixels that evaluate "
                  "the spheres of a lamp).", "",
                  "| configuration | 16x16 frame (s), median | excess over baseline (s) | "
                  "in reach of lamp A | of lamp B | of any lamp |",
                  "|---|---:|---:|---:|---:|---:|"]
        b0 = _med([t[0] for t in tiny.get("none", []) if t])
        def order(tag):
            return (tag.startswith("nocull"), int("".join(filter(str.isdigit, tag)) or 0))
        for tag, v in sorted(tiny.items(), key=lambda kv: order(kv[0])):
            m = _med([t[0] for t in v if t])
            sh = (reach or {}).get(tag) or {}
            cells = [f"{100 * sh[k]:.1f} %" if k in sh else "" for k in
                     ("Lamp A", "Lamp B", "any lamp")]
            lines.append(f"| {tag} | {m:.2f} | {m - b0:+.2f} | " + " | ".join(cells) + " |")
    if oor:
        ol = [x for v in oor.values() for t in v if t for x in t[1:]]
        lines += ["", f"What the points out of reach pay: Cycles {RES[0]}x{RES[1]}, "
                  f"{args.samples} samples, the culled files as rendered and with every point "
                  "taken out of reach (the Mix Shaders' factors forced to 0 after the reach is "
                  f"computed), {len(oor.get('none', []))} rounds in turn (load "
                  f"{min(ol, default=0):.1f}-{max(ol, default=0):.1f}).", "",
                  "| configuration | render (s), median | ratio to baseline (median) |",
                  "|---|---:|---:|"]
        for tag, v in oor.items():
            ratios = [a[0] / b[0] for a, b in zip(v, oor["none"]) if a and b]
            lines.append(f"| {tag} | {_med([t[0] for t in v if t]):.2f} | {_med(ratios):.2f} |")
    lines += ["", "Raw (seconds, load before, load after per render):", "", "```",
              json.dumps({"cycles": cyc, "eevee": eev, "tiny": tiny, "reach": reach,
                          "out_of_reach": oor,
                          "info": {str(k): v for k, v in info.items()}}), "```", ""]
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
    ap.add_argument("--reuse", default="", help="a previous run's directory of .blend files")
    ap.add_argument("--phases", default="cycles,eevee,tiny,reach,outofreach")
    args = ap.parse_args(argv)
    phases = set(args.phases.split(","))
    head = subprocess.run(["git", "-C", ROOT, "rev-parse", "--short", "HEAD"],
                          capture_output=True, text=True).stdout.strip()
    meta = dict(when=time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), head=head,
                machine=f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores",
                note=args.note)
    old = {}
    if args.reuse:                      # the files and the figures of a previous run
        paths = {os.path.splitext(f)[0]: os.path.join(args.reuse, f)
                 for f in os.listdir(args.reuse) if f.endswith(".blend")}
        with open(args.out) as f:
            text = f.read()
        old = json.loads(text.split("```\n", 1)[1].split("\n```", 1)[0])
        info = {int(k): v for k, v in old["info"].items()}
    else:
        tmp = tempfile.mkdtemp(prefix="relight_bench_moving_render_")
        paths, info = build(args, tmp)
    print("built", paths, info, flush=True)
    if phases & {"cycles", "eevee"}:
        cyc, eev = measure(args, paths, phases, old)
    else:
        cyc, eev = old.get("cycles", {"none": []}), old.get("eevee", {"none": []})
    tiny, reach = old.get("tiny"), old.get("reach")
    if phases & {"tiny", "reach"}:
        tiny, reach = measure_fixed(args, paths)
    oor = old.get("out_of_reach")
    if "outofreach" in phases:
        oor = measure_out_of_reach(args, paths)
    write(args, info, cyc, eev, meta, tiny, reach, oor)
    print("wrote", args.out)


if __name__ == "__main__":
    main()
