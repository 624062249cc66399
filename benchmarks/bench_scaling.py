"""Scaling of solve_radiosity with the number of input patches: time per phase and peak RSS.

Scene: cornell_box(subdivide=n) (17 n^2 patches).  Each (preset, n) case runs in its own
subprocess so that ru_maxrss is the peak of that case alone; a case that exceeds the time limit
is recorded as "timeout" (and larger n are skipped for that preset), one that exceeds the memory
cap (RLIMIT_AS) as "oom".  Writes benchmarks/results/scaling.md and scaling.png.

    python benchmarks/bench_scaling.py [--n 3 5 8 12 18 25] [--presets draft medium]
                                       [--timeout 300] [--mem-gb 10]
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

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
PHASES = ("setup", "refine", "form_factors", "visibility", "final_links", "solve")


def child(n: int, preset: str, mem_gb: float) -> None:
    """Run one case and print its stats as JSON on the last line of stdout."""
    import resource
    if mem_gb > 0:
        lim = int(mem_gb * 2**30)
        resource.setrlimit(resource.RLIMIT_AS, (lim, lim))
    sys.path.insert(0, str(ROOT))
    from relight_addon.core.radiosity.memory import BASE_BYTES, estimate_precompute_memory
    from relight_addon.core.radiosity.precompute import solve_radiosity
    from scenes.testscenes import cornell_box
    scene = cornell_box(subdivide=n)
    estimate = estimate_precompute_memory(scene, preset, proxy=False) / 2**20
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    t0 = time.perf_counter()
    try:
        sol = solve_radiosity(scene, preset)
    except MemoryError:
        print(json.dumps({"status": "oom", "seconds": time.perf_counter() - t0}))
        return
    total = time.perf_counter() - t0
    st = {k: (float(v) if isinstance(v, (float, np.floating)) else int(v)) for k, v in sol.stats().items()}
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    st.update(status="ok", seconds=total, rss_before_mb=rss0, peak_rss_mb=peak,
              estimate_mb=estimate, estimated_of_mb=peak - rss0 + BASE_BYTES / 2**20)
    print(json.dumps(st))


def run_case(n, preset, timeout, mem_gb):
    cmd = [sys.executable, __file__, "--child", str(n), preset, "--mem-gb", str(mem_gb)]
    t0 = time.perf_counter()
    try:
        out = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"status": "timeout", "seconds": time.perf_counter() - t0}
    lines = out.stdout.strip().splitlines()
    if out.returncode != 0 or not lines:
        err = out.stderr.strip().splitlines()
        status = "oom" if "MemoryError" in out.stderr or out.returncode in (-9, 137) else "error"
        return {"status": status, "seconds": time.perf_counter() - t0,
                "error": err[-1] if err else f"rc={out.returncode}"}
    return json.loads(lines[-1])


def core_fingerprint():
    """Short hash of the core sources (they may change while the benchmark runs)."""
    import hashlib
    h = hashlib.sha1()
    for f in sorted((ROOT / "relight_addon" / "core").rglob("*.py")):
        h.update(f.read_bytes())
    return h.hexdigest()[:10]


def fit_exponent(x, y):
    x, y = np.asarray(x, float), np.asarray(y, float)
    if len(x) < 2:
        return float("nan")
    return float(np.polyfit(np.log(x), np.log(y), 1)[0])


def fmt(v, d=2):
    return "—" if v is None else (f"{v:.{d}f}" if isinstance(v, float) else str(v))


def write_md(rows, args, load_before, load_after, path):
    lines = ["# solve_radiosity scaling with the number of input patches", "",
             f"Scene `cornell_box(subdivide=n)` (17 n² patches), presets {', '.join(args.presets)}. "
             f"One subprocess per case; peak RSS = `ru_maxrss` of that process (includes the "
             f"~{fmt(np.median([r['rss_before_mb'] for r in rows if r['status'] == 'ok']), 0)} MB "
             f"of Python + numpy + scipy + scene). Timeout {args.timeout:.0f} s per case, memory cap "
             f"{args.mem_gb:g} GB (RLIMIT_AS).", "",
             f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
             f"Python {platform.python_version()}, numpy {np.__version__}. "
             f"Load average (1, 5, 15 min) before: {', '.join(f'{x:.2f}' for x in load_before)}; "
             f"after: {', '.join(f'{x:.2f}' for x in load_after)} (other processes were running, "
             "so absolute times are noisy). Core sources sha1 (relight_addon/core/**/*.py): "
             f"`{args.core}`.", "",
             "Times in seconds; form_factors and visibility are parts of refine + final_links. "
             "*estimate*: the memory estimate the Precompute button checks (core/radiosity/"
             "memory.py), and its ratio to what it estimates: the peak less the RSS before the "
             "solve, plus its 60 MB for Python and numpy.", "",
             "| preset | n | patches | elements | leaves | links | setup | refine | form_factors | "
             "visibility | final_links | solve | iters | total s | peak RSS MB | estimate MB | "
             "estimate / measured |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        if r["status"] != "ok":
            lines.append(f"| {r['preset']} | {r['n']} | {r['patches_in']} | | | | | | | | | | | "
                         f"{r['status']} ({r['seconds']:.0f} s) | | | |")
            continue
        lines.append(
            f"| {r['preset']} | {r['n']} | {r['patches']} | {r['elements']} | {r['leaves']} | "
            f"{r['links']} | " + " | ".join(fmt(r.get('t_' + p, 0.0), 3 if r.get('t_' + p, 0) < 1 else 1)
                                              for p in PHASES)
            + f" | {r['iterations']} | {fmt(r['seconds'], 2)} | {fmt(r['peak_rss_mb'], 0)} | "
            f"{fmt(r['estimate_mb'], 0)} | {fmt(r['estimate_mb'] / r['estimated_of_mb'], 2)} |")
    lines += ["", "## Fitted exponents (log-log least squares over the completed cases, "
              "patches >= 400)", "",
              "| preset | time ~ P^a | links ~ P^a | leaves ~ P^a | (peak RSS - baseline) ~ P^a |",
              "|---|---:|---:|---:|---:|"]
    for preset in args.presets:
        ok = [r for r in rows if r["preset"] == preset and r["status"] == "ok" and r["patches"] >= 400]
        P = [r["patches"] for r in ok]
        lines.append(f"| {preset} | {fit_exponent(P, [r['seconds'] for r in ok]):.2f} | "
                     f"{fit_exponent(P, [r['links'] for r in ok]):.2f} | "
                     f"{fit_exponent(P, [r['leaves'] for r in ok]):.2f} | "
                     f"{fit_exponent(P, [max(r['peak_rss_mb'] - r['rss_before_mb'], 1.0) for r in ok]):.2f} |")
    lines += ["", "## Findings", "", args.findings or "(see the report)", ""]
    path.write_text("\n".join(lines))


def plot(rows, presets, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4.2))
    for preset, mk in zip(presets, "os^v"):
        ok = [r for r in rows if r["preset"] == preset and r["status"] == "ok"]
        if not ok:
            continue
        P = np.array([r["patches"] for r in ok])
        a1.loglog(P, [r["seconds"] for r in ok], mk + "-", label=f"{preset} total")
        a1.loglog(P, [r["t_final_links"] for r in ok], mk + ":", alpha=0.6, label=f"{preset} final_links")
        a1.loglog(P, [r["t_refine"] for r in ok], mk + "--", alpha=0.6, label=f"{preset} refine")
        a2.loglog(P, [r["peak_rss_mb"] for r in ok], mk + "-", label=f"{preset} peak RSS")
        bad = [r for r in rows if r["preset"] == preset and r["status"] != "ok"]
        for r in bad:
            a1.axvline(r["patches_in"], color="grey", ls=":", lw=0.8)
            a1.text(r["patches_in"], a1.get_ylim()[1], f" {preset} {r['status']}", rotation=90,
                    va="top", fontsize=7)
    P = np.array([100, 10_000])
    a1.loglog(P, 1e-5 * P**2, "k:", lw=0.8, label="∝ P²")
    a1.set(xlabel="input patches", ylabel="seconds", title="solve_radiosity time")
    a2.set(xlabel="input patches", ylabel="MB", title="peak RSS (whole process)")
    for a in (a1, a2):
        a.grid(True, which="both", alpha=0.3)
        a.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--child", nargs=2, metavar=("N", "PRESET"))
    ap.add_argument("--n", type=int, nargs="+", default=[3, 5, 8, 12, 18, 25])
    ap.add_argument("--presets", nargs="+", default=["draft", "medium"])
    ap.add_argument("--timeout", type=float, default=300.0)
    ap.add_argument("--mem-gb", type=float, default=10.0)
    ap.add_argument("--findings", default="", help="paragraph of findings for the markdown")
    ap.add_argument("--from-json", help="re-render md/png from a saved raw json")
    args = ap.parse_args()
    if args.child:
        child(int(args.child[0]), args.child[1], args.mem_gb)
        return
    RESULTS.mkdir(parents=True, exist_ok=True)
    raw = RESULTS / "scaling_raw.json"
    if args.from_json:
        saved = json.loads(Path(args.from_json).read_text())
        rows, load_before, load_after = saved["rows"], saved["load_before"], saved["load_after"]
        fp = saved.get("core", "?")
    else:
        load_before = os.getloadavg()
        fp_before = core_fingerprint()
        rows = []
        for preset in args.presets:
            stop = False
            for n in args.n:
                if stop:
                    rows.append({"preset": preset, "n": n, "patches_in": 17 * n * n,
                                 "status": "skipped", "seconds": 0.0})
                    continue
                r = run_case(n, preset, args.timeout, args.mem_gb)
                r.update(preset=preset, n=n, patches_in=17 * n * n, load=os.getloadavg()[0])
                rows.append(r)
                print(f"{preset:7s} n={n:3d} P={17 * n * n:6d} {r['status']:8s} "
                      f"{r['seconds']:8.2f} s  links={r.get('links', '-')} leaves={r.get('leaves', '-')} "
                      f"rss={r.get('peak_rss_mb', 0):.0f} MB  load={r['load']:.2f}", flush=True)
                stop = r["status"] != "ok"
        load_after = os.getloadavg()
        fp = core_fingerprint()
        if fp != fp_before:
            fp = f"{fp_before} -> {fp} (CHANGED during the run: cases are not comparable)"
        raw.write_text(json.dumps({"rows": rows, "load_before": load_before,
                                   "load_after": load_after, "core": fp}, indent=1))
    args.core = fp
    write_md(rows, args, load_before, load_after, RESULTS / "scaling.md")
    plot(rows, args.presets, RESULTS / "scaling.png")


if __name__ == "__main__":
    main()
