"""RenderPark's own example scenes, side by side (issue 10 "Scale"): the office of rpkCpp's
etc/office3/office.mgf (Radiance's office example converted to MGF: a desk, chairs, book
cases, blinds, two fluorescent panels and a desk lamp; walls, floor and ceiling are thin slabs)
and the classroom of etc/salon/classroom.mgf (desks and chairs, ceiling lamps, windows).

The scene files are not shipped with the project (RenderPark's licence allows redistribution
only with its authors' permission).  Fetch them from the public repository OscarChavarro/rpkCpp:
commit 20874afedeea4e9a4e15119e911fd368203955c7, path etc/office3/office.mgf (51,972 bytes,
sha256 fa299a7820ec7a0b7b954b0c192ba4640eb8ac4767aaf7469b35a3c5e6952e34); commit
c98a00f1dbe7d815ebe064ce5e9bbeb61cb94435, path etc/salon/classroom.mgf (1,118,244 bytes, sha256
ce14567c84698736be76b8548634c86eae60ff59efb2811c2b88520067687b1d), and
pass a path (the scene is told by the file's name, or ``--scene``).

The file is read by benchmarks/mgf.py (curved surfaces cut as RenderPark does, 4 divisions per
quarter circle: 12,463 faces, 12,629 patches, 3 lamps), its faces turned to the side their lamps
light and given backs where both sides are lit (core/relight/orient.py: the slabs' faces point
into the slabs, so read one-sided the room would see their backs), then solved by
``solve_radiosity`` with one radiosity basis per lamp, as the precompute does.  Each preset runs
in its own process, so that its peak RSS is its own.  The peer is rpkCpp (Galerkin hierarchical
radiosity with clustering, one system for all lamps, one thread).  With ``--peer PATH/rpk`` it
is run here, on the same file, in the same session (benchmarks/peer.py: its process CPU time
and peak RSS, the median of ``--peer-runs`` runs of ``--peer-iterations`` iterations), and the
report says so; without it the report uses ``PEERS``, issue 47's measurement, and says where
those figures come from.  Our side is the child's process CPU time too ("solve CPU s").

    python benchmarks/bench_mgf.py PATH/office.mgf [--presets draft,medium] [--peer PATH/rpk]
    python benchmarks/bench_mgf.py PATH/classroom.mgf
    python benchmarks/bench_mgf.py PATH/office.mgf --presets draft,medium,high --seeds 1,2,3,4

Writes benchmarks/results/mgf.md (the office) or mgf_classroom.md, seed 0.  With ``--seeds``,
the spread over the random seed (the oracle's and the final links' rays): each (seed, preset)
solve is added to mgf_seeds_raw.json (or mgf_classroom_seeds_raw.json) as it ends, so that
seeds can be run in several sittings, and mgf_seeds.md (mgf_classroom_seeds.md) is written
from every seed stored there.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

from bench_cornell import worse_than_below
from peer import RPK_ITERATIONS, measure_runs, rpk_command, source_line

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
# the rpkCpp measurements, per scene, and where each report goes
# rpkCpp with its defaults, converged (process CPU time, peak RSS): measured by the session that
# filed issue 47 on a 2-core machine of this kind, not by this script; a table says so
PEERS = {"office": {"faces": 12_607, "seconds": 58.5, "peak_mb": 193.0, "report": "mgf.md",
                    "seeds": "mgf_seeds", "seconds_range": "57-60"},
         "classroom": {"faces": 5_250, "seconds": 116.5, "peak_mb": 758.0,
                       "report": "mgf_classroom.md", "seeds": "mgf_classroom_seeds",
                       "seconds_range": "109-124"}}
PEER_SOURCE = ("measured by the session that filed issue 47, on a 2-core machine of this "
               "kind, not in this run")
PRESET_ORDER = ("draft", "medium", "high", "ultra")
REFERENCE_PATCHES = 12
# 4 M samples a patch: at 1 M the reference's own noise (0.63 % on the classroom's largest
# patches) was the size of the gap between medium and high, and two 1 M runs differed by up to
# 1.7 % on one patch
REFERENCE_SPP = 1 << 22


def child(path, preset, seed=0):
    import resource

    import numpy as np
    sys.path.insert(0, str(ROOT))
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from mgf import parse_mgf
    from relight_addon.core.radiosity.memory import estimate_precompute_memory
    from relight_addon.core.radiosity.precompute import solve_radiosity
    from relight_addon.core.relight.orient import orient
    t0 = time.perf_counter()
    model = parse_mgf(path)
    scene = model.scene()
    read_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    oriented = orient(scene, scene.make_occluder(), 0)
    two = oriented.scene
    orient_s = time.perf_counter() - t0
    rss_before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    estimate = estimate_precompute_memory(two, preset, proxy=False) / 2**20
    t0, c0 = time.perf_counter(), time.process_time()
    sol = solve_radiosity(two, preset, seed=seed)
    B = sol.patch_radiosity()
    solve_s = time.perf_counter() - t0
    solve_cpu_s = time.process_time() - c0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    area = two.area_normal()[0]
    lum = np.array([0.2126, 0.7152, 0.0722])
    emitted = float(area @ (two.emission @ lum))
    reflected = float(area @ ((B - two.emission) @ lum))
    rows = sol.system.gather(sol.system.exposure[:, None])[:, 0]     # 1 on exposed surfaces
    probes = reference_patches(two)
    near = near_lamp_patches(two)
    print(json.dumps(dict(probes=probes.tolist(), probe_radiosity=(B[probes] @ lum).tolist(),
        near_probes=near.tolist(), near_radiosity=(B[near] @ lum).tolist(),
        preset=preset, seed=seed, faces=model.faces, patches=scene.n_patches,
        patches_oriented=two.n_patches,
        flipped=int(oriented.flipped.sum()), backs=int(len(oriented.back_of)),
        lamps=len(scene.lamp_names), read_s=read_s, orient_s=orient_s, solve_s=solve_s,
        solve_cpu_s=solve_cpu_s,
        rss_before_mb=rss_before, peak_mb=peak, estimate_mb=estimate,
        elements=int(sol.hierarchy.n), leaves=int(len(sol.leaves)), links=int(sol.links.n),
        iterations=int(sol.info.iterations), residual=float(sol.info.residual),
        converged=bool(getattr(sol.info, "converged", True)),
        reflected_over_emitted=reflected / max(emitted, 1e-300),
        rows_max=float(rows.max()), finite=bool(np.isfinite(B).all()))))


def oriented_scene(path):
    sys.path.insert(0, str(ROOT))
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from mgf import read_mgf
    from relight_addon.core.relight.orient import orient
    scene = read_mgf(path)
    return orient(scene, scene.make_occluder(), 0)


def reference_patches(scene, n=REFERENCE_PATCHES):
    """The n largest patches that are not lamps: where Mitsuba's estimate is sharpest."""
    import numpy as np
    area = scene.area_normal()[0]
    cand = np.flatnonzero(scene.lamp < 0)
    return np.sort(cand[np.argsort(-area[cand], kind="stable")[:n]])


