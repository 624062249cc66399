"""Another program's cost, measured here: process CPU time (user + sys) and peak RSS of one run
of a command, in this session on this machine (issue 47: a peer's figures are measured beside
ours, not quoted from elsewhere).

The figures are the peer's own (``os.wait4`` on its pid), not this process's nor its other
children's: ``RUSAGE_CHILDREN`` would fold in every child waited for before.  And the peer is
started by a small launcher (a bare Python, no site packages: about 10 MB), not forked from
this process: Linux carries a forked image's resident size into the child's ``ru_maxrss``
across exec, so a peer forked from a process holding 300 MB read at least 300 MB.  A program
that starts children of its own is measured without them (the figures then say less than it
costs).

    python benchmarks/peer.py -- ./build/rpk office.mgf -radiance-method Galerkin ...
"""
from __future__ import annotations

import json
import os
import shlex
import shutil
import signal
import subprocess
import sys
import time

# rpkCpp (RenderPark's C++ port) in batch mode, Galerkin hierarchical radiosity, no ray tracing,
# as its own scripts run the office and the classroom (scripts/*.sh of OscarChavarro/rpkCpp)
RPK_ARGS = ("-radiance-method", "Galerkin", "-raytracing-method", "none", "-batch",
            "-batch-quit-at-end", "-offscreen")
RPK_ITERATIONS = 9


def rpk_command(rpk, scene_file, iterations=RPK_ITERATIONS):
    """The command line of one rpkCpp run on ``scene_file`` with its defaults otherwise."""
    return [str(rpk), str(scene_file), *RPK_ARGS, "-iterations", str(int(iterations))]


# The launcher: starts the command with its output discarded, waits for it, prints its rusage.
_LAUNCHER = """
import json, os, sys
null = os.open(os.devnull, os.O_RDWR)
pid = os.fork()
if pid == 0:
    os.dup2(null, 1); os.dup2(null, 2)
    try:
        os.execvp(sys.argv[1], sys.argv[1:])
    finally:
        os._exit(127)
_, status, ru = os.wait4(pid, 0)
print(json.dumps([os.waitstatus_to_exitcode(status), ru.ru_utime, ru.ru_stime, ru.ru_maxrss]))
"""


def measure(cmd, timeout=None, cwd=None) -> dict:
    """One run of ``cmd`` (a list): {"cpu_s", "user_s", "sys_s", "peak_mb", "wall_s",
    "returncode", "command", "date"}.  Its output is discarded; past ``timeout`` seconds it is
    killed (returncode negative).  Raises FileNotFoundError when the program is missing."""
    cmd = [str(c) for c in cmd]
    if shutil.which(cmd[0]) is None:
        raise FileNotFoundError(f"{cmd[0]}: no such program")
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-I", "-S", "-c", _LAUNCHER, *cmd], cwd=cwd,
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                            start_new_session=True)
    nan = float("nan")
    try:
        out, _ = proc.communicate(timeout=timeout)
        code, user, system, maxrss = json.loads(out.strip().splitlines()[-1])
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)          # the launcher and the peer
        proc.communicate()
        code, user, system, maxrss = -signal.SIGKILL, nan, nan, nan
    # ru_maxrss is in KiB on Linux, in bytes on macOS
    peak = maxrss / (2**20 if sys.platform == "darwin" else 2**10)
    return {"cpu_s": user + system, "user_s": user, "sys_s": system, "peak_mb": peak,
            "wall_s": time.perf_counter() - t0, "returncode": code, "command": shlex.join(cmd),
            "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}


def measure_runs(cmd, runs=3, timeout=None) -> dict:
    """``runs`` runs of ``cmd``: the median run's figures by CPU time, with every run's CPU
    seconds and peak MB under "runs".  Raises RuntimeError when a run fails."""
    got = []
    for _ in range(max(1, int(runs))):
        r = measure(cmd, timeout=timeout)
        if r["returncode"] != 0:
            raise RuntimeError(f"{r['command']}: exit code {r['returncode']}")
        got.append(r)
    order = sorted(got, key=lambda r: r["cpu_s"])
    out = dict(order[len(order) // 2])
    out["runs"] = [(r["cpu_s"], r["peak_mb"]) for r in got]
    return out


def source_line(peer: dict) -> str:
    """How a report says where measured peer figures come from."""
    runs = peer.get("runs") or [(peer["cpu_s"], peer["peak_mb"])]
    cpu = sorted(c for c, _ in runs)
    return (f"measured in this run on this machine ({peer['date']}): `{peer['command']}`, "
            f"{len(runs)} run(s), CPU {cpu[0]:.1f}-{cpu[-1]:.1f} s (the median run's figures "
            "are used), peak RSS of that process")


if __name__ == "__main__":
    argv = sys.argv[1:]
    if argv[:1] == ["--"]:
        argv = argv[1:]
    if not argv:
        sys.exit(__doc__)
    r = measure(argv)
    print(f"CPU {r['cpu_s']:.2f} s (user {r['user_s']:.2f}, sys {r['sys_s']:.2f}), peak "
          f"{r['peak_mb']:.0f} MB, wall {r['wall_s']:.2f} s, exit code {r['returncode']}")
