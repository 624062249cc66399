"""The extension as Blender sees it: manifest validation, the built zip, install and enable.

Uses Blender's own extension CLI from the bpy wheel (tools/blender_ext.py finds it) and installs
the zip into a throw-away user folder (BLENDER_USER_RESOURCES) in a fresh interpreter, so the
developer's own Blender configuration is never touched.

The linux-x64 zip, with its bundled wheels, is built from the current tree into a temp dir, as
`make extension` builds it (a zip left in dist/ may predate the sources).
"""

from __future__ import annotations

import ast
import glob
import json
import os
import shutil
import subprocess
import sys
import textwrap
import tomllib
import zipfile

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BLENDER_EXT = [sys.executable, os.path.join(ROOT, "tools", "blender_ext.py")]
ADDON_ID = "relight"
MODULE = f"bl_ext.user_default.{ADDON_ID}"

bpy = pytest.importorskip("bpy", reason="needs the bpy wheel (make test installs it)")
if sys.platform != "linux":
    pytest.skip("the install test uses the linux-x64 build", allow_module_level=True)

# Inside a real Blender (tests/run_in_blender.py) sys.executable is Blender's Python, which has
# no bpy module: run Blender's CLI script from Blender's own scripts folder and install the
# add-on through the Blender binary. With the bpy wheel, a fresh Python of this venv does both.
IN_BLENDER = bool(bpy.app.binary_path)
CLI_ENV = dict(os.environ, BLENDER_SCRIPTS=bpy.utils.system_resource("SCRIPTS"))

with open(os.path.join(ROOT, "blender_manifest.toml"), "rb") as _fh:
    MANIFEST = tomllib.load(_fh)

# Everything a build copy needs; the build's own exclusion patterns do the rest.
_COPY_IGNORE = shutil.ignore_patterns(
    ".git", ".venv*", "dist", "wheels", "out", ".cache", "__pycache__", ".pytest_cache", "*.zip",
)


def _run(cmd, **kwargs):
    kwargs.setdefault("env", CLI_ENV)
    return subprocess.run(cmd, capture_output=True, text=True, timeout=600, **kwargs)


def _build_linux_zip(tmp_dir: str) -> str:
    """Build the linux-x64 zip as `make extension` does, from a copy of the tree: download the
    linux-x64 wheels (pip's cache makes repeated runs cheap), list them, build split zips."""
    src = os.path.join(tmp_dir, "src")
    shutil.copytree(ROOT, src, ignore=_COPY_IGNORE)
    wheels_dir = os.path.join(src, "wheels")
    proc = _run([sys.executable, os.path.join(ROOT, "tools", "fetch_wheels.py"),
                 "--platform", "linux-x64", "--dest", wheels_dir])
    assert proc.returncode == 0, proc.stdout + proc.stderr
    sys.path.insert(0, os.path.join(ROOT, "tools"))
    try:
        import sync_wheels
    finally:
        sys.path.pop(0)
    sync_wheels.sync(os.path.join(src, "blender_manifest.toml"),
                     [w for w in os.listdir(wheels_dir) if w.endswith(".whl")])
    out = os.path.join(tmp_dir, "dist")
    os.makedirs(out)
    proc = _run([*BLENDER_EXT, "build", "--source-dir", src, "--output-dir", out,
                 "--split-platforms"])
    assert proc.returncode == 0, proc.stdout + proc.stderr
    zips = [z for z in os.listdir(out) if z.endswith("linux_x64.zip")]
    assert len(zips) == 1, os.listdir(out)
    return os.path.join(out, zips[0])


@pytest.fixture(scope="module")
def extension_zip(tmp_path_factory) -> str:
    # Always built from the current tree: a zip left in dist/ may predate the sources.
    return _build_linux_zip(str(tmp_path_factory.mktemp("build")))


def test_manifest_validates():
    proc = _run([*BLENDER_EXT, "validate", ROOT])
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "Success" in proc.stdout


