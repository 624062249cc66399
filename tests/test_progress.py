"""Long work a user can follow and stop (issue 42, 8): core/progress.py and the operators' job.

Truth: the callbacks the computation makes (their order, fractions and messages), the chunks
of work that ran, and the job's thread (alive or not)."""
import threading
import time

import numpy as np
import pytest

from relight_addon.core import progress
from relight_addon.core.progress import Cancelled


def test_ticks_report_within_a_stage_at_most_every_tick():
    seen = []
    with progress.reporting(lambda f, m: seen.append((time.monotonic(), f, m))):
        progress.report(0.2, "stage", 0.6)
        for i in range(50):
            time.sleep(0.01)
            progress.tick((i + 1) / 50)
        with progress.scope(0.6, 1.0):
            progress.report(0.5, "inner", 1.0)
    assert seen[0][1:] == (0.2, "stage")
    ticks = [s for s in seen if s[2] == "stage"][1:]
    assert 1 <= len(ticks) <= 4                       # 0.5 s of work, one tick per 0.2 s
    assert all(0.2 < f <= 0.6 for _, f, _ in ticks)
    assert np.all(np.diff([t for t, _, _ in seen[:-1]]) >= progress.TICK - 1e-3)
    assert seen[-1][1:] == (pytest.approx(0.8), "inner")      # 0.6 + 0.4 * 0.5
    progress.tick()                                           # outside: nothing at all


def test_a_cancel_drops_the_chunks_not_started():
    ran = []
    stop = threading.Event()

    def work(i):
        ran.append(i)
        time.sleep(0.05)
        return i

    def callback(f, m):
        if stop.is_set():
            raise Cancelled(m)

    with progress.reporting(callback):
        progress.report(0.0, "chunks", 1.0)
        progress.TICK, tick0 = 0.0, progress.TICK
        try:
            def watched(i):
                if len(ran) >= 4:
                    stop.set()
                return work(i)
            with pytest.raises(Cancelled):
                progress.chunked(watched, range(200), threads=2)
        finally:
            progress.TICK = tick0
    assert len(ran) < 12                 # not the 200 queued chunks


def test_a_precompute_reports_inside_its_long_stages_and_stops_at_once():
    """The office at draft: several reports per long stage (ticks), fractions that never go
    back, and a cancel raised from a tick stops it before the next report."""
    from relight_addon.core.relight.shadowfree import ShadowFreeOptions, shadow_free
    from scenes.office import office_geometry, office_scene_data
    data = office_scene_data(office_geometry(seed=0, texture_size=16))
    seen = []
    tick0, progress.TICK = progress.TICK, 0.0      # every tick passed on: the count shows them
    try:
        shadow_free(data, ShadowFreeOptions(preset="draft"),
                    progress=lambda f, m: seen.append((f, m)))
        stages = {}
        for f, m in seen:
            stages.setdefault(m, []).append(f)
        assert np.all(np.diff([f for f, _ in seen]) >= -1e-12)
        assert seen[0][0] == 0.0 and seen[-1][0] >= 0.6
        long = [m for m, fs in stages.items() if len(fs) >= 3]
        assert any("Refining" in m for m in long) and any("Light between" in m for m in long)
        assert not any("eq " in m or "T_inter" in m for m in stages)   # no equation numbers
        after = []

        def cancel_midway(f, m):
            after.append((f, m))
            if f >= 0.3:
                raise Cancelled(m)
        with pytest.raises(Cancelled):
            shadow_free(data, ShadowFreeOptions(preset="draft"), progress=cancel_midway)
        assert after[-1][0] >= 0.3 and sum(f >= 0.3 for f, _ in after) == 1
    finally:
        progress.TICK = tick0


bpy = pytest.importorskip("bpy")


def test_no_second_job_until_the_cancelled_one_has_stopped():
    """Esc returns at once; the buttons stay disabled ('stopping') until the worker's thread
    has ended, then the next job may start."""
    import importlib
    from scenes.addon import PACKAGE, register_repo_addon
    register_repo_addon()
    op = importlib.import_module(PACKAGE + ".operators.precompute")

    class Slow:
        action = "solve"

        def compute(self, progress=None):
            for _ in range(40):
                time.sleep(0.05)
                progress(0.5, "working")

    job = op.SolveJob(Slow()).start()
    op._ACTIVE["job"] = job
    try:
        assert "running" in op._busy_reason()
        t0 = time.monotonic()
        job.cancel()
        assert "stopping" in op._busy_reason()
        assert job.join(timeout=5)
        assert time.monotonic() - t0 < 0.3           # the next progress report stopped it
        assert job.state == "cancelled" and op._busy_reason() is None
    finally:
        op._ACTIVE["job"] = None
