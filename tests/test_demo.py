"""The README's demo command, run as a user runs it: `python -m demo.cornell` and
`python -m demo.office` in fresh processes.  The office demo chains Precompute, keyframed lamps,
EEVEE and Cycles renders, then an Update that adds a virtual lamp and a virtual box: a path no
other test walks in one process (it once failed on bpy 5.2 after the Update, on a material the
Update had replaced)."""
import json
import os
import subprocess
import sys

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _run(module, *args, timeout=600):
    done = subprocess.run([sys.executable, "-m", module, *args], cwd=ROOT, timeout=timeout,
                          capture_output=True, text=True)
    assert done.returncode == 0, f"{module} failed:\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}"
    return done.stdout


def test_the_cornell_demo_draws_the_box(tmp_path):
    _run("demo.cornell", "--preset", "draft", "--out", str(tmp_path))
    assert os.path.getsize(tmp_path / "cornell.png") > 1000


@pytest.mark.slow
def test_the_office_demo_runs_to_its_end_and_matches_cycles(tmp_path):
    """Small settings (16^2 texels, 96 x 72 pixels, few samples): the demo's every step runs,
    its files are written, and each relit EEVEE frame is within the noise of the small bake
    against its Cycles truth (frame 1, the photo's own lighting, is that floor: a coarse
    texture against a per-pixel render); the virtual lamp and box frame may not be far off it."""
    pytest.importorskip("bpy")
    summary = tmp_path / "demo.json"
    _run("demo.office", "--out", str(tmp_path), "--texture-size", "16", "--bake-samples", "32",
         "--res", "96x72", "--eevee-samples", "1", "--cycles-samples", "8", "--no-denoise",
         "--json", str(summary))
    got = json.loads(summary.read_text())
    for name in ("frame_0001.png", "frame_0003.png", "frame_0004.png", "truth_0004.png",
                 "demo_side_by_side.png", "demo.blend"):
        assert os.path.getsize(tmp_path / name) > 1000, name
    rel = {int(f): d["linear_rel"] for f, d in got["diffs"].items()}
    assert all(np.isfinite(v) for v in rel.values())
    assert rel[1] < 0.25
    assert rel[3] < 1.5 * rel[1] + 0.02        # a lamp off and one doubled: shadows removed
    assert rel[4] < 1.5 * rel[1] + 0.05        # with the virtual lamp and box
    assert got["times"]["update: virtual lamp and box"] < 30
