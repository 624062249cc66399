"""The layer rules of the house (DESIGN.md §1, issue 43): the import contracts of
``.importlinter`` hold on the extension, checked by import-linter through the developer's
command (``python tools/lint_imports.py``); and each contract is broken by the import it
forbids, put into a copy of the extension (a contract that the tool could not see break, e.g.
because imports leaving a top package vanish from its graph, would hold whatever the code)."""
import os
import shutil
import subprocess
import sys

import pytest

pytest.importorskip("importlinter")     # requirements/test.txt (not in Blender's own Python)

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TOOL = os.path.join(ROOT, "tools", "lint_imports.py")
CONTRACTS = ("core-is-bpy-free", "core-layers", "radiosity-below-relight",
             "geometry-below-radiosity", "bridge-below-ui", "core-acyclic", "relative-imports")

# contract id -> (file of the extension, an import that breaks it)
BREACHES = {
    "core-is-bpy-free": ("relight_addon/core/geometry/extent.py", "import mathutils"),
    "core-layers": ("relight_addon/core/geometry/raycast.py", "from ..scene import SceneData"),
    "radiosity-below-relight": ("relight_addon/core/radiosity/solver.py",
                                "from ..relight import maps"),
    "geometry-below-radiosity": ("relight_addon/core/geometry/sampling.py",
                                 "from ..radiosity import hierarchy"),
    "bridge-below-ui": ("relight_addon/blender/write.py", "from ...operators import base"),
    # a circle inside one package (shadowfree imports maps), which no layer rule forbids
    "core-acyclic": ("relight_addon/core/relight/maps.py", "from . import shadowfree"),
    "relative-imports": ("operators/base.py", "import relight_addon.core.scene"),
}


def _lint(*args):
    run = subprocess.run([sys.executable, TOOL, "--no-logo", *args], capture_output=True,
                         text=True, timeout=300)
    return run.returncode, run.stdout + run.stderr


def _config_ids():
    import configparser
    cfg = configparser.ConfigParser()
    cfg.read(os.path.join(ROOT, ".importlinter"))
    return {s.split(":", 2)[2] for s in cfg.sections() if s.startswith("importlinter:contract:")}


def test_the_layer_contracts_hold():
    assert _config_ids() == set(CONTRACTS)
    code, out = _lint()
    print(out)
    assert code == 0, out
    assert f"Contracts: {len(CONTRACTS)} kept, 0 broken." in out


@pytest.fixture(scope="module")
def copy_of_the_extension(tmp_path_factory):
    """The extension's Python files (and the contracts), copied."""
    dst = tmp_path_factory.mktemp("ext")
    for name in ("__init__.py", "preferences.py", ".importlinter"):
        shutil.copy(os.path.join(ROOT, name), dst / name)
    for pkg in ("relight_addon", "operators", "panels"):
        shutil.copytree(os.path.join(ROOT, pkg), dst / pkg,
                        ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    return dst


@pytest.mark.parametrize("contract", CONTRACTS)
def test_each_contract_breaks_on_the_import_it_forbids(copy_of_the_extension, contract):
    root = copy_of_the_extension
    path, line = BREACHES[contract]
    target = root / path
    original = target.read_text()
    target.write_text(original + f"\n{line}\n")          # a module-level import at its end
    try:
        code, out = _lint("--root", str(root), "--config", str(root / ".importlinter"),
                          "--contract", contract)
    finally:
        target.write_text(original)
    print(out)
    assert code == 1 and "BROKEN" in out and "0 kept, 1 broken" in out, out
