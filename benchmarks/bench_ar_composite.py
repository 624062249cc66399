"""AR mode's composite (issue 45) on the scenes of tests/ar_composite_scenes.py: the scene's own
render after ``bpy.ops.relight.ar_setup()`` against Cycles with the object really there (the
truth), beside the object pasted without a shadow and Cycles' shadow catcher composite (what
a user would otherwise make).  Writes benchmarks/results/ar_composite.md and
ar_composite_raw.json.

    python benchmarks/bench_ar_composite.py [--res 120 90] [--samples 128] [--cases ...]
    python benchmarks/bench_ar_composite.py --res 400 300 --samples 256 --ours 32 --eevee 0 \
        --cases ground/sphere/sunrise --name ar_composite_400

Each render runs in a fresh bpy process (tests/ar_composite_job.py) and is cached on disk
(tests/ar_composite.py: ``$RELIGHT_BAKE_CACHE`` or ``.cache/bakes``).  Scores: mean CIEDE2000
over the image, inside the object's shadow, on the object.  Times: each render's process CPU
seconds and wall seconds as measured when it was rendered (the machine is shared: the wall
times carry the load of that moment).  One run.
"""
from __future__ import annotations

import argparse
import json
import platform
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

import ar_composite as C  # noqa: E402
import ar_truth as T  # noqa: E402

CASES = ("ground/sphere/sunrise", "ground/sphere/courtyard", "table/sphere/sunrise",
         "corner/sphere/interior")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--res", type=int, nargs=2, default=(120, 90))
    ap.add_argument("--samples", type=int, default=128, help="photo, truth, shadow catcher")
    ap.add_argument("--ours", type=int, default=16, help="our Cycles render's samples")
    ap.add_argument("--eevee", type=int, default=8, help="our EEVEE render's samples (0: none)")
    ap.add_argument("--cases", nargs="*", default=list(CASES))
    ap.add_argument("--name", default="ar_composite",
                    help="results file stem (another resolution: another file)")
    a = ap.parse_args()
    hdris = T.bundled_hdris()
    res, n = tuple(a.res), a.samples
    rows = []
    for case in a.cases:
        scene, obj, hdri = case.split("/")
        path = hdris[hdri]
        photo = C.photo(scene, obj, path, res, n)
        truth = C.reference("truth", scene, obj, path, res, n, n)
        catcher = C.reference("catcher", scene, obj, path, res, n, n)
        row = {"case": case}

        def score(image):
            return C.scores(photo["image"], image, truth["image"], photo["mask"])
        row["pasted"] = score(C.pasted(photo["image"], truth["image"], photo["mask"]))
        row["catcher"] = dict(score(catcher["image"]), cpu=float(catcher["cpu"]),
                              wall=float(catcher["seconds"]))
        engines = [("CYCLES", a.ours)] + ([("BLENDER_EEVEE", a.eevee)] if a.eevee else [])
        for engine, samples in engines:
            o = C.ours(scene, obj, path, res, engine=engine, samples=samples, photo_samples=n)
            row[engine] = dict(score(o["image"]), cpu=float(o["cpu"]), wall=float(o["seconds"]),
                               setup=float(o["setup_seconds"]), samples=samples)
        rows.append(row)
        print(json.dumps(row), flush=True)
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / f"{a.name}_raw.json").write_text(json.dumps(
        {"res": res, "samples": n, "python": platform.python_version(), "rows": rows},
        indent=1))
    lines = [f"# AR composite vs Cycles truth ({res[0]} x {res[1]}, truth / photo / catcher at "
             f"{n} samples)", "",
             "Mean CIEDE2000 against Cycles with the object really there: image / shadow / "
             "object. Times: render CPU s (wall s); Set Up wall s. Written by "
             "benchmarks/bench_ar_composite.py, one run.", "",
             "| case | pasted | catcher | catcher time | ours Cycles | time | Set Up | "
             "ours EEVEE | time |", "|---|---|---|---|---|---|---|---|---|"]

    def f(s):
        return f"{s['image']:.2f} / {s['shadow']:.2f} / {s['object']:.2f}"
    for r in rows:
        cy, ev = r["CYCLES"], r.get("BLENDER_EEVEE")
        lines.append(
            f"| {r['case']} | {f(r['pasted'])} | {f(r['catcher'])} | "
            f"{r['catcher']['cpu']:.1f} ({r['catcher']['wall']:.1f}) | {f(cy)} | "
            f"{cy['cpu']:.1f} ({cy['wall']:.1f}) | {cy['setup']:.1f} | "
            + (f"{f(ev)} | {ev['cpu']:.1f} ({ev['wall']:.1f}) |" if ev else "- | - |"))
    lines += ["", "Notes:", "",
              "- pasted: the truth's pixels on the object over the photo, no shadow (what the "
              "shadow is worth); catcher: Cycles' shadow catcher composite (the receivers as "
              "shadow catchers, the HDRI as World) at the truth's samples.",
              "- Shadow: the truth darker than the photo by 10 % outside the object; object: "
              "its coverage > 1/2. A region of few pixels (the table's) is dominated by its "
              "penumbra's edge pixels at this size.",
              "- EEVEE lights the object by the World alone (its world probe): Set Up gives "
              "it a World output that shows the photo below the horizon, projected onto the "
              "receivers' ground (ar_write.write_world; the scene setting EEVEE Sees the Photo "
              "Below, on by default), where the map alone showed its own ground. What is left "
              "on the object: the map's ground beyond the receiver, the object's own occlusion "
              "of the World's light. Its World shader costs EEVEE's render on llvmpipe (no GPU "
              "here) about 10-18 s of CPU more than a World of the map alone (200 x 150, the "
              "torus: 15.7 s against 4.4 s).",
              "- Times: the render's process CPU seconds (all its threads), the wall seconds "
              "beside them carry the shared machine's load of that moment; Set Up once per "
              "scene (environment, receiver view, sphere fits)."]
    (RESULTS / f"{a.name}.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