def near_lamp_patches(scene, n=REFERENCE_PATCHES, shortlist=10, lamp_points=4):
    """The n patches that are not lamps (nor among the largest) with the most direct light at
    their centres: the ``shortlist`` x n with the most unoccluded, then the n with the most
    seen past occluders from ``lamp_points`` x ``lamp_points`` points of every lamp (a face
    3 mm behind another, lit in the open, is dark in fact).  At least 1 % of the largest
    ones' smallest area, so that Mitsuba's estimate stays sharp.  On the classroom these are
    the tube fixtures' reflectors, where the largest patches did not show medium 10 % high."""
    import numpy as np
    sys.path.insert(0, str(ROOT))
    from relight_addon.core.geometry.formfactor import point_kernel, point_to_polygon
    from relight_addon.core.geometry.raycast import ray_offset
    from relight_addon.core.geometry.sampling import quadrature
    area, normal = scene.area_normal()
    largest = reference_patches(scene)
    cand = np.setdiff1d(np.flatnonzero((scene.lamp < 0) & (area >= 0.01 * area[largest].min())),
                        largest)
    centre = scene.corners[cand].mean(axis=1)
    lum = np.array([0.2126, 0.7152, 0.0722])
    lamps = np.flatnonzero(scene.lamp >= 0)
    # (lamps, cand): each lamp's unoccluded light at each centre, read twice below
    unoccluded = np.stack([(scene.emission[lamp] @ lum) * point_to_polygon(
        centre, normal[cand], np.repeat(scene.corners[lamp][None], len(cand), axis=0),
        np.repeat(normal[lamp][None], len(cand), axis=0)) for lamp in lamps])
    keep = np.argsort(-unoccluded.sum(axis=0), kind="stable")[:shortlist * n]
    cand, centre, unoccluded = cand[keep], centre[keep], unoccluded[:, keep]
    occluder = scene.make_occluder()
    lo, hi = scene.corners.reshape(-1, 3).min(0), scene.corners.reshape(-1, 3).max(0)
    eps = ray_offset(float(np.linalg.norm(hi - lo)))
    seen = np.zeros(len(cand))
    pts, w = quadrature(scene.corners[lamps], lamp_points)              # (lamps, k, 3)
    for lamp, lp, lw, light in zip(lamps, pts, w, unoccluded):
        q = np.broadcast_to(lp, (len(cand),) + lp.shape).reshape(-1, 3)
        p = np.repeat(centre, len(lp), axis=0)
        nr = np.repeat(normal[cand], len(lp), axis=0)
        ns = np.broadcast_to(normal[lamp], q.shape)
        kernel = (point_kernel(nr, ns, q - p) * np.tile(lw, len(cand))).reshape(len(cand), -1)
        free = ~occluder.segments_occluded(p + eps * nr, q + eps * ns).reshape(len(cand), -1)
        # the points weigh the visible fraction only: near a lamp their sum is far from F
        fraction = (kernel * free).sum(axis=1) / np.maximum(kernel.sum(axis=1), 1e-300)
        seen += fraction * light
    return np.sort(cand[np.argsort(-seen, kind="stable")[:n]])


