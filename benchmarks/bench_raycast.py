"""Ray-casting throughput: raw embreex, EmbreeOccluder with 1 and 2 threads, BVHTree fallback.

Scene: ~10k small random triangles in the unit cube (about half of the random segments are
blocked).  Segments join random points of the cube.  Writes benchmarks/results/raycast.md.

    python benchmarks/bench_raycast.py [--rays 1000000] [--bvh-rays 100000]
"""
from __future__ import annotations

import argparse
import os
import platform
import resource
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from relight_addon.core.geometry import raycast as rc  # noqa: E402


def _cpu():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def best_of(fn, repeats=5):
    """(best wall time, process CPU time / wall time of that run, result)."""
    best, ratio, out = np.inf, 0.0, None
    for _ in range(repeats):
        c0, t0 = _cpu(), time.perf_counter()
        out = fn()
        w = time.perf_counter() - t0
        if w < best:
            best, ratio = w, (_cpu() - c0) / w
    return best, ratio, out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--triangles", type=int, default=10_000)
    ap.add_argument("--rays", type=int, default=1_000_000)
    ap.add_argument("--bvh-rays", type=int, default=100_000)
    ap.add_argument("--numpy-rays", type=int, default=2_000)
    args = ap.parse_args()

    rng = np.random.default_rng(0)
    nt, n = args.triangles, args.rays
    tris = rng.random((nt, 1, 3)) + 0.01 * rng.standard_normal((nt, 3, 3))
    o = rng.random((n, 3))
    e = rng.random((n, 3))
    rows = []  # (method, rays, seconds, cpu/wall, note)
    load0 = os.getloadavg()[0]

    if "embree" in rc.available_backends():
        t0 = time.perf_counter()
        occ1 = rc.EmbreeOccluder(tris, threads=1)
        build = time.perf_counter() - t0
        occ2 = rc.EmbreeOccluder(tris, threads=2)
        scene = occ1._scene  # raw embreex calls, inputs prepared outside the timing
        org = np.ascontiguousarray(o - occ1._centre, np.float32)
        dr = np.ascontiguousarray(e - o, np.float32)

        def raw1():
            return scene.run(org, dr, dists=np.ones(n, np.float32), query="OCCLUDED")

        def raw2():
            h = n // 2
            with ThreadPoolExecutor(2) as ex:
                fs = [ex.submit(scene.run, org[a:b], dr[a:b], np.ones(b - a, np.float32),
                                "OCCLUDED") for a, b in ((0, h), (h, n))]
                return np.concatenate([f.result() for f in fs])

        t, cw, r = best_of(raw1)
        frac = (r >= 0).mean()
        rows.append(("embreex `scene.run` OCCLUDED, 1 thread (raw)", n, t, cw, f"{frac:.1%} blocked"))
        t, cw, r2 = best_of(raw2)
        assert np.array_equal(r, r2)
        rows.append(("embreex `scene.run` OCCLUDED, 2 threads (raw)", n, t, cw, "same answers"))
        t, cw, a1 = best_of(lambda: occ1.segments_occluded(o, e))
        rows.append(("`EmbreeOccluder.segments_occluded`, threads=1", n, t, cw,
                     "incl. float64->float32 prep"))
        t, cw, a2 = best_of(lambda: occ2.segments_occluded(o, e))
        assert np.array_equal(a1, a2)
        rows.append(("`EmbreeOccluder.segments_occluded`, threads=2", n, t, cw, "same answers"))
        d = e - o
        t, cw, _ = best_of(lambda: occ1.first_hit_distance(o, d))
        rows.append(("`EmbreeOccluder.first_hit_distance`, threads=1", n, t, cw, "closest hit"))
        t, cw, _ = best_of(lambda: occ2.first_hit_distance(o, d))
        rows.append(("`EmbreeOccluder.first_hit_distance`, threads=2", n, t, cw, "closest hit"))
        rows.append(("Embree scene build", nt, build, float("nan"), "triangles, not rays"))
    else:
        a1 = None
        print("embreex not available", file=sys.stderr)

    try:
        import bpy  # noqa: F401  (makes mathutils importable outside Blender)
        have_bvh = "bvhtree" in rc.available_backends()
    except ImportError:
        have_bvh = False
    if have_bvh:
        m = args.bvh_rays
        t0 = time.perf_counter()
        bvh = rc.BVHTreeOccluder(tris)
        build = time.perf_counter() - t0
        t, cw, b = best_of(lambda: bvh.segments_occluded(o[:m], e[:m]), repeats=2)
        note = "" if a1 is None else f"agrees with Embree on {(b == a1[:m]).mean():.4%}"
        rows.append(("`BVHTreeOccluder.segments_occluded` (mathutils)", m, t, cw, note))
        rows.append(("BVHTree build", nt, build, float("nan"), "triangles, not rays"))

    k = args.numpy_rays
    npo = rc.NumpyOccluder(tris)
    t, cw, c = best_of(lambda: npo.segments_occluded(o[:k], e[:k]), repeats=1)
    note = "" if a1 is None else f"agrees with Embree on {(c == a1[:k]).mean():.2%}"
    rows.append(("`NumpyOccluder.segments_occluded` (brute force)", k, t, cw, note))

    lines = [
        "# Ray-casting throughput",
        "",
        f"Scene: {nt} random triangles (edge sigma 0.01) in the unit cube; segments between "
        "random points of the cube. Best of 5 (BVHTree best of 2, numpy 1 run). cpu/wall is the "
        "process CPU time over wall time of the best run (2 = both cores busy).",
        "",
        f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} logical CPUs, "
        f"Python {platform.python_version()}, numpy {np.__version__}; 1-min load average "
        f"{load0:.2f} before / {os.getloadavg()[0]:.2f} after (other work shares the CPUs).",
        "",
        "| method | rays | time (s) | M rays/s | cpu/wall | note |",
        "|---|---:|---:|---:|---:|---|",
    ]
    for name, cnt, t, cw, note in rows:
        rate = "" if "build" in name else f"{cnt / t / 1e6:.3g}"
        cws = "" if np.isnan(cw) else f"{cw:.2f}"
        lines.append(f"| {name} | {cnt:,} | {t:.3f} | {rate} | {cws} | {note} |")
    text = "\n".join(lines) + "\n"
    out = ROOT / "benchmarks" / "results" / "raycast.md"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
