"""Run the pytest suite inside a real Blender (its own Python, its own bpy and numpy).

    blender -b --factory-startup --python-exit-code 1 --python tests/run_in_blender.py [-- PYTEST ARGS]

Arguments after ``--`` go to pytest (default: ``-q -p no:cacheprovider <this folder>``).
Blender's Python has no pytest: install it once into Blender's own interpreter with
``<blender python> -m pip install pytest`` (the interpreter path is printed below when pytest
is missing), together with the test-only packages that some tests use (they skip when absent).
The exit code is pytest's (0 when all passed).
"""

import os
import sys

TESTS = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(TESTS)


def main() -> int:
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    if ROOT not in sys.path:
        sys.path.insert(0, ROOT)
    try:
        import pytest
    except ImportError:
        print(f"pytest is not installed in Blender's Python; run:\n  {sys.executable} -m pip install pytest",
              file=sys.stderr)
        return 2
    os.chdir(ROOT)
    return int(pytest.main(argv or ["-q", "-p", "no:cacheprovider", TESTS]))


if __name__ == "__main__":
    # --python-exit-code only covers uncaught exceptions; sys.exit makes Blender exit with
    # pytest's own code (1 failed, 2 interrupted, 5 no tests ...).
    sys.exit(main())
