# Relight: developer commands. See README.md.
#
#   make test        create .venv on first use (bpy wheel + runtime + test deps), run pytest
#   make test-quick  the tests not marked slow (under 5 minutes)
#   make layers      the import contracts of .importlinter (import-linter; make test checks them too)
#   make demo        solve the embedded Cornell box (out/cornell.png), then relight the photographed
#                    office through the operators: a lamp off, a virtual lamp and a virtual box
#                    (EEVEE frames, Cycles truth, out/demo_side_by_side.png, out/demo.blend); writes
#                    under out/ only (`make demo-results` also updates benchmarks/results/)
#   make extension   download the runtime wheels per platform, build dist/relight-*-<platform>.zip
#   make test-lts    the same tests against Blender 4.2 LTS (bpy 4.2) in .venv-lts
#   make test-cache  render again the Cycles bakes and Mitsuba references shipped in
#                    tests/data/cache (after a change to a test scene or a bpy/Mitsuba update)
#   make clean       remove build output and caches (keeps the venvs; `make distclean` removes them)

PYTHON  ?= python3.11
VENV    ?= .venv
LTS     ?= .venv-lts
# the slowest tests listed at the end, so that CI's log shows where the suite's time goes
PYTEST_ARGS ?= -q -rs -p no:cacheprovider --durations=25
# two worker processes, each taking whole test files (a file's module fixtures, Cycles bakes
# and scans, are built once), the longest files first (conftest.py's LONGEST_FIRST); the LTS
# run stays in one process (bpy 4.2's exit, conftest.py)
PYTEST_JOBS ?= -n 2 --dist loadfile --no-loadscope-reorder

REQ_COMMON := requirements/runtime.txt requirements/test.txt
REQ_MAIN   := requirements/blender.txt $(REQ_COMMON)
REQ_LTS    := requirements/blender-lts.txt $(REQ_COMMON)

# The stamp is newer than every requirement file once the venv matches them.
STAMP     := $(VENV)/.requirements-stamp
STAMP_LTS := $(LTS)/.requirements-stamp

.PHONY: test test-quick layers demo demo-results extension wheels test-lts test-cache validate clean distclean venv venv-lts

test: $(STAMP)
	$(VENV)/bin/python -m pytest $(PYTEST_ARGS) $(PYTEST_JOBS) tests

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
	$(VENV)/bin/python -m pip install --disable-pip-version-check -q --upgrade pip
	$(VENV)/bin/python -m pip install --disable-pip-version-check -q $(addprefix -r ,$(REQ_MAIN))
	@touch $@

# bpy 4.2 needs its own venv: one bpy per interpreter.
$(STAMP_LTS): $(REQ_LTS)
	@test -x $(LTS)/bin/python || $(PYTHON) -m venv $(LTS)
	$(LTS)/bin/python -m pip install --disable-pip-version-check -q --upgrade pip
	$(LTS)/bin/python -m pip install --disable-pip-version-check -q $(addprefix -r ,$(REQ_LTS))
	@touch $@

test-lts: $(STAMP_LTS)
	$(LTS)/bin/python -c "import bpy; print('bpy', bpy.app.version_string)"
	$(LTS)/bin/python -m pytest $(PYTEST_ARGS) tests

# every test, from empty caches of its own (a developer's .cache, benchmarks' references
# included, is left alone), then what they rendered becomes the shipped cache (conftest.py)
FRESH_CACHE := $(CURDIR)/.cache/test-cache
test-cache: $(STAMP)
	rm -rf $(FRESH_CACHE) tests/data/cache
	RELIGHT_BAKE_CACHE=$(FRESH_CACHE)/bakes RELIGHT_MITSUBA_CACHE=$(FRESH_CACHE)/mitsuba \
		$(VENV)/bin/python -m pytest $(PYTEST_ARGS) $(PYTEST_JOBS) tests \
		--ignore=tests/test_shipped_references.py
	mkdir -p tests/data/cache
	cp -r $(FRESH_CACHE)/bakes $(FRESH_CACHE)/mitsuba tests/data/cache/
	$(VENV)/bin/python -c "import bpy, json, importlib.metadata as m; print(json.dumps({'bpy': \
		bpy.app.version_string.split()[0], 'mitsuba': m.version('mitsuba')}, indent=1))" \
		> tests/data/cache/versions.json

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
