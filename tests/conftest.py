"""Shared pytest set-up: make ``import relight_addon...`` work from the repository root."""

import os
import shutil
import sys

import pytest

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


def pytest_configure(config):
    # `make test-quick` runs `-m "not slow"`: what a developer runs between edits (< 5 min)
    config.addinivalue_line("markers", "slow: Cycles bakes and renders, scans, EEVEE, long "
                                       "solves (left out of `make test-quick`)")


@pytest.fixture
def test_room():
    """The suite's test room (helpers.room) in a factory-empty file, the add-on registered and
    its preset at draft; not precomputed."""
    bpy = pytest.importorskip("bpy")
    from helpers.blender import addon
    from helpers.room import build_scene
    addon()
    build_scene()
    bpy.context.scene.relight.preset = "draft"
    return bpy.context.scene


@pytest.fixture
def count_solves(monkeypatch):
    """``solves = count_solves()``: from then on ``solves`` gets an entry for each new solve of
    the room (the pipeline's ``solve``; an Update that keeps the room adds none)."""
    def start():
        from helpers.blender import addon_module
        pipeline = addon_module("relight_addon.blender.pipeline")
        solves = []
        solve = pipeline.solve
        monkeypatch.setattr(pipeline, "solve", lambda *a, **k: solves.append(1) or solve(*a, **k))
        return solves
    return start


def pytest_collection_modifyitems(session, config, items):
    rank = {name: i for i, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))


# The Cycles bakes and Mitsuba 3 references the tests read (~7 min of one core on a clean
# clone), shipped as a clean clone's first run left them in .cache.  Their keys hold the scene,
# the settings and bpy's or Mitsuba's version, so a changed scene or another version renders
# afresh; test_shipped_references.py re-renders a cheap subset against them.  `make test-cache`
# rebuilds them.
SHIPPED_CACHE = os.path.join(ROOT, "tests", "data", "cache")


def shipped_cache_targets():
    """{shipped folder: the cache folder the harness reads}."""
    from reference.mitsuba_ref import CACHE_DIR
    from scenes.bake import default_cache_dir
    return {os.path.join(SHIPPED_CACHE, "bakes"): default_cache_dir(),
            os.path.join(SHIPPED_CACHE, "mitsuba"): str(CACHE_DIR)}


def pytest_sessionstart(session):
    """Copies every shipped entry missing from the caches (each worker does: copies are
    atomic, and an entry already there, shipped or rendered here, is kept)."""
    for shipped, target in shipped_cache_targets().items():
        for folder, _, files in os.walk(shipped):
            out = os.path.join(target, os.path.relpath(folder, shipped))
            for name in files:
                dest = os.path.join(out, name)
                if not os.path.exists(dest):
                    os.makedirs(out, exist_ok=True)
                    tmp = f"{dest}.{os.getpid()}.tmp"
                    shutil.copyfile(os.path.join(folder, name), tmp)
                    os.replace(tmp, dest)


_exit_status = {}


def pytest_sessionfinish(session, exitstatus):
    _exit_status["code"] = int(exitstatus)


def pytest_unconfigure(config):
    """bpy 4.x does not leave: 4.2 segfaults in its interpreter teardown after an EEVEE render,
    4.5 hangs in a static destructor (tools/bpy_exit_hook.py, which `make` installs into the LTS
    venv for every other Python there).  There, leave right after pytest has reported, with its
    status."""
    bpy = sys.modules.get("bpy")
    if bpy is not None and tuple(bpy.app.version) < (5, 0, 0) and "code" in _exit_status:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(_exit_status["code"])
