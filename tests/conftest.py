"""Shared pytest set-up: make ``import relight_addon...`` work from the repository root."""

import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)


# The longest test files, longest first (seconds in one process, `--durations`): `make test`'s
# two workers take whole files in collection order (--dist loadfile, --no-loadscope-reorder),
# so the long ones start first and the short ones fill in beside them (longest processing time
# first); a long file started last would run on alone.  The others keep pytest's order.
LONGEST_FIRST = ("test_proxy.py", "test_clutter_furnace.py", "test_shadowfree.py",
                 "test_against_mitsuba.py", "test_family_relight.py", "test_memory_estimate.py",
                 "test_eevee_light.py", "test_radiosity.py", "test_relit_renders.py",
                 "test_data_safety.py", "test_office_bakes.py")


def pytest_collection_modifyitems(session, config, items):
    rank = {name: i for i, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))


_exit_status = {}


def pytest_sessionfinish(session, exitstatus):
    _exit_status["code"] = int(exitstatus)


def pytest_unconfigure(config):
    """bpy 4.2 crashes in its own interpreter teardown after an EEVEE render (segfault once
    every test has passed).  There, leave right after pytest has reported, with its status."""
    bpy = sys.modules.get("bpy")
    if bpy is not None and tuple(bpy.app.version) < (4, 3, 0) and "code" in _exit_status:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(_exit_status["code"])
