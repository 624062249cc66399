"""The memory estimate that makes relight.precompute refuse a scene before solving
(core/radiosity/memory.py), against the peak memory of real solves in fresh processes.

The operator's refusal itself is tested in test_unwrap.py (it needs Blender)."""
import json
import os
import subprocess
import sys

import numpy as np
import pytest

from relight_addon.core.radiosity.memory import BASE_BYTES, estimate_precompute_memory
from scenes.testscenes import cornell_box

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# One solve in a fresh process: what it adds to the process's peak, as the estimate counts it
# (over BASE_BYTES for Python and numpy).  The peak is the memory's high-water mark (VmHWM):
# ru_maxrss would start at the parent's (pytest's) size, which Linux carries over exec.
MEASURE = """
import json, sys

def high_water_kb():
    with open("/proc/self/status") as status:
        return next(int(line.split()[1]) for line in status if line.startswith("VmHWM:"))

sys.path[:0] = [{root!r}, {tests!r}]
from relight_addon.core.radiosity.memory import BASE_BYTES, estimate_precompute_memory
from relight_addon.core.radiosity.precompute import solve_radiosity
from scenes.testscenes import cornell_box
scene = cornell_box(subdivide={n})
before = high_water_kb()
solve_radiosity(scene, {preset!r}, seed=0)
peak = high_water_kb()
print(json.dumps({{"measured": (peak - before) * 1024 + BASE_BYTES,
                  "estimate": estimate_precompute_memory(scene, {preset!r}, proxy=False)}}))
"""


@pytest.mark.slow
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc/self/status")
@pytest.mark.parametrize("preset,n", [("draft", 18), ("medium", 8)])
def test_estimate_bounds_a_measured_solve_closely(preset, n):
    """From above, and within 1.75x: 5,508 patches at draft (measured ~650 MB, estimated
    1.15x) and 1,088 at medium (390-430 MB, 1.15-1.3x).  The model was fitted 15 % above 40
    solves (memory.py's docstring); this one is measured again here, in a fresh process."""
    code = MEASURE.format(root=ROOT, tests=os.path.join(ROOT, "tests"), n=n, preset=preset)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=300, cwd=ROOT)
    assert out.returncode == 0, out.stderr[-2000:]
    rec = json.loads(out.stdout.strip().splitlines()[-1])
    ratio = rec["estimate"] / rec["measured"]
    assert 1.0 <= ratio <= 1.75, (preset, n, rec, ratio)


MEASURE_SCAN = """
import json, sys

def high_water_kb():
    with open("/proc/self/status") as status:
        return next(int(line.split()[1]) for line in status if line.startswith("VmHWM:"))

sys.path[:0] = [{root!r}]
from relight_addon.core.radiosity.memory import BASE_BYTES, estimate_precompute_memory
from relight_addon.core.relight.shadowfree import ShadowFreeOptions, shadow_free
from scenes import family_eval as fe
room = fe.photographed_room(20, "exact", scan=dict(triangles=20_000, noise=0.002, seed=0))
before = high_water_kb()
res = shadow_free(room.data, ShadowFreeOptions(preset="medium"))
peak = high_water_kb()
print(json.dumps({{"measured": (peak - before) * 1024 + BASE_BYTES,
                  "estimate": estimate_precompute_memory(room.data, "medium"),
                  "proxy_faces": res.stats["proxy_faces"]}}))
"""


@pytest.mark.slow
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc/self/status")
def test_estimate_of_a_scan_solved_on_a_proxy_is_within_a_quarter():
    """Issue 10's target: a scanned room's precompute (20k triangles solved on a proxy of
    3,000) within 25 % of its estimate, in a fresh process.  Measured 574 and 666 MB in two
    runs of the same case (the peak varies by +-14 % from run to run), estimated 635 MB; the
    estimate before it counted its phases as one after another was 1.4-1.6x (940 MB)."""
    code = MEASURE_SCAN.format(root=ROOT)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=600, cwd=ROOT)
    assert out.returncode == 0, out.stderr[-2000:]
    rec = json.loads(out.stdout.strip().splitlines()[-1])
    assert rec["proxy_faces"] > 0
    ratio = rec["estimate"] / rec["measured"]
    assert 0.75 <= ratio <= 1.25, (rec, ratio)


