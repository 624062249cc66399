"""Photos of the demo office projected back onto its UV maps, against a Cycles bake of the
same lighting (slow: ten 320 x 240 Cycles photos at 32 samples, about 7 minutes of one core,
and a 256-sample bake; both cached).

Truth: ``scenes.bake.bake_lighting`` (DIFFUSE, direct + indirect + colour: the outgoing
radiance of every texel, what a photo shows).  The issue's target: mean CIEDE2000 <= 2.0 over
the texels some camera sees; the texels no camera sees keep colours of their own object.
"""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
pytest.importorskip("cv2")

from relight_addon.core.texture.colour import delta_e_2000, linear_rgb_to_lab  # noqa: E402
from scenes import bake  # noqa: E402
from scenes import capture as sc  # noqa: E402

pytestmark = pytest.mark.slow
SIZE = 48


@pytest.fixture(scope="module")
def office():
    info, result, _, _ = sc.project_office(texture_size=SIZE)
    truth = bake.bake_lighting(dict(info.lamp_powers), samples=256, seed=0, texture_size=SIZE)
    return info, truth, result


def test_projection_against_the_bake(office):
    info, truth, result = office
    des, seen_all, cover_all = [], 0, 0
    for m in result.meshes:
        t = truth[m.name]
        de = delta_e_2000(linear_rgb_to_lab(np.clip(m.texture, 0, None)),
                          linear_rgb_to_lab(np.clip(t, 0, None)))
        des.append(de[m.seen])
        seen_all += int(m.seen.sum())
        cover_all += int(m.covered.sum())
    de = np.concatenate(des)
    assert seen_all > 0.8 * cover_all, (seen_all, cover_all)
    assert de.mean() <= 2.0, de.mean()
    # the photo exposed half a stop brighter (and the one half a stop darker) matched
    np.testing.assert_allclose(result.gains["Photo 3"], 2 ** -0.5, rtol=0.04)
    np.testing.assert_allclose(result.gains["Photo 7"], 2 ** 0.5, rtol=0.04)


def test_hidden_texels_are_holes(office):
    """The floor's texels that no camera sees (Blender's own scene.ray_cast from each texel to
    each camera whose frame holds it, not our occluder) are never painted from a photo: they
    are holes, filled from the floor's seen texels; and most texels Blender says some camera
    sees are seen (all but the bands along the floor's contacts with other objects)."""
    import mathutils
    from bpy_extras.object_utils import world_to_camera_view
    info, truth, result = office
    floor = next(m for m in result.meshes if m.name == "Floor")
    scene = bpy.context.scene
    dg = bpy.context.evaluated_depsgraph_get()
    W, D = sc_room()
    cams = [o for o in scene.objects if o.type == "CAMERA" and o.name.startswith("Photo")]
    visible = np.zeros((SIZE, SIZE), bool)
    for y in range(SIZE):             # one ray per texel and camera: Blender's ray_cast is the truth
        for x in range(SIZE):
            p = mathutils.Vector(((x + 0.5) / SIZE * W, (y + 0.5) / SIZE * D, 1e-4))
            for cam in cams:
                ndc = world_to_camera_view(scene, cam, p)
                if not (0 < ndc.x < 1 and 0 < ndc.y < 1 and ndc.z > 0):
                    continue
                d = cam.matrix_world.translation - p
                hit, *_ = scene.ray_cast(dg, p, d.normalized(), distance=d.length - 1e-4)
                if not hit:
                    visible[y, x] = True
                    break
    assert not (floor.seen & ~visible).any()          # seen only where some camera sees it
    assert (floor.seen & visible).sum() > 0.85 * visible.sum()
    assert (~visible).sum() > 20                      # there are hidden texels (under the table)


def sc_room():
    from scenes.office import ROOM
    return ROOM[0], ROOM[1]