def test_manifest_fields():
    assert MANIFEST["id"] == ADDON_ID
    assert MANIFEST["type"] == "add-on"
    # the range says what is tested: this bpy (4.5 LTS or 5.2, the two lines of `make test`)
    # lies inside it, the maximum exclusive
    version = lambda s: tuple(int(p) for p in s.split("."))  # noqa: E731
    assert version(MANIFEST["blender_version_min"]) <= tuple(bpy.app.version)
    assert tuple(bpy.app.version) < version(MANIFEST["blender_version_max"])
    for reason in MANIFEST.get("permissions", {}).values():
        assert not reason.endswith("."), "Blender rejects permission reasons ending with a period"
    # Never bundle numpy: Blender ships its own and two copies break at import.
    assert not [w for w in MANIFEST.get("wheels", []) if os.path.basename(w).startswith("numpy-")]


def test_zip_contents(extension_zip):
    proc = _run([*BLENDER_EXT, "validate", extension_zip])
    assert proc.returncode == 0, proc.stdout + proc.stderr
    with zipfile.ZipFile(extension_zip) as zf:
        names = zf.namelist()
    for required in ("blender_manifest.toml", "__init__.py", "operators/__init__.py",
                     "panels/__init__.py", "relight_addon/__init__.py"):
        assert required in names
    excluded = ("tests/", "tools/", "benchmarks/", "requirements/", "scenes/", "demo/", ".ci/",
                ".git", ".venv", "dist/", "out/", "Makefile", "README.md")
    leaked = [n for n in names if n.startswith(excluded) or "__pycache__" in n or n.endswith(".pyc")]
    assert not leaked, leaked
    wheels = [n for n in names if n.startswith("wheels/")]
    assert not [w for w in wheels if "numpy" in os.path.basename(w).lower()]
    # every compiled runtime library for both Pythons of the lines (4.5: cp311, 5.x: cp313),
    # or one stable-ABI wheel (abi3) for both
    tags: dict[str, set[str]] = {}
    for w in wheels:
        name, *_, python, abi, _platform = os.path.basename(w)[:-4].split("-")
        tags.setdefault(name.lower(), set()).add("abi3" if abi == "abi3" else python)
    compiled = {n: t for n, t in tags.items() if t != {"py3"}}
    assert compiled.keys() >= {"scipy", "xatlas", "fast_simplification", "pillow", "embreex",
                               "opencv_contrib_python_headless"}, tags
    assert all(t == {"abi3"} or t >= {"cp311", "cp313"} for t in compiled.values()), tags


def _absolute_local_imports(path: str) -> list[str]:
    with open(path, encoding="utf-8") as fh:
        tree = ast.parse(fh.read(), path)
    local = {"relight_addon", "operators", "panels"}
    bad = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names = [node.module]
        else:
            continue
        bad += [f"{os.path.relpath(path, ROOT)}:{node.lineno} {n}" for n in names if n.split(".")[0] in local]
    return bad


def test_extension_imports_are_relative():
    """Blender imports the add-on as bl_ext.<repo>.relight: absolute local imports break there."""
    files = [os.path.join(ROOT, "__init__.py")]
    for sub in ("operators", "panels", "relight_addon/core", "relight_addon/blender"):
        files += glob.glob(os.path.join(ROOT, sub, "**", "*.py"), recursive=True)
    bad = [hit for f in files for hit in _absolute_local_imports(f)]
    assert not bad, bad