def test_memory_estimate_grows_with_preset_and_patches():
    small = cornell_box(subdivide=1)
    est = [estimate_precompute_memory(small, p) for p in ("draft", "medium", "high", "ultra")]
    assert all(x < y for x, y in zip(est, est[1:])), est
    sizes = [estimate_precompute_memory(cornell_box(subdivide=n), "draft", proxy=False)
             for n in (3, 8, 25)]
    assert all(x < y for x, y in zip(sizes, sizes[1:])), sizes
    # A preset made from another (Quality.with_) is counted as the nearest named one
    from relight_addon.core.radiosity.presets import PRESETS
    finer = PRESETS["medium"].with_(name="custom", min_area=2.5e-4)
    assert estimate_precompute_memory(small, finer) == pytest.approx(est[1], rel=0.2)
    # Solved on a proxy (a mesh of more faces than the preset's proxy needs), the estimate
    # follows the proxy and the faces' own cost: 200k faces fit in a few GB where the solve on
    # the faces themselves was estimated at 70 GB (issue 10).
    scan = np.full(200_000, 100.0 / 200_000)
    with_proxy = estimate_precompute_memory(scan, "medium") / 2**30
    without = estimate_precompute_memory(scan, "medium", proxy=False) / 2**30
    assert with_proxy < 2.0 < 8.0 < without, (with_proxy, without)
    # Its phases follow one another: the proxy's solve is the peak up to a few million faces
    # (the same for 100k), then the mesh's own phase (turning and decimating the faces).
    half = estimate_precompute_memory(scan[:100_000] * 2, "medium") / 2**30
    assert half <= with_proxy < half + 0.1
    huge = estimate_precompute_memory(np.full(5_000_000, 100.0 / 5_000_000), "medium") / 2**30
    assert huge > with_proxy + 1.0
    assert estimate_precompute_memory(np.zeros(3), "draft") >= BASE_BYTES


def test_memory_estimate_counts_texels():
    """The texel term follows the measured shadow-free peaks (office, 2 lamps, draft:
    benchmarks/results/texel_scaling.md) from above: 693 MB at 1.17 M texels, where every
    texel's direct light is kept, and within 25 % of 857 MB at 4.7 M and 1859 MB at 16.5 M
    texels, cast and written block by block; and grows with the texture size."""
    from scenes.office import office_geometry, office_scene_data
    data = office_geometry(0, 2, 48)

    def estimate(up):
        tex = None if up == 1 else {s.name: np.kron(s.albedo, np.ones((up, up, 1), np.float32))
                                    for s in data.surfaces}
        return estimate_precompute_memory(office_scene_data(data, tex), "draft") / 2**20
    e = {up: estimate(up) for up in (1, 8, 16, 30)}
    assert e[1] < e[8] and e[16] < e[30]
    assert 693 <= e[8] < 2 * 693, e
    assert 857 <= e[16] < 1.25 * 857, e
    assert 1859 <= e[30] < 1.25 * 1859, e


GROW = """
import json, sys
sys.path[:0] = [{root!r}]
import numpy as np
from relight_addon.core.radiosity.memory import growable, resized

def high_water_kb():
    with open("/proc/self/status") as status:
        return next(int(line.split()[1]) for line in status if line.startswith("VmHWM:"))

a = {make}(25_000_000, np.float64)          # 200 MB
a[:] = 1.0
before = high_water_kb()
a = resized(a, 30_000_000)
a[25_000_000:] = 2.0
print(json.dumps({{"added_mb": (high_water_kb() - before) / 1024, "ok": bool(a[0] == 1.0)}}))
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc; glibc's mremap")
def test_a_growable_buffer_grows_without_being_held_twice():
    """The form factors' entries (400 MB a field on RenderPark's office at medium) grow by the
    rays' entries and the source split's children: a buffer numpy advised for huge pages was
    copied by realloc (held twice at the peak), one made by ``growable`` is remapped."""
    def added(make):
        out = subprocess.run([sys.executable, "-c", GROW.format(root=ROOT, make=make)],
                             capture_output=True, text=True, check=True)
        return json.loads(out.stdout.strip().splitlines()[-1])
    grown = added("growable")
    assert grown["ok"] and grown["added_mb"] < 60, grown        # the 40 MB tail only
    plain = added("np.empty")
    print("grown by 40 MB: growable +%.0f MB, np.empty +%.0f MB" % (grown["added_mb"],
                                                                   plain["added_mb"]))