def mitsuba_reference(path, probes, spp):
    """Mitsuba 3's radiosity (luminance) of the ``probes`` patches of the oriented scene, with
    their standard errors.  Mitsuba's surfaces are one-sided like ours; each back made for a
    face lit on both sides is moved 0.1 mm behind its front, so that a ray meets the side it
    comes from."""
    import numpy as np
    sys.path.insert(0, str(ROOT / "tests"))
    from reference.mitsuba_ref import patch_radiosity
    oriented = oriented_scene(path)
    scene = oriented.scene
    n = len(oriented.back_of)
    if n:
        corners = scene.corners.copy()
        normal = scene.area_normal()[1]
        corners[-n:] += 1e-4 * normal[-n:, None, :]
        occluder = scene.occluder.copy()
        occluder[-n:] = True         # its front blocks for it here; moved, it blocks itself
        scene = replace(scene, corners=corners, occluder=occluder)
    B, err = patch_radiosity(scene, probes, spp=spp, return_stderr=True)
    lum = np.array([0.2126, 0.7152, 0.0722])
    return B @ lum, err @ lum


def run(path, preset, seed=0, timeout=3600):
    cmd = [sys.executable, __file__, str(path), "--child", preset, "--seed", str(seed)]
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    lines = [x for x in out.stdout.splitlines() if x.startswith("{")]
    if out.returncode or not lines:
        raise RuntimeError(f"{preset}: {out.stderr[-2000:]}")
    return json.loads(lines[-1])


def machine_line():
    """The reports' last line: the load when they were written, the machine, the date."""
    return (f"Load average at the end: {os.getloadavg()[0]:.2f}; {os.cpu_count()} CPUs; Python "
            f"{platform.python_version()}.  Date: "
            f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}.")


