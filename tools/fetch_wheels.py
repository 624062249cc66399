#!/usr/bin/env python3
"""Download the extension's runtime wheels for every platform Blender builds for.

Usage: python tools/fetch_wheels.py [--dest wheels] [--python-version 3.11 --python-version 3.13]

Reads the pinned requirements in requirements/runtime.txt and requirements/bundle-extra.txt,
downloads unmodified PyPI wheels (``pip download --only-binary=:all: --no-deps``) for each
platform of blender_manifest.toml and each Python of PYTHON_VERSIONS (default) into ``wheels/``,
and never numpy (Blender ships it).  One zip per platform then holds the wheels of both Pythons:
Blender installs only those matching its own Python and platform (bl_pkg's wheel filter,
Blender 4.2 and later), so the same zip serves Blender 4.5 LTS (3.11) and 5.x (3.13).
A package without a wheel for a platform and Python is skipped with a message (embreex, for example,
where the core falls back to mathutils.bvhtree). Then checks, per platform and Python, that the
``Requires-Dist`` of every downloaded wheel is satisfied by another downloaded wheel or by a
module Blender ships, so a missing transitive dependency is caught here and not in Blender.

Exit status: 0 when every required wheel exists or is optional; 1 otherwise.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import zipfile

try:
    from packaging.markers import default_environment
    from packaging.requirements import Requirement
    from packaging.utils import canonicalize_name, parse_wheel_filename
except ImportError:  # pip vendors packaging
    from pip._vendor.packaging.markers import default_environment
    from pip._vendor.packaging.requirements import Requirement
    from pip._vendor.packaging.utils import canonicalize_name, parse_wheel_filename

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
REQUIREMENT_FILES = ("requirements/runtime.txt", "requirements/bundle-extra.txt")

# The Pythons of the Blender lines the manifest accepts: 4.5 LTS (3.11), 5.x (3.13).
PYTHON_VERSIONS = ("3.11", "3.13")

# Modules that Blender's own Python provides (4.5 to 5.x); never bundled.
PROVIDED_BY_BLENDER = {
    "numpy", "requests", "certifi", "charset-normalizer", "idna", "urllib3", "zstandard",
    "cython", "autopep8", "pycodestyle",
}

# Packages that may lack a wheel for a platform: the add-on has a fallback.
OPTIONAL = {"embreex"}

# Blender platform -> ladder of pip platform-tag sets, tried in order. The first set
# matches Blender's own minimum OS (glibc 2.28, macOS 11); later sets accept a newer
# minimum OS for packages that publish nothing older, and that is reported.
_MANYLINUX = [f"manylinux_2_{minor}_x86_64" for minor in range(28, 16, -1)] + ["manylinux2014_x86_64"]
PLATFORMS: dict[str, list[list[str]]] = {
    "linux-x64": [_MANYLINUX],
    "windows-x64": [["win_amd64"]],
    "macos-arm64": [[f"macosx_{v}_0_arm64"] for v in (11, 12, 13, 14)],
    "macos-x64": [[f"macosx_{v}_0_x86_64"] for v in (11, 12, 13, 14)],
}

# Marker environment of Blender's Python on each platform (for Requires-Dist markers).
MARKER_ENV = {
    "linux-x64": {"sys_platform": "linux", "platform_system": "Linux", "platform_machine": "x86_64", "os_name": "posix"},
    "windows-x64": {"sys_platform": "win32", "platform_system": "Windows", "platform_machine": "AMD64", "os_name": "nt"},
    "macos-arm64": {"sys_platform": "darwin", "platform_system": "Darwin", "platform_machine": "arm64", "os_name": "posix"},
    "macos-x64": {"sys_platform": "darwin", "platform_system": "Darwin", "platform_machine": "x86_64", "os_name": "posix"},
}


def read_requirements(root: str) -> list[Requirement]:
    reqs = []
    for rel in REQUIREMENT_FILES:
        with open(os.path.join(root, rel), encoding="utf-8") as fh:
            for line in fh:
                line = line.split("#", 1)[0].strip()
                if line and not line.startswith("-"):
                    req = Requirement(line)
                    if canonicalize_name(req.name) not in PROVIDED_BY_BLENDER:
                        reqs.append(req)
    return reqs


def pip_download(req: str, platforms: list[str], python_version: str, dest: str) -> tuple[bool, str]:
    cmd = [
        sys.executable, "-m", "pip", "download", "--disable-pip-version-check", "--quiet",
        "--no-deps", "--only-binary=:all:", "--implementation", "cp",
        "--python-version", python_version, "--dest", dest,
    ]
    for tag in platforms:
        cmd += ["--platform", tag]
    cmd.append(req)
    proc = subprocess.run(cmd, capture_output=True, text=True)
    return proc.returncode == 0, (proc.stderr or proc.stdout).strip()


def wheel_requires(path: str) -> list[Requirement]:
    with zipfile.ZipFile(path) as zf:
        name = next(n for n in zf.namelist() if n.endswith(".dist-info/METADATA") and n.count("/") == 1)
        text = zf.read(name).decode("utf-8", "replace")
    reqs = []
    for line in text.splitlines():
        if not line.strip():
            break  # end of headers
        if line.startswith("Requires-Dist:"):
            reqs.append(Requirement(line.split(":", 1)[1].strip()))
    return reqs


def check_closure(platform: str, wheel_paths: list[str], python_version: str) -> list[str]:
    """Unsatisfied Requires-Dist (without extras) of the wheels bundled for one platform."""
    env = dict(default_environment())
    env.update(MARKER_ENV[platform])
    env.update(python_version=python_version, python_full_version=python_version + ".0",
               implementation_name="cpython", platform_python_implementation="CPython", extra="")
    have = {}
    for path in wheel_paths:
        name, version, _, _ = parse_wheel_filename(os.path.basename(path))
        have[canonicalize_name(name)] = version
    problems = []
    for path in wheel_paths:
        for req in wheel_requires(path):
            if req.marker is not None and not req.marker.evaluate(env):
                continue
            name = canonicalize_name(req.name)
            if name in PROVIDED_BY_BLENDER:
                continue
            if name not in have:
                problems.append(f"{os.path.basename(path)} needs {req} (not bundled)")
            elif req.specifier and not req.specifier.contains(have[name], prereleases=True):
                problems.append(f"{os.path.basename(path)} needs {req}, bundled {have[name]}")
    return problems


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--dest", default=os.path.join(ROOT, "wheels"))
    parser.add_argument("--python-version", action="append", dest="python_versions",
                        help=f"a Python to fetch for, repeatable (default: {', '.join(PYTHON_VERSIONS)})")
    parser.add_argument("--platform", action="append", choices=sorted(PLATFORMS),
                        help="limit to these Blender platforms (default: all)")
    args = parser.parse_args(argv)

    platforms = args.platform or list(PLATFORMS)
    pythons = args.python_versions or list(PYTHON_VERSIONS)
    reqs = read_requirements(ROOT)
    os.makedirs(args.dest, exist_ok=True)
    wanted: set[str] = set()
    lines = [(p, py) for p in platforms for py in pythons]
    per_line: dict[tuple[str, str], list[str]] = {line: [] for line in lines}
    missing: dict[tuple[str, str], list[str]] = {line: [] for line in lines}
    failed = False

    for platform, python in lines:
        for req in reqs:
            got = None
            for rung, tags in enumerate(PLATFORMS[platform]):
                with tempfile.TemporaryDirectory() as tmp:
                    ok, log = pip_download(str(req), tags, python, tmp)
                    files = sorted(f for f in os.listdir(tmp) if f.endswith(".whl")) if ok else []
                    for f in files:
                        shutil.copy2(os.path.join(tmp, f), os.path.join(args.dest, f))
                if files:
                    got = files
                    if rung:
                        print(f"  note: {platform}: {req} needs {tags[0]} (newer OS than Blender's minimum)")
                    break
            if got is None:
                missing[platform, python].append(req.name)
                level = "skip" if canonicalize_name(req.name) in OPTIONAL else "ERROR"
                failed |= level == "ERROR"
                print(f"  {level}: no {platform} wheel for {req} (python {python})")
                continue
            for f in got:
                wanted.add(f)
                per_line[platform, python].append(f)

    # Remove wheels left over from older pins.
    for f in sorted(os.listdir(args.dest)):
        if f.endswith(".whl") and f not in wanted:
            os.remove(os.path.join(args.dest, f))
            print(f"  removed stale {f}")

    print("\nWheels per platform and Python:")
    for platform, python in lines:
        files = per_line[platform, python]
        size = sum(os.path.getsize(os.path.join(args.dest, f)) for f in files)
        print(f"- {platform}, python {python}: {len(files)} wheels, {size / 2**20:.1f} MiB"
              + (f"; missing: {', '.join(missing[platform, python])}" if missing[platform, python] else ""))
        for f in files:
            print(f"    {f}")
        problems = check_closure(platform, [os.path.join(args.dest, f) for f in files], python)
        for p in problems:
            print(f"  ERROR: {platform}, python {python}: {p}")
        failed |= bool(problems)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
