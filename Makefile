# Relight: developer commands. See README.md.
#
#   make test        both Blender lines: the whole suite on bpy 5.2 (Python 3.13, .venv), then
#                    LTS_TESTS on bpy 4.5 LTS (Python 3.11, .venv-lts); each venv is created on
#                    first use (bpy wheel + runtime + test deps)
#   make test-main   the whole suite on bpy 5.2 only
#   make test-quick  the tests not marked slow (under 5 minutes), on bpy 5.2
#   make layers      the import contracts of .importlinter (import-linter; make test checks them too)
#   make demo        solve the embedded Cornell box (out/cornell.png), then relight the photographed
#                    office through the operators: a lamp off, a virtual lamp and a virtual box
#                    (EEVEE frames, Cycles truth, out/demo_side_by_side.png, out/demo.blend); writes
#                    under out/ only (`make demo-results` also updates benchmarks/results/)
#   make extension   download the runtime wheels per platform and Python (cp311, cp313), build
#                    dist/relight-*-<platform>.zip (one zip per platform serves both lines)
#   make test-lts    LTS_TESTS against Blender 4.5 LTS (bpy 4.5) in .venv-lts
#   make test-cache  render again the Cycles bakes and Mitsuba references shipped in
#                    tests/data/cache (after a change to a test scene or a bpy/Mitsuba update)
#   make clean       remove build output and caches (keeps the venvs; `make distclean` removes them)

# Blender 5.2 runs Python 3.13, Blender 4.5 LTS Python 3.11: one interpreter per line (a bpy
# wheel is built for one Python).  pyenv's 3.13 by its full path (its bare `python3.13` shim
# refuses when 3.13 is not pyenv's selected version), else a python3.13 on PATH.
PYENV_ROOT_DIR := $(shell pyenv root 2>/dev/null)
PYTHON     ?= $(firstword $(wildcard $(PYENV_ROOT_DIR)/versions/3.13*/bin/python3.13) python3.13)
PYTHON_LTS ?= python3.11
VENV    ?= .venv
LTS     ?= .venv-lts
# the slowest tests listed at the end, so that CI's log shows where the suite's time goes
PYTEST_ARGS ?= -q -rs -p no:cacheprovider --durations=25
# two worker processes, each taking whole test files (a file's module fixtures, Cycles bakes
# and scans, are built once), the longest files first (conftest.py's LONGEST_FIRST)
PYTEST_JOBS ?= -n 2 --dist loadfile --no-loadscope-reorder

# The LTS line runs the tests whose result could differ between Blender 4.5 and 5.2: what talks
# to Blender's API where it changed (node trees and materials read and written, lights, EEVEE,
# the compositor, the gpu module, undo, save and reopen, operators and panels, the extension
# zip installed into Blender) rather than the bpy-free core, which is the same code on the same
# numpy maths.  AR mode needs Blender 5.0's compositor: on 4.5 its refusal is tested
# (test_ar_refused.py).  The Cycles truth the tests compare against is rendered by each line's own
# Cycles (bakes are keyed by bpy's version; both lines' bakes are shipped in tests/data/cache).
LTS_TESTS ?= tests/test_extension_install.py tests/test_bridge_read.py \
	tests/test_precompute_operator.py tests/test_user_edits.py tests/test_virtual_lamps.py \
	tests/test_virtual_objects.py tests/test_virtual_emissive.py tests/test_sphere_nodes.py \
	tests/test_id_arrays.py \
	tests/test_eevee_light.py tests/test_ar_refused.py \
	tests/test_capture_operators.py tests/test_messages.py tests/test_progress.py \
	tests/test_data_safety.py

REQ_COMMON := requirements/runtime.txt requirements/test.txt
REQ_MAIN   := requirements/blender.txt $(REQ_COMMON)
REQ_LTS    := requirements/blender-lts.txt $(REQ_COMMON)

# The stamp is newer than every requirement file once the venv matches them.
STAMP     := $(VENV)/.requirements-stamp
STAMP_LTS := $(LTS)/.requirements-stamp

.PHONY: test test-main test-quick layers demo demo-results extension wheels test-lts test-cache validate clean distclean venv venv-lts

# both lines even when the first fails (CI's log then shows both); the status fails if either does
test: $(STAMP) $(STAMP_LTS)
	@status=0; \
	$(MAKE) --no-print-directory test-main || status=1; \
	$(MAKE) --no-print-directory test-lts || status=1; \
	exit $$status

# a bound on each line's whole run (normally 14 and 2 minutes): a worker that crashed inside
# bpy once left pytest-xdist waiting for ever (the LTS line, 2026-12-02), which CI's own limit
# would only have ended after 90 minutes
MAIN_LIMIT ?= 2400
LTS_LIMIT ?= 900
BOUNDED = timeout --kill-after=60

test-main: $(STAMP)
	$(VENV)/bin/python -c "import bpy, sys; print('main line: bpy', bpy.app.version_string, 'python', sys.version.split()[0])"
	$(BOUNDED) $(MAIN_LIMIT) $(VENV)/bin/python -m pytest $(PYTEST_ARGS) $(PYTEST_JOBS) tests