def peer_figures(scene, measured=None):
    """(CPU seconds, peak MB, the sentence saying where they come from) of the peer: measured
    in this run (benchmarks/peer.py's measure_runs) when given, else issue 47's ``PEERS``."""
    if measured is not None:
        return measured["cpu_s"], measured["peak_mb"], (
            f"rpkCpp {measured['cpu_s']:.1f} s of CPU, {measured['peak_mb']:.0f} MB: "
            + source_line(measured))
    peer = PEERS[scene]
    return peer["seconds"], peer["peak_mb"], (
        f"rpkCpp with its defaults, converged: {peer['faces']:,} patches, "
        f"{peer['seconds_range']} s of CPU, {peer['peak_mb']:.0f} MB ({PEER_SOURCE})")


def report(rows, reference=None, scene="office", measured=None):
    RESULTS.mkdir(parents=True, exist_ok=True)
    peer = PEERS[scene]
    peer_cpu, peer_mb, peer_source = peer_figures(scene, measured)
    first = rows[0]
    lines = [
        f"# RenderPark's {scene} (MGF), side by side with rpkCpp", "",
        "Generated by `benchmarks/bench_mgf.py` (see its docstring for the scene file, which is "
        "not shipped).  " f"{first['faces']:,} faces read ({first['patches']:,} patches, "
        f"{first['lamps']} lamps); turned to their lit side ({first['flipped']:,} flipped) with "
        f"{first['backs']:,} backs where both sides are lit: {first['patches_oriented']:,} "
        "patches solved, one basis per lamp.  Each preset in its own process; peak RSS "
        "includes Python, numpy, scipy and Embree (the RSS before the solve is shown); \"time / "
        "rpkCpp's\" is process CPU over process CPU.  " f"{peer_source}.", "",
        "| preset | elements | leaves | links | solve s | solve CPU s | peak RSS MB "
        "| RSS before the solve MB "
        "| estimate MB | peak / rpkCpp's | time / rpkCpp's | GMRES iterations | residual "
        "| reflected / emitted | max row sum | vs Mitsuba mean % | max % "
        "| near lamps: mean % | max % | bias % |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
        "---:|---:|"]
    for r in rows:
        lines.append(
            f"| {r['preset']} | {r['elements']:,} | {r['leaves']:,} | {r['links']:,} | "
            f"{r['solve_s']:.1f} | {_cpu(r):.1f} | {r['peak_mb']:.0f} | "
            f"{r['rss_before_mb']:.0f} | "
            f"{r['estimate_mb']:.0f} | {r['peak_mb'] / peer_mb:.2f} | "
            f"{_cpu(r) / peer_cpu:.2f} | {r['iterations']} | {r['residual']:.1e} | "
            f"{r['reflected_over_emitted']:.3f} | {r['rows_max']:.4f} | "
            + (f"{100 * r['ref_mean']:.2f} | {100 * r['ref_max']:.2f} | "
               f"{100 * r['near_mean']:.2f} | {100 * r['near_max']:.2f} | "
               f"{100 * r['near_bias']:+.2f} |" if reference else "- | - | - | - | - |"))
    lines += ["", "Reading the file took {:.1f} s and orienting the faces {:.1f} s (not in the "
              "solve time).".format(first["read_s"], first["orient_s"]), "",
              "\"reflected / emitted\": luminance power reflected by all patches over the power "
              "the lamps emit" + (" (the issue measured 0.0035 of RenderPark's reflected light "
                                  "on its office read one-sided, its slabs' backs facing the room)"
                                  if scene == "office" else "") +
              f"; here {first['flipped']:,} faces are turned round and {first['backs']:,} get "
              "backs.", "",
              machine_line()]
    if reference:
        lines[-3:-3] = [reference, ""]
    (RESULTS / peer["report"]).write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


def _cpu(row):
    """A row's solve CPU seconds (rows written before they were kept: wall seconds)."""
    return row.get("solve_cpu_s", row["solve_s"])


