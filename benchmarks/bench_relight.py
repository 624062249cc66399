"""Cost of the relight update B = sum_k I_k B_k (k = 4 lamps) at 10k, 50k and 200k leaves.

The update does not depend on the scene, so synthetic bases of shape (k, L, 3) are used, in
float64 and float32.  Ways compared: np.tensordot (what RadiositySolution.radiosity does),
np.einsum, np.dot on a (k, L*3) view, a preallocated ``out`` filled by np.multiply(..., out=)
then ``+=`` per lamp, and the same in float32.  Each timing is the median over many timeit
repeats, in ms.  Also times RadiositySolution.radiosity() on a real solution (cornell_box,
preset "high").  Writes benchmarks/results/relight_update.md.

    python benchmarks/bench_relight.py [--leaves 10000 50000 200000] [--repeat 300]
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import timeit
from pathlib import Path

# A child measures with a fixed BLAS thread count (must be set before numpy is imported).
if "--blas-threads" in sys.argv:
    _nt = sys.argv[sys.argv.index("--blas-threads") + 1]
    if _nt != "default":
        for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
            os.environ[_v] = _nt

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
RESULTS = ROOT / "benchmarks" / "results"
K = 4


def median_ms(fn, repeat):
    fn()                                                    # warm up (page in the output)
    t = timeit.Timer(fn)
    number = max(1, int(0.002 / max(t.timeit(1), 1e-7)))   # ~2 ms per measurement
    return 1e3 * float(np.median(t.repeat(repeat=repeat, number=number))) / number


def ways(basis, I):
    """name -> zero-argument callable computing sum_k I_k basis[k] (same dtype as basis)."""
    k, L, c = basis.shape
    flat = basis.reshape(k, L * c)
    If = I.astype(basis.dtype)
    out = np.empty((L, c), basis.dtype)
    out_flat = out.reshape(-1)
    tmp = np.empty((L, c), basis.dtype)

    def accumulate():
        np.multiply(basis[0], If[0], out=out)
        for j in range(1, k):
            np.multiply(basis[j], If[j], out=tmp)
            np.add(out, tmp, out=out)
        return out

    def dot_out():
        return np.dot(If, flat, out=out_flat)

    return {
        "tensordot(I, basis, axes=1)": lambda: np.tensordot(I, basis, axes=1),
        "einsum('k,klc->lc')": lambda: np.einsum("k,klc->lc", If, basis),
        "I @ basis.reshape(k, -1)": lambda: (If @ flat).reshape(L, c),
        "np.dot(I, flat, out=prealloc)": dot_out,
        "prealloc multiply(out=) + add(out=)": accumulate,
    }


def check(basis, I, fns):
    ref = np.tensordot(I.astype(np.float64), basis.astype(np.float64), axes=1)
    tol = 1e-12 if basis.dtype == np.float64 else 1e-5
    for name, fn in fns.items():
        got = np.asarray(fn(), np.float64).reshape(ref.shape)
        err = np.max(np.abs(got - ref)) / np.max(np.abs(ref))
        assert err < tol, (name, basis.dtype, err)


def measure(args):
    """Run every way at every size; return a JSON-able dict."""
    rng = np.random.default_rng(0)
    I = np.array([1.0, 0.5, 2.0, 0.25])
    load_before = os.getloadavg()
    table = {}                                 # "name|dtype" -> {L: ms}
    for L in args.leaves:
        b64 = rng.random((K, L, 3))
        for dtype in (np.float64, np.float32):
            basis = b64.astype(dtype)
            fns = ways(basis, I)
            check(basis, I, fns)
            for name, fn in fns.items():
                ms = median_ms(fn, args.repeat)
                table.setdefault(f"{name}|{np.dtype(dtype).name}", {})[str(L)] = ms
                print(f"[blas {args.blas_threads}] L={L:7d} {np.dtype(dtype).name:8s} {name:36s} "
                      f"{ms:8.4f} ms", file=sys.stderr, flush=True)
    from relight_addon.core.radiosity.precompute import solve_radiosity
    from scenes.testscenes import cornell_box
    sol = solve_radiosity(cornell_box(subdivide=1), args.real_preset)
    real = {"k": len(sol.basis), "L": len(sol.leaves),
            "radiosity([1.0])": median_ms(lambda: sol.radiosity([1.0]), args.repeat),
            "radiosity()": median_ms(lambda: sol.radiosity(), args.repeat),
            "patch_radiosity([1.0])": median_ms(lambda: sol.patch_radiosity([1.0]),
                                                max(20, args.repeat // 5))}
    return {"table": table, "real": real, "I": I.tolist(), "load_before": load_before,
            "load_after": os.getloadavg()}


def section(res, Ls, title):
    table = {tuple(k.split("|")): {int(L): v for L, v in row.items()} for k, row in res["table"].items()}
    mid = Ls[len(Ls) // 2]
    ref = table[("tensordot(I, basis, axes=1)", "float64")]
    lines = [f"## {title}", "",
             f"Load average (1, 5, 15 min) before: {', '.join(f'{x:.2f}' for x in res['load_before'])}; "
             f"after: {', '.join(f'{x:.2f}' for x in res['load_after'])}.", "",
             "| way | dtype | " + " | ".join(f"L = {L // 1000}k" for L in Ls)
             + f" | speed-up vs tensordot f64 at {mid // 1000}k |",
             "|---|---|" + "---:|" * (len(Ls) + 1)]
    for (name, dt), row in table.items():
        lines.append(f"| `{name}` | {dt} | " + " | ".join(f"{row[L]:.4f}" for L in Ls)
                     + f" | {ref[mid] / row[mid]:.2f}× |")
    r = res["real"]
    lines += ["", f"Real solution `cornell_box(subdivide=1)` preset 'high' (k = {r['k']} lamp, "
              f"L = {r['L']} leaves): `sol.radiosity([1.0])` {r['radiosity([1.0])']:.4f} ms, "
              f"`sol.radiosity()` {r['radiosity()']:.4f} ms, `sol.patch_radiosity([1.0])` "
              f"{r['patch_radiosity([1.0])']:.4f} ms.", ""]
    return lines


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--leaves", type=int, nargs="+", default=[10_000, 50_000, 200_000])
    ap.add_argument("--repeat", type=int, default=300)
    ap.add_argument("--real-preset", default="high")
    ap.add_argument("--blas-threads", default=None, help="(child) BLAS threads: 'default' or N")
    ap.add_argument("--findings", default="", help="paragraph of findings for the markdown")
    args = ap.parse_args()
    if args.blas_threads is not None:
        print(json.dumps(measure(args)))
        return
    results = {}
    for nt in ("default", "1"):
        cmd = [sys.executable, __file__, "--blas-threads", nt, "--repeat", str(args.repeat),
               "--real-preset", args.real_preset, "--leaves", *map(str, args.leaves)]
        out = subprocess.run(cmd, stdout=subprocess.PIPE, text=True, check=True)
        results[nt] = json.loads(out.stdout.strip().splitlines()[-1])
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "relight_update_raw.json").write_text(json.dumps(results, indent=1))
    I = results["default"]["I"]
    lines = ["# Relight update B = Σ_k I_k B_k (k = 4 lamps)", "",
             f"Synthetic bases (4, L, 3), I = {I}. Median of {args.repeat} timeit repeats (each "
             "repeat loops the call for ~2 ms), in **ms per update**; the output is freshly "
             "allocated except in the `prealloc`/`out=` rows. All ways agree with the float64 "
             "tensordot to 1e-12 (float64) / 1e-5 relative (float32). `I` is float64 as in "
             "`RadiositySolution.radiosity`; the einsum / dot / prealloc rows cast it to the basis "
             "dtype first.", "",
             f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
             f"numpy {np.__version__}, Python {platform.python_version()}. Other processes "
             "(including the scaling benchmark) were running: see the load averages.", ""]
    lines += section(results["default"], args.leaves, "BLAS threads: default")
    lines += section(results["1"], args.leaves, "BLAS threads: 1 (OPENBLAS_NUM_THREADS=1)")
    lines += ["## Findings", "", args.findings or "(see the report)", ""]
    (RESULTS / "relight_update.md").write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
