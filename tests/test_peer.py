"""benchmarks/peer.py: a peer program's process CPU and peak RSS, measured here (issue 47), and
bench_mgf's report using them."""
import os
import sys

import pytest

BENCH = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "benchmarks")
if BENCH not in sys.path:
    sys.path.insert(0, BENCH)

import peer  # noqa: E402

# A stand-in for the peer: touches 200 MB, then spins for 0.3 s of its own CPU time.
HEAVY = ("import time\n"
         "b = bytearray(200 * 2**20)\n"
         "for i in range(0, len(b), 4096): b[i] = 1\n"
         "t = time.process_time()\n"
         "while time.process_time() - t < 0.3: pass\n")


def test_a_run_is_measured_by_its_own_cpu_and_peak():
    heavy = peer.measure([sys.executable, "-c", HEAVY])
    assert heavy["returncode"] == 0
    assert heavy["cpu_s"] >= 0.28
    assert heavy["peak_mb"] >= 200
    assert heavy["wall_s"] >= 0.28
    # the next run's figures are its own, not the largest child's so far (RUSAGE_CHILDREN's)
    light = peer.measure([sys.executable, "-c", "pass"])
    assert light["peak_mb"] < 120, light
    assert light["cpu_s"] < heavy["cpu_s"]


def test_a_failing_or_missing_peer_is_told():
    with pytest.raises(RuntimeError, match="exit code 3"):
        peer.measure_runs([sys.executable, "-c", "raise SystemExit(3)"], runs=1)
    with pytest.raises(FileNotFoundError):
        peer.measure(["/nonexistent/rpk"])
    killed = peer.measure([sys.executable, "-c", "import time; time.sleep(30)"], timeout=0.5)
    assert killed["returncode"] < 0 and killed["wall_s"] < 10


def test_rpk_command_runs_rpkcpp_in_batch_with_its_iterations():
    cmd = peer.rpk_command("/opt/rpk", "office.mgf", 7)
    assert cmd[:2] == ["/opt/rpk", "office.mgf"]
    assert cmd[cmd.index("-radiance-method") + 1] == "Galerkin"
    assert cmd[cmd.index("-iterations") + 1] == "7"
    assert "-batch-quit-at-end" in cmd and "-offscreen" in cmd


def _row():
    return dict(preset="medium", elements=100, leaves=80, links=1000, solve_s=6.0,
                solve_cpu_s=10.0, peak_mb=400.0, rss_before_mb=150.0, estimate_mb=500.0,
                iterations=12, residual=1e-9, reflected_over_emitted=0.5, rows_max=1.0,
                faces=10, patches=10, lamps=1, flipped=0, backs=0, patches_oriented=10,
                read_s=0.1, orient_s=0.1)


def test_the_report_divides_by_the_peer_measured_in_the_run(tmp_path, monkeypatch):
    bench_mgf = pytest.importorskip("bench_mgf")
    monkeypatch.setattr(bench_mgf, "RESULTS", tmp_path)
    measured = peer.measure_runs([sys.executable, "-c", HEAVY], runs=1)
    measured.update(cpu_s=5.0, peak_mb=200.0)          # round figures for the ratios below
    bench_mgf.report([_row()], None, "office", measured)
    text = (tmp_path / "mgf.md").read_text()
    assert "measured in this run on this machine" in text
    assert sys.executable in text                       # the command that was measured
    line = next(x for x in text.splitlines() if x.startswith("| medium |"))
    cells = [c.strip() for c in line.strip("|").split("|")]
    assert cells[5] == "10.0"                          # solve CPU s
    assert cells[9] == "2.00" and cells[10] == "2.00"   # peak and CPU over the peer's
    # without a measured peer the figures are used, and the report says whose they are
    bench_mgf.report([_row()], None, "office")
    text = (tmp_path / "mgf.md").read_text()
    assert "measured by the session that filed issue 47" in text
    assert "measured in this run" not in text