# the tests not marked slow (conftest.py): under 5 minutes, between edits
test-quick: $(STAMP)
	$(VENV)/bin/python -m pytest $(PYTEST_ARGS) $(PYTEST_JOBS) -m "not slow" tests

layers: $(STAMP)
	$(VENV)/bin/python tools/lint_imports.py

demo: $(STAMP)
	$(VENV)/bin/python -m demo.cornell
	$(VENV)/bin/python -m demo.office

# the demo, and its pictures copied into benchmarks/results (tracked: a deliberate update)
demo-results: $(STAMP)
	$(VENV)/bin/python -m demo.cornell --results benchmarks/results/cornell_demo.png
	$(VENV)/bin/python -m demo.office --results benchmarks/results/demo_office.png

venv: $(STAMP)
venv-lts: $(STAMP_LTS)

$(STAMP): $(REQ_MAIN)
	@test -x $(VENV)/bin/python || $(PYTHON) -m venv $(VENV)
	@$(VENV)/bin/python -c "import sys; sys.exit(sys.version_info[:2] != (3, 13))" || \
		{ echo "$(VENV) is not Python 3.13 (bpy 5.2): remove it (make distclean)"; exit 1; }
	$(VENV)/bin/python -m pip install --disable-pip-version-check -q --upgrade pip
	$(VENV)/bin/python -m pip install --disable-pip-version-check -q $(addprefix -r ,$(REQ_MAIN))
	@touch $@

# bpy 4.5 needs its own venv and Python: one bpy per interpreter.
$(STAMP_LTS): $(REQ_LTS)
	@test -x $(LTS)/bin/python || $(PYTHON_LTS) -m venv $(LTS)
	$(LTS)/bin/python -m pip install --disable-pip-version-check -q --upgrade pip
	$(LTS)/bin/python -m pip install --disable-pip-version-check -q $(addprefix -r ,$(REQ_LTS))
	@# bpy 4.5 hangs at exit (Blender's bug, tools/bpy_exit_hook.py): every Python of the venv
	@# loads the hook that leaves before bpy's static destructors
	echo "import runpy; runpy.run_path('$(CURDIR)/tools/bpy_exit_hook.py')" > \
		"$$($(LTS)/bin/python -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')/relight_bpy_exit.pth"
	@touch $@

test-lts: $(STAMP_LTS)
	$(LTS)/bin/python -c "import bpy, sys; print('LTS line: bpy', bpy.app.version_string, 'python', sys.version.split()[0])"
	$(BOUNDED) $(LTS_LIMIT) $(LTS)/bin/python -m pytest $(PYTEST_ARGS) $(PYTEST_JOBS) $(LTS_TESTS)

# every test of both lines, from empty caches of their own (a developer's .cache, benchmarks'
# references included, is left alone), then what they rendered becomes the shipped cache
# (conftest.py): bakes are keyed by bpy's version, so each line ships its own
FRESH_CACHE := $(CURDIR)/.cache/test-cache
FRESH_ENV   := RELIGHT_BAKE_CACHE=$(FRESH_CACHE)/bakes RELIGHT_MITSUBA_CACHE=$(FRESH_CACHE)/mitsuba
test-cache: $(STAMP) $(STAMP_LTS)
	rm -rf $(FRESH_CACHE) tests/data/cache
	$(FRESH_ENV) $(VENV)/bin/python -m pytest $(PYTEST_ARGS) $(PYTEST_JOBS) tests \
		--ignore=tests/test_shipped_references.py
	$(FRESH_ENV) $(LTS)/bin/python -m pytest $(PYTEST_ARGS) $(PYTEST_JOBS) $(LTS_TESTS)
	mkdir -p tests/data/cache
	cp -r $(FRESH_CACHE)/bakes $(FRESH_CACHE)/mitsuba tests/data/cache/
	$(VENV)/bin/python -c "import json, subprocess, importlib.metadata as m; print(json.dumps({'bpy': \
		[subprocess.check_output([p, '-c', 'import importlib.metadata as m; print(m.version(\"bpy\"))'], \
		text=True).strip() for p in ('$(VENV)/bin/python', '$(LTS)/bin/python')], \
		'mitsuba': m.version('mitsuba')}, indent=1))" > tests/data/cache/versions.json

validate: $(STAMP)
	$(VENV)/bin/python tools/blender_ext.py validate .

# Unmodified PyPI wheels for every platform of the manifest (never numpy: Blender ships it);
# missing optional wheels (embreex) are reported and skipped.
wheels: $(STAMP)
	$(VENV)/bin/python tools/fetch_wheels.py --dest wheels

extension: wheels
	$(VENV)/bin/python tools/sync_wheels.py
	$(VENV)/bin/python tools/blender_ext.py validate .
	@mkdir -p dist
	rm -f dist/relight-*.zip
	$(VENV)/bin/python tools/blender_ext.py build --source-dir . --output-dir dist --split-platforms
	@ls -l dist/*.zip

clean:
	rm -rf dist out .cache .pytest_cache
	find . -path ./$(VENV) -prune -o -path ./$(LTS) -prune -o -name __pycache__ -type d -exec rm -rf {} +

distclean: clean
	rm -rf wheels $(VENV) $(LTS)