_INSTALL_SCRIPT = textwrap.dedent("""
    import json, os, sys
    import bpy

    zip_path, module = sys.argv[sys.argv.index("--") + 1:][:2] if "--" in sys.argv else sys.argv[1:3]
    result = {"repos": [r.module for r in bpy.context.preferences.extensions.repos]}
    result["install"] = sorted(bpy.ops.extensions.package_install_files(
        filepath=zip_path, repo="user_default", enable_on_install=True))
    result["enabled"] = module in bpy.context.preferences.addons
    result["module_file"] = getattr(sys.modules.get(module), "__file__", None)
    result["has_operator"] = hasattr(bpy.ops.relight, "check_dependencies")
    result["has_panel"] = hasattr(bpy.types, "RELIGHT_PT_main")
    result["run"] = sorted(bpy.ops.relight.check_dependencies()) if result["has_operator"] else None
    result["version"] = sys.modules[module + ".panels.main"].addon_version()
    result["operators"] = sorted(op for op in ("precompute", "restore_originals", "clear")
                                 if hasattr(bpy.ops.relight, op))
    # A real Precompute from the installed copy: a textured floor under an area light.
    bpy.ops.mesh.primitive_plane_add(size=2.0)
    floor = bpy.context.active_object
    image = bpy.data.images.new("floor_photo", 8, 8)
    image.pixels.foreach_set([0.5] * (8 * 8 * 4))
    image.pack()
    mat = bpy.data.materials.new("floor_mat")
    mat.use_nodes = True
    tex = mat.node_tree.nodes.new("ShaderNodeTexImage")
    tex.image = image
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    mat.node_tree.links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    floor.data.materials.append(mat)
    bpy.ops.object.light_add(type='AREA', location=(0.0, 0.0, 1.5))
    bpy.context.active_object.data.energy = 50.0
    result["precompute"] = sorted(bpy.ops.relight.precompute(preset="draft"))
    result["relit_material"] = floor.material_slots[0].material.name
    # Wheels are unpacked into <user>/extensions/.local/... while the add-on is enabled.
    user = os.environ["BLENDER_USER_RESOURCES"]
    result["site_packages"] = sorted(
        entry for path in sys.path if path.startswith(user) and os.path.isdir(path)
        for entry in os.listdir(path) if entry.endswith(".dist-info"))
    bpy.ops.preferences.addon_disable(module=module)
    result["after_disable"] = {
        "enabled": module in bpy.context.preferences.addons,
        "has_operator_class": hasattr(bpy.types, "RELIGHT_OT_check_dependencies"),
        "has_panel": hasattr(bpy.types, "RELIGHT_PT_main"),
    }
    print("RESULT " + json.dumps(result))
""")


def test_install_enable_run(extension_zip, tmp_path):
    user = tmp_path / "blender_user"
    user.mkdir()
    script = tmp_path / "install.py"
    script.write_text(_INSTALL_SCRIPT)
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(user))
    env.pop("PYTHONPATH", None)  # the add-on must work from the installed copy alone
    if IN_BLENDER:
        cmd = [bpy.app.binary_path, "-b", "--factory-startup", "--python-exit-code", "1",
               "--python", str(script), "--", extension_zip, MODULE]
    else:
        cmd = [sys.executable, str(script), extension_zip, MODULE]
    proc = _run(cmd, env=env, cwd=str(tmp_path))
    output = proc.stdout + proc.stderr
    assert proc.returncode == 0, output
    line = next((ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")), None)
    assert line is not None, output
    result = json.loads(line[len("RESULT "):])

    assert "user_default" in result["repos"], result
    assert result["install"] == ["FINISHED"], output
    assert result["enabled"], output
    assert result["module_file"].startswith(str(user)), result["module_file"]
    assert result["has_operator"] and result["has_panel"], result
    assert result["run"] == ["FINISHED"], output
    assert "Relight: available:" in output and "ray casting:" in output, output
    assert result["version"] == MANIFEST["version"]
    assert result["operators"] == ["clear", "precompute", "restore_originals"], result
    assert result["precompute"] == ["FINISHED"], output
    assert result["relit_material"] == "floor_mat.relight", result
    assert result["after_disable"] == {"enabled": False, "has_operator_class": False, "has_panel": False}

    # Bundled wheels (when the zip has them) are unpacked into the user site-packages,
    # which Blender puts on sys.path.
    with zipfile.ZipFile(extension_zip) as zf:
        wheels = [os.path.basename(n) for n in zf.namelist() if n.startswith("wheels/") and n.endswith(".whl")]
    installed = {d.split("-")[0].lower() for d in result["site_packages"]}
    expected = {w.split("-")[0].lower() for w in wheels}
    assert expected <= installed, sorted(expected - installed)
    # one copy each: Blender took this Python's wheel of each library, not the other line's
    assert len(result["site_packages"]) == len(installed), result["site_packages"]
