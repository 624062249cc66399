"""Scanned rooms: the precompute of dense, noisy triangle meshes (issue 10 "Scale").

Family rooms (scenes/family.py) re-meshed as scans (scenes/scan.py: ~N triangles, 2 mm of
normal noise, jittered vertices; the photo textures and the Cycles truth stay valid texel for
texel) are read through the add-on's reader and precomputed by ``shadow_free`` as the
Precompute button does: meshes of more than PROXY_FACTOR x the preset's proxy faces are solved
on a decimated proxy (core/radiosity/proxy.py).  Each case runs in its own process, so that
its peak RSS is its own.  Reported per case: wall time of the precompute, peak RSS and the RSS
after reading (Blender, the scene and its images), the memory estimate the operator checks
before it starts, and the lamp-off error against the Cycles truth (mean CIEDE2000 over the
lamp-off / only-one-lamp targets, overall and in the switched-off lamps' former shadows, as
benchmarks/bench_family.py), beside the same room read as its clean quads, and (medium) the
scans read as one group, as a real scan (one object, one material) is.

    python benchmarks/bench_scan.py                       # everything (~45 min)
    python benchmarks/bench_scan.py --quick               # the memory / time scaling only
    python benchmarks/bench_scan.py --one-group-only      # the one-group scans (~3 min)
    python benchmarks/bench_scan.py --photos-only         # photo-resolution textures (~13 min)
    python benchmarks/bench_scan.py --seeds 0-4 [--rooms 0 16] [--seeds-raw results/scan_seeds_raw_a.json]

``--seeds`` precomputes the 100k-face scans at every preset with the solver's, the
orientation's and the texel rays' seed set to each (the scan's mesh stays the same); the
records go to results/scan_seeds_raw*.json (one file per process, so that two can run side by
side) and scan.md reports their spread.

Writes benchmarks/results/scan.md, scan_raw.json and scan.png.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
NOISE = 0.002
ROOMS = (0, 16, 5, 3)
PRESETS = ("draft", "medium", "high")
SIZES = (25_000, 50_000, 100_000, 200_000)
PROXY_CURVE = (500, 1000, 1500, 3000, 6000)
PHOTO_UPSCALES = (4, 8, 12)     # room 0's photos x 4, 8, 12 a side: 1.7 M, 6.8 M, 15.3 M texels


def child(room, faces, preset, proxy_faces, one_group=False, photo_up=1, seed=0):
    import resource

    import numpy as np
    sys.path.insert(0, str(ROOT))
    from relight_addon.core.radiosity import presets as P
    from relight_addon.core.radiosity.memory import estimate_precompute_memory
    from relight_addon.core.relight.shadowfree import ShadowFreeOptions, shadow_free
    from scenes import family_eval as fe
    if proxy_faces:
        P.PRESETS[preset] = P.PRESETS[preset].with_(proxy_faces=proxy_faces)
    t0 = time.perf_counter()
    r = fe.photographed_room(room, "exact",
                             scan=dict(triangles=faces, noise=NOISE) if faces else None)
    read_s = time.perf_counter() - t0
    if one_group:
        # a real scan is one object with one material: every surface face in one group
        surface = r.data.lamp < 0
        group = r.data.group.copy()
        group[surface] = group[surface].min()
        r.data.group = group
    if photo_up > 1:
        # photo-resolution textures: every photo upscaled (its texels repeated); the Cycles
        # truth no longer matches texel for texel, so only memory and time are measured
        from relight_addon.core.relight.maps import texels_of
        r.data.images = [np.ascontiguousarray(np.kron(texels_of(im), np.ones(
            (photo_up, photo_up, 1), np.float32))) for im in r.data.images]
    rss_read = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    estimate = estimate_precompute_memory(r.data, preset) / 2**20
    without_proxy = estimate_precompute_memory(r.data, preset, proxy=False) / 2**20
    t0 = time.perf_counter()
    res = shadow_free(r.data, ShadowFreeOptions(preset=preset, seed=seed))
    seconds = time.perf_counter() - t0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    if photo_up > 1:
        print(json.dumps({"room": room, "faces": int(r.data.n_patches), "preset": preset,
                          "photo_up": photo_up, "texels": int(res.texel_map.n_texels),
                          "seconds": seconds, "rss_read_mb": rss_read, "peak_mb": peak,
                          "estimate_mb": estimate}))
        return
    sc = fe.score(r, res)
    off = {k: v for k, v in sc["targets"].items() if k.endswith(" off") or k.startswith("only")}
    if not off:                                   # one lamp: its doubling
        off = {k: v for k, v in sc["targets"].items() if k.endswith("x2")}

    def mean(key, part):
        vals = [v[key][part][0] for v in off.values()
                if part == "all" or v[key]["shadow_texels"] >= 20]
        return float(np.nanmean(vals)) if vals else float("nan")
    st = res.stats
    proxy = res.solution.context.get("proxy")
    print(json.dumps({
        "room": room, "faces": int(r.data.n_patches), "preset": preset, "seed": seed,
        "proxy_setting": proxy_faces, "one_group": bool(one_group), "read_s": read_s,
        "seconds": seconds,
        "rss_read_mb": rss_read, "peak_mb": peak, "estimate_mb": estimate,
        "estimate_without_proxy_mb": without_proxy,
        "proxy_faces": int(st.get("proxy_faces", 0)), "leaves": int(st["leaves"]),
        "links": int(st["links"]), "deviation_mm": 1000 * float(st.get("proxy_deviation", 0)),
        "roughness_mm": 1000 * float(proxy.roughness) if proxy is not None else 0.0,
        "timings": {k: float(v) for k, v in res.timings.items()},
        "floor": float(sc["floor"][0]), "ratio_error": float(sc["ratio_error"]),
        "relit_all": mean("relit", "all"), "relit_shadow": mean("relit", "shadow"),
        "scale_all": mean("scale", "all"), "scale_shadow": mean("scale", "shadow"),
        "applied": [bool(x) for x in res.lamps.applied]}))


def run(room, faces, preset, proxy_faces=0, one_group=False, photo_up=1, timeout=1800, seed=0):
    cmd = [sys.executable, __file__, "--child", str(room), str(faces), preset, str(proxy_faces),
           str(int(one_group)), str(photo_up), str(seed)]
    t0 = time.perf_counter()
    try:
        out = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"room": room, "faces": faces, "preset": preset, "status": "timeout"}
    lines = [ln for ln in out.stdout.splitlines() if ln.startswith("{")]
    if not lines:
        return {"room": room, "faces": faces, "preset": preset, "status": "failed",
                "stderr": out.stderr[-2000:], "seconds": time.perf_counter() - t0}
    rec = json.loads(lines[-1])
    rec["status"] = "ok"
    print(f"{time.strftime('%H:%M:%S')} room {room} {faces} faces {preset} seed {seed} "
          f"(proxy {proxy_faces or 'preset'}): {rec['seconds']:.1f} s, peak {rec['peak_mb']:.0f} "
          f"MB, lamp off {rec.get('relit_all', float('nan')):.2f} / "
          f"{rec.get('relit_shadow', float('nan')):.2f}", flush=True)
    return rec


def _f(x, nd=2):
    return "-" if x is None or x != x else f"{x:.{nd}f}"


def write(records, path_md, path_png):
    import numpy as np
    sys.path.insert(0, str(ROOT))
    from relight_addon.core.radiosity.memory import BASE_BYTES
    base = BASE_BYTES / 2**20                     # what the estimate counts over the read
    photos = [r for r in records if r.get("status") == "ok" and r.get("photo_up", 1) > 1]
    ok = [r for r in records if r.get("status") == "ok" and r.get("photo_up", 1) == 1]
    lines = ["# Scanned rooms: dense noisy meshes solved on a proxy", "",
             "Generated by `benchmarks/bench_scan.py` (see its docstring).  Family rooms "
             f"re-meshed as scans (`scenes/scan.py`: {NOISE * 1000:.0f} mm of normal noise, "
             "jittered vertices), read by the add-on's reader and precomputed as the Precompute "
             "button does; the clean room (its quads) beside each.  Lamp off: mean CIEDE2000 "
             "against the Cycles truth over the lamp-off and only-one-lamp targets (a one-lamp "
             "room: its doubling), overall / in the switched-off lamps' former shadows; "
             "\"global scale\" is the photo scaled by the best single factor.  Peak RSS "
             "includes Blender (bpy), the scene and its images: \"after read\" is that part.",
             ""]
    main = [r for r in ok if r.get("proxy_setting", 0) == 0 and r["faces"] <= 120_000
            and not r.get("one_group")]
    if main:
        lines += ["## Rooms x presets (scan of ~100k triangles vs the clean room)", "",
                  "| room | preset | mesh | faces | proxy faces | leaves | links | time s | "
                  "peak RSS MB (after read) | lamp off: all / shadow | global scale | noise "
                  "floor | ratio error |",
                  "|---|---|---|---:|---:|---:|---:|---:|---|---|---|---:|---:|"]
        for r in sorted(main, key=lambda r: (r["room"], PRESETS.index(r["preset"]), r["faces"])):
            mesh = "scan" if r["faces"] > 1000 else "clean"
            lines.append(
                f"| {r['room']} | {r['preset']} | {mesh} | {r['faces']:,} | "
                f"{r['proxy_faces'] or '-'} | {r['leaves']:,} | {r['links']:,} | "
                f"{r['seconds']:.1f} | {r['peak_mb']:.0f} ({r['rss_read_mb']:.0f}) | "
                f"{_f(r['relit_all'])} / {_f(r['relit_shadow'])} | "
                f"{_f(r['scale_all'])} / {_f(r['scale_shadow'])} | {_f(r['floor'])} | "
                f"{r['ratio_error']:.3f} |")
        lines.append("")
        for preset in PRESETS:
            pairs = []
            for room in sorted({r["room"] for r in main}):
                c = [r for r in main if r["room"] == room and r["preset"] == preset]
                scan = [r for r in c if r["faces"] > 1000]
                clean = [r for r in c if r["faces"] <= 1000]
                if scan and clean:
                    pairs.append((scan[0], clean[0]))
            if pairs:
                s_all = [p[0]["relit_all"] for p in pairs]
                c_all = [p[1]["relit_all"] for p in pairs]
                s_sh = [p[0]["relit_shadow"] for p in pairs]
                c_sh = [p[1]["relit_shadow"] for p in pairs]
                lines.append(
                    f"- {preset}: scan {np.mean(s_all):.2f} (worst {np.max(s_all):.2f}) / "
                    f"{np.nanmean(s_sh):.2f} (worst {np.nanmax(s_sh):.2f}) against clean "
                    f"{np.mean(c_all):.2f} (worst {np.max(c_all):.2f}) / {np.nanmean(c_sh):.2f} "
                    f"(worst {np.nanmax(c_sh):.2f}), over {len(pairs)} rooms; scan time "
                    f"{np.mean([p[0]['seconds'] for p in pairs]):.1f} s, peak "
                    f"{np.max([p[0]['peak_mb'] for p in pairs]):.0f} MB")
        lines.append("")
    sizes = [r for r in ok if r["room"] == 0 and r["preset"] == "medium"
             and r.get("proxy_setting", 0) == 0 and r["faces"] > 1000 and not r.get("one_group")]
    if sizes:
        lines += ["## Memory and time against the mesh size (room 0, medium)", "",
                  "| faces | time s | read s | peak RSS MB | after read MB | precompute MB "
                  "(peak - after read) | estimate MB | estimate without the proxy MB | "
                  "lamp off |",
                  "|---:|---:|---:|---:|---:|---:|---:|---:|---|"]
        for r in sorted(sizes, key=lambda r: r["faces"]):
            lines.append(
                f"| {r['faces']:,} | {r['seconds']:.1f} | {r['read_s']:.1f} | "
                f"{r['peak_mb']:.0f} | {r['rss_read_mb']:.0f} | "
                f"{r['peak_mb'] - r['rss_read_mb']:.0f} | {r['estimate_mb']:.0f} | "
                f"{r['estimate_without_proxy_mb']:,.0f} | {_f(r['relit_all'])} / "
                f"{_f(r['relit_shadow'])} |")
        lines.append("")
        big = max(sizes, key=lambda r: r["faces"])
        lines.append(f"Timings of the largest ({big['faces']:,} faces), s: " + ", ".join(
            f"{k} {v:.1f}" for k, v in big["timings"].items()) + ".")
        lines.append("")
    one = [r for r in ok if r.get("one_group")]
    if one:
        lines += ["## One object, one material (a real scan)", "",
                  "The family's scans keep a group (a Blender object and material) per surface; "
                  "a real scan is usually one object with one material.  The same scans with "
                  "every surface face in one group (the shadow-edge vote then tells surfaces "
                  "apart by their facing and place only), at medium:", "",
                  "| room | faces | time s | lamp off: all / shadow, one group | per-surface "
                  "groups |", "|---|---:|---:|---|---|"]
        grouped = {(r["room"], r["preset"]): r for r in main if r["faces"] > 1000}
        for r in sorted(one, key=lambda r: r["room"]):
            g = grouped.get((r["room"], r["preset"]))
            lines.append(f"| {r['room']} | {r['faces']:,} | {r['seconds']:.1f} | "
                         f"{_f(r['relit_all'])} / {_f(r['relit_shadow'])} | " +
                         (f"{_f(g['relit_all'])} / {_f(g['relit_shadow'])} |" if g else "- |"))
        lines += ["", f"One group: {np.mean([r['relit_all'] for r in one]):.2f} (worst "
                  f"{np.max([r['relit_all'] for r in one]):.2f}) / "
                  f"{np.nanmean([r['relit_shadow'] for r in one]):.2f} (worst "
                  f"{np.nanmax([r['relit_shadow'] for r in one]):.2f}) over {len(one)} rooms.", ""]
    scans = [r for r in ok if r["faces"] > 1000]
    if scans:
        ratio = [(r, r["estimate_mb"] / (r["peak_mb"] - r["rss_read_mb"] + base)) for r in scans]
        lines += ["## The memory estimate on scans", "",
                  "What the operator checks before it starts (core/radiosity/memory.py), against "
                  f"what the precompute added (peak - after read, + {base:.0f} MB for Python and "
                  "numpy, as the estimate counts it); the issue asks for within 25 %.  The same "
                  "case's peak varies by about +-14 % from run to run.", "",
                  "| preset | cases | estimate / measured: min | mean | max |",
                  "|---|---:|---:|---:|---:|"]
        for preset in PRESETS:
            q = [x for r, x in ratio if r["preset"] == preset]
            if q:
                lines.append(f"| {preset} | {len(q)} | {min(q):.2f} | {np.mean(q):.2f} | "
                             f"{max(q):.2f} |")
        q = [x for _, x in ratio]
        lines += ["", f"All {len(q)} scan cases: {min(q):.2f}-{max(q):.2f} "
                  f"({sum(abs(x - 1) <= 0.25 for x in q)} within 25 %).", ""]
    if photos:
        lines += ["## Photo-resolution textures on a scan (room 0, ~100k faces, medium)", "",
                  "The same scan with every photo upscaled (its texels repeated): memory and "
                  "time only (the truth no longer matches texel for texel).", "",
                  "| photo scale | texels | time s | peak RSS MB (after read) | measured MB "
                  "(+ base) | estimate MB | estimate / measured |",
                  "|---:|---:|---:|---|---:|---:|---:|"]
        for r in sorted(photos, key=lambda r: r["photo_up"]):
            m = r["peak_mb"] - r["rss_read_mb"] + base
            lines.append(f"| {r['photo_up']}x | {r['texels']:,} | {r['seconds']:.0f} | "
                         f"{r['peak_mb']:.0f} ({r['rss_read_mb']:.0f}) | {m:.0f} | "
                         f"{r['estimate_mb']:.0f} | {r['estimate_mb'] / m:.2f} |")
        lines.append("")
    curve = [r for r in ok if r.get("proxy_setting", 0)]
    if curve:
        lines += ["## The proxy's size: speed against accuracy (room 0, ~100k faces, medium)",
                  "", "| proxy faces asked | got | leaves | links | time s | peak RSS MB | "
                  "lamp off: all / shadow |", "|---:|---:|---:|---:|---:|---:|---|"]
        for r in sorted(curve, key=lambda r: r["proxy_setting"]):
            lines.append(f"| {r['proxy_setting']:,} | {r['proxy_faces']:,} | {r['leaves']:,} | "
                         f"{r['links']:,} | {r['seconds']:.1f} | {r['peak_mb']:.0f} | "
                         f"{_f(r['relit_all'])} / {_f(r['relit_shadow'])} |")
        lines.append("")
    lines += _seed_spread()
    bad = [r for r in records if r.get("status") != "ok"]
    if bad:
        lines += ["Failed or timed out: " + ", ".join(
            f"room {r['room']} {r['faces']} {r['preset']} ({r['status']})" for r in bad), ""]
    load = os.getloadavg()
    lines.append(f"Machine: {platform.machine()}, {os.cpu_count()} cores, Python "
                 f"{platform.python_version()}; load average at the end {load[0]:.2f}.  "
                 f"Date: {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}.")
    path_md.write_text("\n".join(lines) + "\n")
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return
    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    if sizes:
        s = sorted(sizes, key=lambda r: r["faces"])
        f = [r["faces"] for r in s]
        ax[0].plot(f, [r["seconds"] for r in s], "o-", label="precompute s")
        ax[0].plot(f, [(r["peak_mb"] - r["rss_read_mb"]) / 100 for r in s], "s-",
                   label="precompute memory (100 MB)")
        ax[0].plot(f, [r["estimate_mb"] / 100 for r in s], "x--", label="estimate (100 MB)")
        ax[0].set_xlabel("faces of the scan")
        ax[0].set_ylabel("seconds, or hundreds of MB")
        ax[0].set_title("room 0, medium")
        ax[0].legend()
    if curve:
        c = sorted(curve, key=lambda r: r["proxy_setting"])
        ax[1].plot([r["seconds"] for r in c], [r["relit_all"] for r in c], "o-", label="all")
        ax[1].plot([r["seconds"] for r in c], [r["relit_shadow"] for r in c], "s-",
                   label="former shadows")
        for r in c:
            ax[1].annotate(str(r["proxy_setting"]), (r["seconds"], r["relit_all"]))
        ax[1].set_xlabel("precompute s")
        ax[1].set_ylabel("lamp off, mean CIEDE2000")
        ax[1].set_title("proxy faces (room 0 scan, medium)")
        ax[1].legend()
    fig.tight_layout()
    fig.savefig(path_png, dpi=80)


def _seed_spread():
    """scan.md's section on the seeds (results/scan_seeds_raw*.json): per preset, the rooms'
    mean and worst lamp-off error over the seeds, and where a preset is not more accurate than
    the one below it on a seed."""
    import glob

    import numpy as np
    recs = [r for path in sorted(glob.glob(str(RESULTS / "scan_seeds_raw*.json")))
            for r in json.loads(Path(path).read_text()) if r.get("status") == "ok"]
    if not recs:
        return []
    seeds = sorted({r["seed"] for r in recs})
    by = {(r["preset"], r["seed"], r["room"]): r for r in recs}
    presets = [p for p in PRESETS if any(r["preset"] == p for r in recs)]
    # the rooms run at every preset with every seed
    rooms = sorted(m for m in {r["room"] for r in recs}
                   if all((p, s, m) in by for p in presets for s in seeds))
    if not rooms:
        return []

    def fig(p, s, part):
        v = [by[p, s, m][part] for m in rooms]
        return float(np.nanmean(v)), float(np.nanmax(v))

    def span(v, nd=2):
        return f"{min(v):.{nd}f} - {max(v):.{nd}f}"
    lines = [f"## Spread over the seed (seeds {seeds[0]}-{seeds[-1]}, scans of ~100k faces)", "",
             f"Rooms {', '.join(map(str, rooms))} as scans, each precomputed with the seed of the "
             "orientation, the solver and the texel rays set to each seed (`--seeds`; the mesh "
             "is the same).  Lamp off, mean CIEDE2000 as above: the rooms' mean and worst, "
             "min - max over the seeds.  Times: wall times with another benchmark running "
             "beside (about 1.5-2x a lone run's).", "",
             "| preset | all: mean | worst room | shadows: mean | worst room | time s | "
             "lamps taking the photo's ratio over the set power, in full or in part (runs) |",
             "|---|---:|---:|---:|---:|---:|---|"]
    for p in presets:
        a = [fig(p, s, "relit_all") for s in seeds]
        b = [fig(p, s, "relit_shadow") for s in seeds]
        t = [np.mean([by[p, s, m]["seconds"] for m in rooms]) for s in seeds]
        over = [f"room {m} seed {s}" for s in seeds for m in rooms
                if any(by[p, s, m]["applied"])]
        lines.append(f"| {p} | {span([x[0] for x in a])} | {span([x[1] for x in a])} | "
                     f"{span([x[0] for x in b])} | {span([x[1] for x in b])} | {span(t, 0)} | "
                     f"{', '.join(over) or 'none'} |")
    worse = []
    for lo, hi in zip(presets, presets[1:]):
        for s in seeds:
            for part, name in (("relit_all", "all"), ("relit_shadow", "shadows")):
                for k, what in ((0, "mean"), (1, "worst")):
                    x, y = fig(lo, s, part)[k], fig(hi, s, part)[k]
                    if y > x + 0.005:
                        worse.append(f"{hi} vs {lo} seed {s} {name} {what} {y:.2f} vs {x:.2f}")
    lines += ["", "A preset less accurate than the one below it on a seed's figure (by more "
              "than 0.005): " + ("; ".join(worse) if worse else "none") + ".", ""]
    return lines


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--child", nargs="+")
    ap.add_argument("--photos-only", action="store_true",
                    help="rerun the photo-resolution cases only, into the existing results")
    ap.add_argument("--one-group-only", action="store_true",
                    help="rerun the one-group scans only, into the existing results")
    ap.add_argument("--quick", action="store_true", help="the size scaling only")
    ap.add_argument("--rooms", nargs="*", type=int, default=list(ROOMS))
    ap.add_argument("--presets", nargs="*", default=list(PRESETS))
    ap.add_argument("--faces", type=int, default=100_000)
    ap.add_argument("--seeds", help="e.g. 0-4: the scans at every preset, per seed")
    ap.add_argument("--seeds-raw", default="results/scan_seeds_raw.json")
    ap.add_argument("--report", action="store_true", help="scan.md from the raw JSON only")
    args = ap.parse_args(argv)
    if args.child:
        room, faces, preset, pf = args.child[:4]
        child(int(room), int(faces), preset, int(pf), len(args.child) > 4 and args.child[4] == "1",
              int(args.child[5]) if len(args.child) > 5 else 1,
              int(args.child[6]) if len(args.child) > 6 else 0)
        return
    if args.seeds:
        a, _, b = args.seeds.partition("-")
        path = Path(args.seeds_raw)
        path = path if path.is_absolute() else ROOT / "benchmarks" / path
        seeded = json.loads(path.read_text()) if path.exists() else []
        for room in args.rooms:
            for preset in args.presets:
                for seed in range(int(a), int(b or a) + 1):
                    seeded.append(run(room, args.faces, preset, seed=seed))
                    path.write_text(json.dumps(seeded, indent=1))
        args.report = True
    if args.report:
        records = json.loads((RESULTS / "scan_raw.json").read_text())
        write(records, RESULTS / "scan.md", RESULTS / "scan.png")
        return
    if args.photos_only or args.one_group_only:
        # those cases run again, in place of theirs in the existing results
        records = json.loads((RESULTS / "scan_raw.json").read_text())
        if args.photos_only:
            records = [r for r in records if r.get("photo_up", 1) == 1]
            records += [run(0, args.faces, "medium", photo_up=up) for up in PHOTO_UPSCALES]
        else:
            records = [r for r in records if not r.get("one_group")]
            records += [run(room, args.faces, "medium", one_group=True) for room in args.rooms]
        (RESULTS / "scan_raw.json").write_text(json.dumps(records, indent=1))
        write(records, RESULTS / "scan.md", RESULTS / "scan.png")
        return
    records = []
    for n in SIZES:
        records.append(run(0, n, "medium"))
    if not args.quick:
        for pf in PROXY_CURVE:
            records.append(run(0, args.faces, "medium", pf))
        for room in args.rooms:
            for preset in args.presets:
                records.append(run(room, 0, preset))
                if not (room == 0 and preset == "medium" and args.faces in SIZES):
                    records.append(run(room, args.faces, preset))
        records += [run(room, args.faces, "medium", one_group=True) for room in args.rooms]
        records += [run(0, args.faces, "medium", photo_up=up) for up in PHOTO_UPSCALES]
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "scan_raw.json").write_text(json.dumps(records, indent=1))
    write(records, RESULTS / "scan.md", RESULTS / "scan.png")
    print((RESULTS / "scan.md").read_text())


if __name__ == "__main__":
    main()
