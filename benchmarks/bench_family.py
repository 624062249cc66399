"""Relighting on the room family against Cycles truth (issue 9): writes results/family.md,
results/family_raw.json and results/family.png.

For every baked room (scenes/family.py, bakes in benchmarks/family/bakes/): the room read as a
user hands it to the add-on (scenes/family_eval.py), precomputed per preset (texel mode, the
default, and DRB97 = no texture correction, a baseline), scored for every target lighting (each
lamp off, each doubled, all but one off): mean and p95 CIEDE2000 overall and in each switched-off
lamp's former shadow, beside the global exposure scale, DRB97, photo-unchanged baselines and the
noise floor; the precompute time.  At the medium preset the lamps' powers are also set 30 % off
and to "unknown" (every lamp at its type's base power) to measure the exitance ratio error.

    python benchmarks/bench_family.py                       # every baked room, all presets
    python benchmarks/bench_family.py --rooms 16 17 --presets medium
    python benchmarks/bench_family.py --report              # tables and plot from the raw JSON
    python benchmarks/bench_family.py --seeds 0-4           # exact powers, every preset, per seed
    python benchmarks/bench_family.py --seeds 0-4 --rooms 0 1 --seeds-raw results/family_seeds_raw_a.json

With ``--seeds`` each room is precomputed (exact powers, texel mode only) with the solver's,
the orientation's and the texel rays' seed set to each of them; the figures go to
results/family_seeds_raw*.json (one file per process, so that two can run side by side) and
family.md reports their spread: the issue's "each preset more accurate than the one below, on
every seed".

Rooms 12-15 are held out from tuning (scenes.family.HELD_OUT): they are reported apart.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, ROOT)

RESULTS = os.path.join(HERE, "results")
RAW = os.path.join(RESULTS, "family_raw.json")
SEEDS_RAW = os.path.join(RESULTS, "family_seeds_raw.json")
PRESETS = ("draft", "medium", "high")


def run_room(index, presets, power_modes, log):
    import bpy  # noqa: F401, PLC0415

    from relight_addon.core.relight.shadowfree import ShadowFreeOptions, shadow_free
    from scenes import family_eval as fe
    out = {}
    for powers in power_modes:
        room = fe.photographed_room(index, powers)
        for preset in (presets if powers == "exact" else ("medium",)):
            t0 = time.perf_counter()
            res = shadow_free(room.data, ShadowFreeOptions(preset=preset))
            seconds = time.perf_counter() - t0
            drb = shadow_free(room.data, ShadowFreeOptions(preset=preset, mode="none")) \
                if powers == "exact" else None
            sc = fe.score(room, res, drb)
            est = res.lamps
            sc.update(seconds=seconds, powers=powers, preset=preset,
                      lamps=[lp.name for lp in room.spec.lamps],
                      photo_ratio=[float(est.photo_ratio[room.lamp_of[lp.name]])
                                   for lp in room.spec.lamps],
                      uncertainty=[float(est.uncertainty[room.lamp_of[lp.name]])
                                   for lp in room.spec.lamps],
                      applied=[bool(est.applied[room.lamp_of[lp.name]])
                               for lp in room.spec.lamps],
                      rho_mean=float(est.rho_mean), misfit=float(res.stats["photo_misfit"]),
                      elements=int(res.stats["elements"]), links=int(res.stats["links"]))
            out[f"{powers}/{preset}"] = sc
            log(f"room {index} {powers}/{preset}: {seconds:.1f} s, floor "
                f"{sc['floor'][0]:.2f}, ratio err {sc['ratio_error']:.3f}, rho^ {est.rho_mean:.2f}, "
                + ", ".join(f"{k}: {v['relit']['all'][0]:.2f}/{v['relit']['shadow'][0]:.2f}"
                            for k, v in sc["targets"].items() if k.endswith("off")))
    return out


def run_room_seeds(index, presets, seeds, log):
    """The room at exact powers, every preset, with each seed (texel mode only: no baseline)."""
    import bpy  # noqa: F401, PLC0415

    from relight_addon.core.relight.shadowfree import ShadowFreeOptions, shadow_free
    from scenes import family_eval as fe
    out = {}
    room = fe.photographed_room(index, "exact")
    for preset in presets:
        for seed in seeds:
            t0 = time.perf_counter()
            res = shadow_free(room.data, ShadowFreeOptions(preset=preset, seed=seed))
            seconds = time.perf_counter() - t0
            sc = fe.score(room, res, None)
            sc.update(seconds=seconds, preset=preset, seed=seed,
                      lamps=[lp.name for lp in room.spec.lamps],
                      rho_mean=float(res.lamps.rho_mean), links=int(res.stats["links"]))
            out[f"exact/{preset}/seed{seed}"] = sc
            f = room_figures(sc)["relit"]
            log(f"room {index} {preset} seed {seed}: {seconds:.1f} s, "
                f"{f['all']:.2f} / {f['shadow']:.2f}, rho^ {sc['rho_mean']:.3f}")
    return out


def _json_safe(x):
    if isinstance(x, dict):
        return {k: _json_safe(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_json_safe(v) for v in x]
    if isinstance(x, (np.floating, float)):
        return None if not np.isfinite(x) else float(x)
    if isinstance(x, (np.integer,)):
        return int(x)
    return x


# -- report -------------------------------------------------------------------------------------

def _off_rows(sc):
    """(label, row) of the lamp-off targets (each lamp off, and all but one off); none in a
    one-lamp room, where switching it off leaves black against black."""
    if len(sc.get("lamps", ())) < 2:
        return []
    return [(k, v) for k, v in sc["targets"].items() if k.endswith(" off") or k.startswith("only")]


def _agg(values):
    v = np.array([x for x in values if x is not None and np.isfinite(x)])
    if len(v) == 0:
        return float("nan"), float("nan")
    return float(v.mean()), float(v.max())


def _num(x):
    return "-" if x is None or not np.isfinite(x) else f"{x:.2f}"


def room_figures(sc):
    """Mean over the room's lamp-off targets of each method's overall and former-shadow mean
    (and p95), plus the doubled targets' overall mean."""
    rows = _off_rows(sc)
    fig = {}
    nan = float("nan")
    for m in ("relit", "drb97", "scale", "photo"):
        if not rows:
            if m in sc["targets"]["original"]:
                fig[m] = dict(all=nan, all_p95=nan, shadow=nan, shadow_p95=nan, worst_target=nan)
            continue
        if m not in rows[0][1]:
            continue
        fig[m] = {
            "all": float(np.mean([r[m]["all"][0] for _, r in rows])),
            "all_p95": float(np.mean([r[m]["all"][1] for _, r in rows])),
            "shadow": _agg([r[m]["shadow"][0] for _, r in rows if r[m]["shadow_texels"]])[0],
            "shadow_p95": _agg([r[m]["shadow"][1] for _, r in rows if r[m]["shadow_texels"]])[0],
            "worst_target": float(max(r[m]["all"][0] for _, r in rows)),
        }
    doubled = [v for k, v in sc["targets"].items() if k.endswith("x2")]
    fig["doubled"] = float(np.mean([r["relit"]["all"][0] for r in doubled]))
    orig = sc["targets"].get("original")
    fig["original"] = float("nan") if orig is None else orig["relit"]["all"][0]
    return fig


