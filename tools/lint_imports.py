#!/usr/bin/env python3
"""Check the layer rules of ``.importlinter`` (import-linter's ``lint-imports``) on the extension.

Usage: python tools/lint_imports.py [--root DIR] [lint-imports options, e.g. --verbose]

``--root``: analyse another copy of the extension (tests/test_layers.py breaks one on purpose).

The repository root is itself the extension package (Blender installs it as
``bl_ext.<repo>.<id>``), and its packages import one another relatively (``from ..relight_addon
import ...`` in operators/): analysed from inside the root, those imports would leave the top
package and vanish from the graph.  So the root is analysed as one package named
``relight_ext`` (the name the tests register it under): a finder on ``sys.path`` maps that name
to this folder, then import-linter runs as its own command does.
"""
from __future__ import annotations

import importlib.abc
import importlib.util
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PACKAGE = "relight_ext"
CONFIG = os.path.join(ROOT, ".importlinter")


class _ExtensionFinder(importlib.abc.MetaPathFinder):
    """Finds ``relight_ext`` at ``root`` (grimp locates packages by find_spec; it reads the
    files, it imports nothing)."""

    def __init__(self, root):
        self.root = root

    def find_spec(self, name, path=None, target=None):
        if name != PACKAGE:
            return None
        return importlib.util.spec_from_file_location(
            PACKAGE, os.path.join(self.root, "__init__.py"),
            submodule_search_locations=[self.root])


def main(argv=None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    root = ROOT
    if "--root" in args:
        i = args.index("--root")
        root = os.path.abspath(args[i + 1])
        del args[i:i + 2]
    sys.meta_path.insert(0, _ExtensionFinder(root))
    from importlinter.cli import lint_imports_command
    if not any(a == "--config" or a.startswith("--config=") for a in args):
        args += ["--config", CONFIG]
    if "--no-cache" not in args:
        args.append("--no-cache")            # a cache would be one more thing to keep out of git
    try:
        lint_imports_command.main(args=args, prog_name="lint-imports", standalone_mode=False)
    except SystemExit as stop:               # click's exit code: 0 kept, 1 broken
        return int(stop.code or 0)
    return 0


if __name__ == "__main__":
    sys.exit(main())
