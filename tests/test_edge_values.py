"""Values at the edge (issue 44: 4, 5, 9): handled, or refused with a sentence naming the light
or material, through the operators on the test room of ``helpers.room`` at draft.

Truth: at the photo's powers the relit room is the photo (whatever the units or the lamps)."""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from helpers.blender import addon_module, pixels, relit_now, relit_state  # noqa: E402


def _photo(name):
    from relight_addon.core.texture.colour import srgb_to_linear
    img = bpy.data.materials[f"{name}_mat"].node_tree.nodes.get("Image Texture")
    px = pixels(img.image)[..., :3].astype(np.float64)
    return px if img.image.is_float else srgb_to_linear(px)


def _float_photos(scale):
    """Every photo as a float image (linear) times ``scale``: photos in absolute units."""
    from relight_addon.core.texture.colour import srgb_to_linear
    for mat in bpy.data.materials:
        node = mat.node_tree.nodes.get("Image Texture")
        if node is None or node.image is None:
            continue
        src = node.image
        px = pixels(src).copy()
        px[..., :3] = srgb_to_linear(px[..., :3]) * scale
        img = bpy.data.images.new(src.name + " float", src.size[0], src.size[1],
                                  float_buffer=True)
        img.colorspace_settings.name = "Linear Rec.709"
        img.pixels.foreach_set(px.ravel())
        node.image = img


def test_photos_beyond_half_floats_are_not_clipped(test_room):
    """Photos in absolute units (every texel x 1e5): the textures are stored as 32-bit float and
    the user is told; the relit floor is the photo (was 0.927 of it: half floats end at
    65504)."""
    _float_photos(1e5)
    assert bpy.ops.relight.precompute(preset="draft") == {"FINISHED"}
    for name in ("Floor", "Ceiling"):
        got, want = relit_now(name), _photo(name)
        assert got.mean() / want.mean() == pytest.approx(1.0, abs=2e-3), name
    st = addon_module("relight_addon.blender.state").status(bpy.context.scene)
    assert any("65504" in w and "32-bit" in w for w in st["warnings"])


def test_a_very_bright_sun_leaves_the_rest_of_the_room_lit(test_room):
    """A 1e9 W/m^2 sun beside 60 W lamps: at the photo's powers every surface is the photo
    (the box and the ceiling rendered black: the maps' floor was relative to the sunlit
    texels)."""
    sun = bpy.data.lights.new("Sun", "SUN")
    sun.energy = 1e9
    obj = bpy.data.objects.new("Sun", sun)
    obj.rotation_euler = (0.3, 0.2, 0.0)
    bpy.context.scene.collection.objects.link(obj)
    assert bpy.ops.relight.precompute(preset="draft") == {"FINISHED"}
    for name in ("Floor", "Ceiling", "WallXn"):
        got, want = relit_now(name), _photo(name)
        assert got.mean() / want.mean() == pytest.approx(1.0, abs=2e-3), name
    assert np.isfinite(relit_now("Box")).all()


def test_a_very_bright_narrow_area_light_is_refused_naming_both_ends(test_room):
    """A 1e9 W area light of spread 5 degrees beside the 60 W and 30 W lamps (the box and the
    ceiling rendered black): refused, naming the weak lamps and the strong one (either may be
    the slip); with the area light at a power of the others' order the room is the photo."""
    area = bpy.data.lights.new("Spot", "AREA")
    area.energy = 1e9
    area.size = 0.2
    area.spread = np.radians(5.0)
    obj = bpy.data.objects.new("Spot", area)
    obj.location = (-1.2, -1.2, 2.9)
    bpy.context.scene.collection.objects.link(obj)
    with pytest.raises(RuntimeError, match=r"Light 'LampB' is set to 30 W, 3e-08 of 'Spot' "
                                           r"\(1e\+09 W\)"):
        bpy.ops.relight.precompute(preset="draft")
    area.energy = 500.0
    assert bpy.ops.relight.precompute(preset="draft") == {"FINISHED"}
    for name in ("Floor", "Ceiling", "WallXn"):
        got, want = relit_now(name), _photo(name)
        assert got.mean() / want.mean() == pytest.approx(1.0, abs=2e-3), name
    assert np.isfinite(relit_now("Box")).all()


@pytest.mark.parametrize("power, says", [
    (1e-9, "Light 'LampB' is set to 1e-09 W"),
    (float("inf"), "Light 'LampB' has power inf"),
    (-5.0, "Light 'LampB' has power -5"),
])
def test_lamp_powers_at_the_edge_are_refused_naming_the_light(test_room, power, says):
    before = relit_state()
    bpy.data.lights["LampB"].energy = power
    with pytest.raises(RuntimeError, match=says):
        bpy.ops.relight.precompute(preset="draft")
    assert relit_state() == before


def test_an_infinite_emission_is_refused_naming_the_material(test_room):
    mat = bpy.data.objects["Box"].material_slots[0].material
    bsdf = next(n for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
    bsdf.inputs["Emission Strength"].default_value = float("inf")
    before = relit_state()
    with pytest.raises(RuntimeError, match="Material 'Box_mat': its Emission Strength is 3.4"):
        bpy.ops.relight.precompute(preset="draft")
    assert relit_state() == before


def test_a_dimmed_lamp_is_no_edge_after_precompute(test_room):
    """After Precompute a lamp may go to any power 0 or more: the drivers follow it."""
    assert bpy.ops.relight.precompute(preset="draft") == {"FINISHED"}
    bpy.data.lights["LampB"].energy = 1e-9
    assert bpy.ops.relight.update() == {"FINISHED"}
    assert np.isfinite(relit_now("Floor")).all()