def write_report(raw, path_md, path_png):
    from scenes import family as fam
    rooms = sorted(raw, key=int)
    lines = ["# Relighting on the room family against Cycles truth", "",
             "Generated by `benchmarks/bench_family.py` (scenes/family.py rooms, Cycles bakes in "
             "benchmarks/family/bakes/; scoring in scenes/family_eval.py).  CIEDE2000, colours "
             "over the 99th percentile of the truth's luminance.  Per room: the mean over its "
             "lamp-off targets (each lamp off, and with several lamps each lamp alone) of the "
             "mean overall / in the switched-off lamps' former shadows; 'x2' is the mean over the "
             "doubled targets.  Baselines: DRB97 (no texture correction), the photo scaled by the "
             "best single factor given the truth (global exposure scale), the photo unchanged.  "
             "Noise floor: photo vs truth at the photo's own lighting (two independent bakes); "
             "'orig': the relit result at the photo's lighting vs the truth (target: within the "
             "floor + 0.3; '-' where the room was last run before that column existed).  "
             f"Rooms {fam.HELD_OUT} are held out from tuning; rooms {fam.TEST_ROOMS} are the "
             "test suite's small rooms (32 texels per surface, bakes in tests/data/family/), "
             "reported apart and in the all-rooms row.  A one-lamp room has no lamp-off figure (black "
             "against black): its doubled lamp and its original lighting are scored.", ""]
    for preset in PRESETS:
        key = f"exact/{preset}"
        have = [r for r in rooms if key in raw[r]]
        if not have:
            continue
        lines += [f"## {preset}", "",
                  "| room | lamps | floor | orig | relit: all / shadow (p95) | x2 | DRB97 "
                  "| global scale | photo | ratio err | rho^ | time |",
                  "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
        for r in have:
            sc = raw[r][key]
            f = room_figures(sc)
            held = (" (held out)" if int(r) in fam.HELD_OUT else
                     " (test room, 32 texels)" if int(r) in fam.TEST_ROOMS else "")
            d = f.get("drb97", {"all": np.nan, "shadow": np.nan})
            lines.append(
                f"| {r}{held} | {len(sc['lamps'])} | {sc['floor'][0]:.2f} | "
                f"{_num(f['original'])} | {f['relit']['all']:.2f} / {f['relit']['shadow']:.2f} "
                f"({f['relit']['all_p95']:.1f} / {f['relit']['shadow_p95']:.1f}) | "
                f"{f['doubled']:.2f} | {d['all']:.2f} / {d['shadow']:.2f} | "
                f"{f['scale']['all']:.2f} / {f['scale']['shadow']:.2f} | "
                f"{f['photo']['all']:.2f} / {f['photo']['shadow']:.2f} | "
                f"{sc['ratio_error']:.3f} | {sc['rho_mean']:.2f} | {sc['seconds']:.1f} s |"
                .replace("nan", "-"))
        full = [r for r in have if int(r) not in fam.TEST_ROOMS]
        for label, sel in (("tuning rooms", [r for r in full if int(r) not in fam.HELD_OUT]),
                           ("held-out rooms", [r for r in full if int(r) in fam.HELD_OUT]),
                           ("test rooms", [r for r in have if int(r) in fam.TEST_ROOMS]),
                           (f"all {len(have)} rooms", have)):
            if not sel:
                continue
            figs = [room_figures(raw[r][key]) for r in sel]
            floor = [raw[r][key]["floor"][0] for r in sel]
            rel_all = [f["relit"]["all"] for f in figs]
            rel_sh = [f["relit"]["shadow"] for f in figs]
            orig = [f["original"] for f in figs if np.isfinite(f["original"])]
            excess = [f["original"] - raw[r][key]["floor"][0] for r, f in zip(sel, figs)
                      if np.isfinite(f["original"])]
            rel_all = [x for x in rel_all if np.isfinite(x)] or [np.nan]
            lines.append(f"| **{label}: mean (worst)** | | {np.mean(floor):.2f} | "
                         + (f"{np.mean(orig):.2f} (floor +{np.max(excess):.2f}) | " if orig
                            else "- | ") +
                         f"**{np.mean(rel_all):.2f} ({np.max(rel_all):.2f}) / "
                         f"{np.nanmean(rel_sh):.2f} ({np.nanmax(rel_sh):.2f})** | "
                         f"{np.mean([f['doubled'] for f in figs]):.2f} | "
                         f"{np.nanmean([f['drb97']['all'] for f in figs if 'drb97' in f]):.2f} / "
                         f"{np.nanmean([f['drb97']['shadow'] for f in figs if 'drb97' in f]):.2f} | "
                         f"{np.nanmean([f['scale']['all'] for f in figs]):.2f} / "
                         f"{np.nanmean([f['scale']['shadow'] for f in figs]):.2f} | "
                         f"{np.nanmean([f['photo']['all'] for f in figs]):.2f} | | | "
                         f"{np.mean([raw[r][key]['seconds'] for r in sel]):.1f} s |")
        lines.append("")
    # presets ordered per room: where a preset is worse than the one below it
    worse = []
    for lo, hi in zip(PRESETS, PRESETS[1:]):
        for r in rooms:
            a, b = raw[r].get(f"exact/{lo}"), raw[r].get(f"exact/{hi}")
            if a is None or b is None:
                continue
            fa, fb = room_figures(a), room_figures(b)
            for part in ("all", "shadow"):
                x, y = fa["relit"][part], fb["relit"][part]
                if np.isfinite(x) and np.isfinite(y) and y > x + 0.05:
                    worse.append(f"room {r} {hi} vs {lo} ({part}): {y:.2f} vs {x:.2f}")
    lines += ["Presets per room: a preset worse than the one below it by more than 0.05 on a "
              "room's lamp-off mean, overall or in the former shadows: "
              + ("; ".join(worse) if worse else "none") + ".", ""]
    lines += _seed_spread(_seeded())
    lines += ["## Lamp exitance ratios (medium)", "",
              "Largest relative error of a lamp's exitance against the others' (its factor x the "
              "power it was set to, against its true power), with the lights' powers exact, 30 % "
              "off (alternately too high and too low) and unknown (every lamp at its type's base "
              "power).  In parentheses: the lamps whose photo estimate was applied.", "",
              "| room | lamps | exact | 30 % off | unknown | photo's view with exact powers "
              "(ratio +- sigma) |", "|---|---|---:|---:|---:|---|"]
    for r in rooms:
        row = raw[r]

        def cell(key):
            if key not in row:
                return "-"
            sc = row[key]
            n = sum(sc["applied"])
            return f"{sc['ratio_error']:.3f}" + (f" ({n})" if n else "")
        ex = row.get("exact/medium")
        view = "" if ex is None else ", ".join(
            f"{t:.2f}+-{s:.2f}" for t, s in zip(ex["photo_ratio"], ex["uncertainty"])
            if t is not None)
        lines.append(f"| {r} | {len(ex['lamps']) if ex else '-'} | {cell('exact/medium')} | "
                     f"{cell('off30/medium')} | {cell('unknown/medium')} | {view} |")
    lines.append("")
    with open(path_md, "w") as f:
        f.write("\n".join(lines))
    _plot(raw, path_png)


def _seeded():
    """The per-seed runs of every results/family_seeds_raw*.json, merged by room."""
    import glob
    seeded = {}
    for path in sorted(glob.glob(os.path.join(RESULTS, "family_seeds_raw*.json"))):
        for room, runs in json.load(open(path)).items():
            seeded.setdefault(room, {}).update(runs)
    return seeded


def _seed_spread(seeded):
    """Family.md's section on the seeds: per preset and seed, the rooms' mean and worst lamp-off
    error, their spread over the seeds, and where a preset is not more accurate than the one
    below it (on a seed's mean or worst over the rooms, or a room by more than 0.05)."""
    from scenes import family as fam
    if not seeded:
        return []
    rooms = sorted(seeded, key=int)
    seeds = sorted({int(k.rsplit("seed", 1)[1]) for r in rooms for k in seeded[r]})
    presets = [p for p in PRESETS if any(f"exact/{p}/seed{s}" in seeded[r]
                                         for r in rooms for s in seeds)]
    # per preset, seed: {room: (all, shadow)} over the rooms with lamp-off targets
    fig = {}
    for p in presets:
        for s in seeds:
            per = {}
            for r in rooms:
                sc = seeded[r].get(f"exact/{p}/seed{s}")
                if sc is None or len(sc["lamps"]) < 2:
                    continue
                f = room_figures(sc)["relit"]
                per[r] = (f["all"], f["shadow"])
            fig[p, s] = per
    common = sorted(set.intersection(*(set(v) for v in fig.values())), key=int)
    held = [r for r in common if int(r) in fam.HELD_OUT]

    def stats(p, s, sel):
        a = np.array([fig[p, s][r][0] for r in sel])
        b = np.array([fig[p, s][r][1] for r in sel])
        return a.mean(), a.max(), np.nanmean(b), np.nanmax(b)

    def span(values, nd=2):
        return f"{min(values):.{nd}f} - {max(values):.{nd}f}"

    lines = [f"## Spread over the seed (seeds {seeds[0]}-{seeds[-1]}, exact powers)", "",
             "Each room precomputed (texel mode) with the seed of the orientation, the solver and "
             "the texel rays set to each seed (`--seeds`; results/family_seeds_raw*.json), over "
             f"the {len(common)} rooms with lamp-off targets ({len(held)} held out).  Lamp-off "
             "CIEDE2000 as above: the rooms' mean (worst room), overall / in the former "
             "shadows; min - max over the seeds.  The times are wall times of runs made two "
             "or three side by side on the 2 cores (about twice a lone run's).", "",
             "| preset | all rooms: mean | worst room | shadows: mean | worst room | held-out "
             "rooms: mean | shadows: mean | time per room s |",
             "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for p in presets:
        st = [stats(p, s, common) for s in seeds]
        hs = [stats(p, s, held) for s in seeds] if held else None
        t = [np.mean([seeded[r][f"exact/{p}/seed{s}"]["seconds"] for r in common])
             for s in seeds]
        lines.append(f"| {p} | {span([x[0] for x in st])} | {span([x[1] for x in st])} | "
                     f"{span([x[2] for x in st])} | {span([x[3] for x in st])} | "
                     + (f"{span([x[0] for x in hs])} | {span([x[2] for x in hs])} | "
                        if hs else "- | - | ")
                     + f"{span(t, 1)} |")
    # the promise: each preset more accurate than the one below, on every seed
    broken, rooms_worse, spread = [], [], []
    names = ("mean", "worst room", "shadows' mean", "shadows' worst room")
    for lo, hi in zip(presets, presets[1:]):
        for s in seeds:
            a, b = stats(lo, s, common), stats(hi, s, common)
            broken += [f"{hi} vs {lo}, seed {s}, {n}: {y:.2f} vs {x:.2f}"
                       for n, x, y in zip(names, a, b) if y > x]
            for r in common:
                for part, x, y in zip(("all", "shadow"), fig[lo, s][r], fig[hi, s][r]):
                    if np.isfinite(x) and np.isfinite(y) and y > x + 0.05:
                        rooms_worse.append(f"room {r} {hi} vs {lo} seed {s} ({part}): "
                                           f"{y:.2f} vs {x:.2f}")
    for p in presets:
        for r in common:
            v = [fig[p, s][r][0] for s in seeds]
            spread.append((max(v) - min(v), p, r))
    spread.sort(reverse=True)
    lines += ["", "A preset less accurate than the one below it on a seed's figure over the "
              "rooms: " + ("; ".join(broken) if broken else "none") + ".  A room more than "
              "0.05 worse than at the preset below, on a seed: "
              + ("; ".join(rooms_worse) if rooms_worse else "none") + ".  Largest spread of a "
              "room's overall error over the seeds: "
              + ", ".join(f"room {r} {p} {d:.2f}" for d, p, r in spread[:3]) + ".", ""]
    return lines


def _plot(raw, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    rooms = sorted(raw, key=int)
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.2))
    x = np.arange(len(rooms))
    key = "exact/medium"
    have = [r for r in rooms if key in raw[r]]
    figs = [room_figures(raw[r][key]) for r in have]
    xs = np.arange(len(have))
    for m, c in (("relit", "C0"), ("drb97", "C1"), ("scale", "C2")):
        axes[0].plot(xs, [f[m]["shadow"] if m in f else np.nan for f in figs], "o-", color=c,
                     label=m if m != "scale" else "global scale")
    axes[0].plot(xs, [raw[r][key]["floor"][0] for r in have], "k--", label="noise floor")
    axes[0].set_xticks(xs, have)
    axes[0].set_xlabel("room")
    axes[0].set_ylabel("CIEDE2000 in the former shadows (lamp off)")
    axes[0].set_title("medium preset, per room")
    axes[0].legend()
    for preset, mk in zip(PRESETS, "sox"):
        k = f"exact/{preset}"
        sel = [r for r in rooms if k in raw[r]]
        if not sel:
            continue
        t = np.mean([raw[r][k]["seconds"] for r in sel])
        e = np.nanmean([room_figures(raw[r][k])["relit"]["all"] for r in sel])
        s = np.nanmean([room_figures(raw[r][k])["relit"]["shadow"] for r in sel])
        axes[1].plot([t], [e], mk, color="C0", label=f"{preset}: all")
        axes[1].plot([t], [s], mk, color="C3", label=f"{preset}: former shadows")
    axes[1].set_xlabel("mean precompute time per room (s)")
    axes[1].set_ylabel("mean CIEDE2000 (lamp off)")
    axes[1].set_title("speed / accuracy over the family")
    axes[1].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--rooms", type=int, nargs="*")
    ap.add_argument("--presets", default=",".join(PRESETS))
    ap.add_argument("--powers", default="exact,off30,unknown")
    ap.add_argument("--report", action="store_true")
    ap.add_argument("--seeds", help="e.g. 0-4: exact powers, every preset, per seed")
    ap.add_argument("--seeds-raw", default=SEEDS_RAW)
    args = ap.parse_args(argv)
    raw = json.load(open(RAW)) if os.path.exists(RAW) else {}
    if args.seeds and not args.report:
        from scenes import family as fam
        from scenes.addon import register_repo_addon
        register_repo_addon()
        a, _, b = args.seeds.partition("-")
        seeds = list(range(int(a), int(b or a) + 1))
        path = os.path.join(ROOT, "benchmarks", args.seeds_raw) \
            if not os.path.isabs(args.seeds_raw) else args.seeds_raw
        seeded = json.load(open(path)) if os.path.exists(path) else {}
        for r in (args.rooms if args.rooms else fam.baked_rooms()):
            got = run_room_seeds(r, args.presets.split(","), seeds,
                                 lambda s: print(s, flush=True))
            seeded.setdefault(str(r), {}).update(_json_safe(got))
            with open(path, "w") as f:
                json.dump(seeded, f, indent=1)
    elif not args.report:
        from scenes import family as fam
        from scenes.addon import register_repo_addon
        register_repo_addon()
        rooms = args.rooms if args.rooms else fam.baked_rooms()
        for r in rooms:
            got = run_room(r, args.presets.split(","), args.powers.split(","),
                           lambda s: print(s, flush=True))
            raw.setdefault(str(r), {}).update(_json_safe(got))
            with open(RAW, "w") as f:
                json.dump(raw, f, indent=1)
    write_report(raw, os.path.join(RESULTS, "family.md"), os.path.join(RESULTS, "family.png"))


if __name__ == "__main__":
    main()
