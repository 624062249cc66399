#!/usr/bin/env python3
"""Rewrite the ``wheels = [...]`` list of blender_manifest.toml to match the files in wheels/.

Usage: python tools/sync_wheels.py [--wheels-dir wheels] [--manifest blender_manifest.toml]
       python tools/sync_wheels.py --clear     (back to ``wheels = []``)

Only the ``wheels`` array is touched; every other line of the manifest stays as written.
"""

from __future__ import annotations

import argparse
import os
import re
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# A top-level `wheels = [ ... ]` array, possibly spanning lines (paths hold no "]").
WHEELS_RE = re.compile(r"^wheels\s*=\s*\[[^\]]*\]", re.MULTILINE)


def render(wheels: list[str]) -> str:
    if not wheels:
        return "wheels = []"
    return "wheels = [\n" + "".join(f'  "./wheels/{w}",\n' for w in wheels) + "]"


def sync(manifest_path: str, wheels: list[str]) -> bool:
    """Write the list; return True when the file changed."""
    with open(manifest_path, encoding="utf-8") as fh:
        text = fh.read()
    new_block = render(sorted(wheels))
    if WHEELS_RE.search(text):
        new_text = WHEELS_RE.sub(lambda _m: new_block, text, count=1)
    else:
        # Insert before the first table so the key stays top-level.
        i = text.find("\n[")
        i = len(text) if i < 0 else i + 1
        new_text = text[:i] + new_block + "\n\n" + text[i:]
    if new_text != text:
        with open(manifest_path, "w", encoding="utf-8") as fh:
            fh.write(new_text)
        return True
    return False


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--wheels-dir", default=os.path.join(ROOT, "wheels"))
    parser.add_argument("--manifest", default=os.path.join(ROOT, "blender_manifest.toml"))
    parser.add_argument("--clear", action="store_true", help="write an empty list")
    args = parser.parse_args(argv)

    wheels = []
    if not args.clear and os.path.isdir(args.wheels_dir):
        wheels = sorted(f for f in os.listdir(args.wheels_dir) if f.endswith(".whl"))
    changed = sync(args.manifest, wheels)
    print(f"{os.path.basename(args.manifest)}: {len(wheels)} wheels listed"
          + (" (updated)" if changed else " (unchanged)"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
