"""The extension's version: blender_manifest.toml is the single source of truth."""
from __future__ import annotations

import functools
import os


@functools.lru_cache(maxsize=1)
def addon_version() -> str:
    import tomllib
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    try:
        with open(os.path.join(root, "blender_manifest.toml"), "rb") as fh:
            return str(tomllib.load(fh).get("version", "?"))
    except (OSError, ValueError):
        return "?"