def score(path, rows):
    """Each row's errors against Mitsuba 3 on the probes of the first row (the same patches at
    every preset and seed: they depend on the scene only); returns the reference's paragraph."""
    import numpy as np
    probes, near = rows[0]["probes"], rows[0]["near_probes"]
    both, both_err = mitsuba_reference(path, probes + near, REFERENCE_SPP)
    ref, err = both[:len(probes)], both_err[:len(probes)]
    near_ref, near_err = both[len(probes):], both_err[len(probes):]
    lit = ref > 0             # a patch lying under another (a floor under its carpet) is dark
    near_lit = near_ref > 0
    for r in rows:
        assert r["probes"] == probes and r["near_probes"] == near
        ours = np.array(r["probe_radiosity"])
        rel = np.abs(ours[lit] / ref[lit] - 1.0)
        r["ref_mean"], r["ref_max"] = float(rel.mean()), float(rel.max())
        r["dark_max"] = float(np.abs(ours[~lit]).max(initial=0.0))
        signed = np.array(r["near_radiosity"])[near_lit] / near_ref[near_lit] - 1.0
        r["near_mean"], r["near_max"] = float(np.abs(signed).mean()), float(np.abs(signed).max())
        r["near_bias"] = float(signed.mean())
    return (f"Mitsuba 3 reference (tests/reference/mitsuba_ref.py, {REFERENCE_SPP:,} "
            f"samples per patch): luminance radiosity of the {len(probes)} largest "
            "patches that are not lamps (walls, floor, ceiling, table tops), relative "
            f"standard error {100 * float(np.mean(err[lit] / ref[lit])):.2f} % on "
            f"average, {100 * float(np.max(err[lit] / ref[lit])):.2f} % at most.  "
            f"{int((~lit).sum())} of them lie under other faces and are dark in Mitsuba "
            "(ours at most " + ", ".join(f"{r['dark_max']:.3g}" for r in rows) +
            f" there, the lit ones at {float(np.median(ref[lit])):.0f} in the median): "
            "the error columns are over the others.  \"Near lamps\": the "
            f"{len(near)} patches with the most direct light at their centres "
            "(bench_mgf.near_lamp_patches: " + ", ".join(map(str, near)) + "), relative "
            f"standard error {100 * float(np.mean(near_err[near_lit] / near_ref[near_lit])):.2f} % "
            "on average; their mean signed error is the bias column.")


