#!/usr/bin/env python3
"""Run Blender's extension CLI (``bl_pkg/cli/blender_ext.py``) from the bpy wheel of this venv.

Usage: python tools/blender_ext.py validate .
       python tools/blender_ext.py build --source-dir . --output-dir dist --split-platforms
       python tools/blender_ext.py --print-path

Finds the script without importing bpy (that takes seconds): ``$BLENDER_SCRIPTS`` (a Blender
``scripts`` folder) when set, else the bpy wheel of this Python. For ``build`` and ``validate``
it passes Blender's own list of valid tags, as ``blender --command extension`` does.
"""

from __future__ import annotations

import glob
import importlib.util
import os
import runpy
import sys


def bpy_root() -> str:
    spec = importlib.util.find_spec("bpy")
    if spec is None or not spec.origin:
        raise SystemExit("bpy is not installed in this Python (run `make test` once to create .venv)")
    return os.path.dirname(spec.origin)


def _version_dir() -> str:
    dirs = sorted(d for d in glob.glob(os.path.join(bpy_root(), "[0-9]*.[0-9]*")) if os.path.isdir(d))
    if not dirs:
        raise SystemExit(f"no Blender version folder in {bpy_root()}")
    return dirs[-1]


def scripts_dir() -> str:
    return os.environ.get("BLENDER_SCRIPTS") or os.path.join(_version_dir(), "scripts")


def script_path() -> str:
    return os.path.join(scripts_dir(), "addons_core", "bl_pkg", "cli", "blender_ext.py")


def tags_path() -> str:
    return os.path.join(scripts_dir(), "modules", "_bpy_internal", "extensions", "tags.py")


def main(argv: list[str]) -> int:
    if argv[:1] == ["--print-path"]:
        print(script_path())
        return 0
    args = list(argv)
    if args[:1] in (["build"], ["validate"]) and not any(a.startswith("--valid-tags") for a in args):
        if os.path.exists(tags_path()):
            args[1:1] = ["--valid-tags", tags_path()]
    script = script_path()
    sys.argv = [script, *args]
    try:
        runpy.run_path(script, run_name="__main__")
    except SystemExit as ex:
        code = ex.code
        return code if isinstance(code, int) else (0 if code is None else 1)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
