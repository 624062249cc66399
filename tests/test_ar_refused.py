"""AR mode on a Blender older than 5.0 (the 4.5 LTS line): Set Up AR is refused with one
sentence that names the Blender needed, and the scene is left as it was.  AR writes 5.0's
compositor (relight_addon/blender/ar.py AR_MIN_BLENDER); test_ar_setup.py tests it on 5.x."""
from __future__ import annotations

import pytest

bpy = pytest.importorskip("bpy")

from helpers.ar import HDRIS, ar_module, build, snapshot  # noqa: E402

pytestmark = pytest.mark.skipif("sunrise" not in HDRIS, reason="bundled HDRIs not found")


def test_set_up_ar_says_which_blender_it_needs(tmp_path):
    sc, _ = build(tmp_path)
    reason = ar_module("ar").unsupported_reason()
    if tuple(bpy.app.version) >= (5, 0, 0):
        assert reason is None
        return
    assert reason and "Blender 5.0" in reason and "\n" not in reason
    before = snapshot()
    with pytest.raises(RuntimeError) as info:
        bpy.ops.relight.ar_setup()
    assert "AR mode needs Blender 5.0" in str(info.value)
    assert snapshot() == before