def seed_spread(path, scene, presets, seeds):
    """Runs every (seed, preset) in its own process, adding each to the scene's raw file as it
    ends, then writes the spread over every seed stored there."""
    raw_path = RESULTS / (PEERS[scene]["seeds"] + "_raw.json")
    raw = json.loads(raw_path.read_text()) if raw_path.exists() else []
    for seed in seeds:
        for preset in presets:
            raw = [r for r in raw if (r["seed"], r["preset"]) != (seed, preset)]
            row = run(path, preset, seed)
            raw.append(row)
            raw.sort(key=lambda r: (r["seed"], PRESET_ORDER.index(r["preset"])))
            RESULTS.mkdir(parents=True, exist_ok=True)
            raw_path.write_text(json.dumps(raw, indent=1) + "\n")
            print(f"seed {seed} {preset}: {row['solve_s']:.0f} s", flush=True)
    reference = score(path, raw)
    presets_run = [p for p in PRESET_ORDER if any(r["preset"] == p for r in raw)]
    seeds_run = sorted({r["seed"] for r in raw})
    # the comparison pairs presets seed by seed: only seeds solved at every preset
    complete = [s for s in seeds_run
                if {r["preset"] for r in raw if r["seed"] == s} == set(presets_run)]

    def by_preset(mean, worst):       # {preset: [(seed, links, mean, max)]}, as bench_cornell's
        return {p: [(r["seed"], r["links"], r[mean], r[worst]) for r in raw
                    if r["preset"] == p and r["seed"] in complete] for p in presets_run}
    lines = [f"# RenderPark's {scene} (MGF): spread over the random seed", "",
             "Generated by `benchmarks/bench_mgf.py --seeds` (the raw figures: "
             f"`{raw_path.name}`).  Seeds {', '.join(map(str, seeds_run))}; each (seed, preset) "
             "solved in its own process, as in the main table (which is seed 0 alone).  The "
             "oracle's and the final links' rays are random; the probes are the same patches "
             "at every seed.  The solve times compare with the main table's only if both ran "
             "alone on the machine (see the load average at the end).", "",
             "| seed | preset | links | solve s | peak RSS MB | largest: mean % | max % "
             "| near lamps: mean % | max % | bias % |",
             "|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in raw:
        lines.append(f"| {r['seed']} | {r['preset']} | {r['links']:,} | {r['solve_s']:.0f} | "
                     f"{r['peak_mb']:.0f} | {100 * r['ref_mean']:.2f} | {100 * r['ref_max']:.2f} | "
                     f"{100 * r['near_mean']:.2f} | {100 * r['near_max']:.2f} | "
                     f"{100 * r['near_bias']:+.2f} |")
    lines += ["", "Min - max over the seeds:", "",
              "| preset | largest: mean % | max % | near lamps: mean % | max % | bias % |",
              "|---|---:|---:|---:|---:|---:|"]
    for p in presets_run:
        rs = [r for r in raw if r["preset"] == p]

        def span(key, fmt="{:.2f}"):
            v = [100 * r[key] for r in rs]
            return fmt.format(min(v)) + " - " + fmt.format(max(v))
        lines.append(f"| {p} | {span('ref_mean')} | {span('ref_max')} | {span('near_mean')} | "
                     f"{span('near_max')} | {span('near_bias', '{:+.2f}')} |")
    worse = (worse_than_below(by_preset("ref_mean", "ref_max"))
             + [w + " (near lamps)" for w in worse_than_below(by_preset("near_mean", "near_max"))])
    lines += ["", "A preset less accurate than the one below it on a seed (mean or max, "
              f"largest patches or near lamps; seeds {', '.join(map(str, complete))}): "
              + (", ".join(worse) or "none") + ".", "",
              reference, "",
              machine_line()]
    (RESULTS / (PEERS[scene]["seeds"] + ".md")).write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("path")
    ap.add_argument("--presets", default="draft,medium")
    ap.add_argument("--child")
    ap.add_argument("--seed", type=int, default=0, help="the child's seed")
    ap.add_argument("--seeds", help="comma-separated: the spread over these seeds (see above)")
    ap.add_argument("--no-reference", action="store_true")
    ap.add_argument("--scene", choices=sorted(PEERS), help="default: the file's name")
    ap.add_argument("--peer", help="rpkCpp's program (build/rpk): run here on the same file")
    ap.add_argument("--peer-iterations", type=int, default=RPK_ITERATIONS)
    ap.add_argument("--peer-runs", type=int, default=3)
    args = ap.parse_args()
    if args.child:
        child(args.path, args.child, args.seed)
        return
    if not Path(args.path).is_file():
        sys.exit(f"{args.path}: no such file (see this script's docstring for where to get it)")
    scene = args.scene or Path(args.path).stem
    if scene not in PEERS:
        sys.exit(f"{args.path}: which scene is it? (--scene {'/'.join(sorted(PEERS))})")
    if args.seeds is not None:           # --seeds= (none) writes the report from the raw file
        seed_spread(args.path, scene, args.presets.split(","),
                    [int(x) for x in args.seeds.split(",") if x])
        return
    measured = None
    if args.peer:
        measured = measure_runs(rpk_command(args.peer, args.path, args.peer_iterations),
                                args.peer_runs)
        print("peer", measured, flush=True)
    rows = []
    for preset in args.presets.split(","):
        rows.append(run(args.path, preset))
        print(preset, {k: v for k, v in rows[-1].items() if not k.startswith("probe")}, flush=True)
    reference = None if args.no_reference else score(args.path, rows)
    report(rows, reference, scene, measured)


if __name__ == "__main__":
    main()
