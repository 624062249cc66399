"""Use the repository itself as the add-on, for the demo and the tests (not needed in Blender,
which installs the extension as ``bl_ext.<repo>.relight``)."""
from __future__ import annotations

import importlib.util
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PACKAGE = "relight_ext"


def register_repo_addon():
    """Load the repository root (the extension package, with its relative imports) under the
    name ``relight_ext`` and register it once; returns the module."""
    if PACKAGE in sys.modules:
        return sys.modules[PACKAGE]
    spec = importlib.util.spec_from_file_location(
        PACKAGE, os.path.join(ROOT, "__init__.py"), submodule_search_locations=[ROOT])
    module = importlib.util.module_from_spec(spec)
    sys.modules[PACKAGE] = module
    spec.loader.exec_module(module)
    module.register()
    return module
