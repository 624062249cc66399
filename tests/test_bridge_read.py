"""The bpy -> SceneData reader (relight_addon/blender/read.py), with Blender as a Python module.

The lamp conventions (every light type's power -> exitance, intensity or irradiance; emission
strength -> exitance on both sides) are checked against tiny Cycles renders: an orthographic
camera looks straight down at a white diffuse 2 x 2 m plane, so each pixel of the render is the
plane's radiance E / pi over the pixel.  Our prediction is the core's lamp_irradiance (lamp
patches and lights) of the scene read_scene returns; Cycles is the independent reference.
"""
import math
import os
import struct
import tempfile
import zlib

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from relight_addon.blender.read import read_scene  # noqa: E402
from relight_addon.core.scene import quad_area_normal  # noqa: E402

N = 32  # render resolution


@pytest.fixture(autouse=True)
def fresh():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    yield


def link(obj):
    bpy.context.scene.collection.objects.link(obj)
    return obj


def mesh_object(name, verts, faces, location=(0, 0, 0)):
    me = bpy.data.meshes.new(name)
    me.from_pydata([tuple(v) for v in verts], [], [tuple(f) for f in faces])
    me.update()
    obj = link(bpy.data.objects.new(name, me))
    obj.location = location
    return obj


def area_light(name, shape, size, size_y=None, power=100.0, location=(0, 0, 1), rotation=(0, 0, 0),
               scale=(1, 1, 1)):
    light = bpy.data.lights.new(name, "AREA")
    light.shape = shape
    light.size = size
    if size_y is not None:
        light.size_y = size_y
    light.energy = power
    obj = link(bpy.data.objects.new(name, light))
    obj.location, obj.rotation_euler, obj.scale = location, rotation, scale
    obj.visible_camera = False
    return obj


def material(name, base=(0.8, 0.8, 0.8), emission=None, strength=0.0):
    mat = bpy.data.materials.new(name)
    tree = mat.node_tree
    if tree is None:  # Blender < 5
        mat.use_nodes = True
        tree = mat.node_tree
    tree.nodes.clear()
    out = tree.nodes.new("ShaderNodeOutputMaterial")
    bsdf = tree.nodes.new("ShaderNodeBsdfPrincipled")
    bsdf.inputs["Base Color"].default_value = (*base, 1.0)
    if emission is not None:
        bsdf.inputs["Emission Color"].default_value = (*emission, 1.0)
        bsdf.inputs["Emission Strength"].default_value = strength
    tree.links.new(bsdf.outputs[0], out.inputs["Surface"])
    return mat, tree, bsdf


def write_png(path, arr, bits=8):
    """Minimal PNG writer (RGB), row 0 = top of the image."""
    h, w, _ = arr.shape
    dt = ">u2" if bits == 16 else "u1"
    raw = b"".join(b"\x00" + np.ascontiguousarray(arr[y]).astype(dt).tobytes() for y in range(h))

    def chunk(tag, data):
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)

    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, bits, 2, 0, 0, 0))
                + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))


def srgb_decode(x):
    x = np.asarray(x, float)
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


# -- geometry ----------------------------------------------------------------------------------

def test_cube_world_space_outward_area():
    bpy.ops.mesh.primitive_cube_add(size=2.0, location=(1.0, -2.0, 0.5), rotation=(0.3, 0.2, 0.1),
                                    scale=(1.0, 2.0, 0.5))
    link(bpy.data.objects.new("lamp", bpy.data.lights.new("lamp", "AREA"))).location = (0, 0, 5)
    cube = bpy.context.active_object
    scene, report = read_scene(bpy.context)
    geo = ~(scene.lamp >= 0)
    assert geo.sum() == 6 and report.quads == 6 and report.faces == 6 and report.objects == 1
    corners = scene.corners[geo]
    m = np.array(cube.matrix_world)
    local = np.array([v.co[:] for v in cube.data.vertices])
    world = local @ m[:3, :3].T + m[:3, 3]
    # every corner is one of the cube's world-space vertices
    d = np.linalg.norm(corners.reshape(-1, 1, 3) - world[None], axis=-1).min(axis=1)
    assert d.max() < 1e-5
    area, normal = quad_area_normal(corners)
    centre = corners.mean(axis=1)
    assert np.all(np.einsum("ij,ij->i", normal, centre - m[:3, 3]) > 0)  # outward
    a, b, c = 2.0, 4.0, 1.0
    assert area.sum() == pytest.approx(2 * (a * b + b * c + c * a), rel=1e-5)
    assert report.viewpoint is None and any("camera" in w for w in report.warnings)


def test_mirrored_object_keeps_faces_outward():
    bpy.ops.mesh.primitive_cube_add(size=2.0, location=(1.0, 2.0, 3.0))
    cube = bpy.context.active_object
    cube.scale = (-1.0, 1.0, 2.0)
    area_light("L", "SQUARE", 1.0, location=(0, 0, 8))
    scene, _ = read_scene(bpy.context)
    geo = scene.lamp < 0
    _, normal = quad_area_normal(scene.corners[geo])
    assert np.all(np.einsum("ij,ij->i", normal, scene.corners[geo].mean(axis=1) - [1.0, 2.0, 3.0]) > 0)


def test_collection_instances_are_read():
    coll = bpy.data.collections.new("props")
    me = bpy.data.meshes.new("tile")
    me.from_pydata([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], [], [(0, 1, 2, 3)])
    coll.objects.link(bpy.data.objects.new("tile", me))  # not linked to the scene itself
    for i, x in enumerate([0.0, 5.0]):
        empty = link(bpy.data.objects.new(f"inst{i}", None))
        empty.instance_type = "COLLECTION"
        empty.instance_collection = coll
        empty.location = (x, 0.0, 1.0)
        empty.scale = (2.0, 2.0, 2.0)
    bpy.data.objects["inst1"]["relight_role"] = "ignored"
    area_light("L", "SQUARE", 1.0, location=(0, 0, 8))
    scene, report = read_scene(bpy.context)
    geo = scene.lamp < 0
    assert geo.sum() == 1 and report.objects == 1
    assert np.allclose(scene.corners[geo][0], [[0, 0, 1], [2, 0, 1], [2, 2, 1], [0, 2, 1]])
    assert report.groups[scene.group[geo][0]][0] == "inst0/tile"
    assert report.ignored_objects == ["inst1/tile"]


def test_subdivision_modifier_is_applied_and_original_untouched():
    bpy.ops.mesh.primitive_cube_add(size=2.0)
    cube = bpy.context.active_object
    mod = cube.modifiers.new("subsurf", "SUBSURF")
    mod.levels = 2
    mod.render_levels = 2
    link(bpy.data.objects.new("lamp", bpy.data.lights.new("lamp", "AREA"))).location = (0, 0, 5)
    scene, report = read_scene(bpy.context)
    assert report.faces == 96 and report.quads == 96
    # SceneData splits the non-planar subdivided quads in two
    assert 96 <= (scene.lamp < 0).sum() <= 192
    assert quad_area_normal(scene.corners[scene.lamp < 0])[0].sum() < 24.0  # shrunk by subdivision
    assert len(cube.data.polygons) == 6 and len(cube.data.vertices) == 8
    assert len(bpy.data.meshes) == 1


def test_ngon_split_into_triangles():
    bpy.ops.mesh.primitive_circle_add(vertices=32, radius=1.0, fill_type="NGON")
    link(bpy.data.objects.new("lamp", bpy.data.lights.new("lamp", "AREA"))).location = (0, 0, 5)
    scene, report = read_scene(bpy.context)
    geo = scene.lamp < 0
    assert report.ngons_split == 1 and report.ngon_triangles == 30 and geo.sum() == 30
    area, normal = quad_area_normal(scene.corners[geo])
    assert area.sum() == pytest.approx(16 * math.sin(2 * math.pi / 32), rel=1e-5)
    assert np.allclose(normal, [0, 0, 1], atol=1e-6)  # circle faces +Z
    assert np.all(scene.corners[geo][:, 2] == scene.corners[geo][:, 3])


# -- lamps -------------------------------------------------------------------------------------

@pytest.mark.parametrize("shape,size,size_y,area", [
    ("SQUARE", 0.8, None, 0.64),
    ("RECTANGLE", 0.8, 0.5, 0.4),
    ("DISK", 0.8, None, math.pi * 0.16),
    ("ELLIPSE", 0.8, 0.5, math.pi * 0.4 * 0.25),
])
def test_area_light_polygons(shape, size, size_y, area):
    rot = (0.4, -0.3, 0.7)
    obj = area_light("L", shape, size, size_y, power=60.0, location=(0.5, 0.2, 2.0), rotation=rot,
                     scale=(1.5, 1.0, 1.0))
    scene, report = read_scene(bpy.context)
    assert report.lamps == 1 and scene.lamp_names == ["L"] and report.errors == []
    a, n = quad_area_normal(scene.corners)
    assert a.sum() == pytest.approx(1.5 * area, rel=1e-6)
    facing = -np.array(obj.matrix_world)[:3, 2]
    facing /= np.linalg.norm(facing)
    assert np.allclose(n, facing, atol=1e-6)
    assert not scene.occluder.any() and np.all(scene.lamp == 0)
    assert np.allclose(scene.emission, 60.0 / (1.5 * area))
    assert np.allclose(scene.corners.reshape(-1, 3).mean(axis=0), obj.location, atol=1e-6)


def test_light_nodes_warned_only_when_they_change_the_light():
    """Blender 5.x gives every new light a node tree (a white, strength-1 Emission): that one is
    no warning; a tree that changes the light (here its strength) is, as it is ignored."""
    mesh_object("floor", [(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)], [(0, 1, 2, 3)])
    plain = bpy.data.lights.new("plain", "POINT")
    plain.energy = 10.0
    link(bpy.data.objects.new("plain", plain))
    noded = bpy.data.lights.new("noded", "POINT")
    noded.energy = 10.0
    noded.use_nodes = True                    # 4.5: no tree before this; 5.x: on already
    emit = next(n for n in noded.node_tree.nodes if n.bl_idname == "ShaderNodeEmission")
    emit.inputs["Strength"].default_value = 2.0
    link(bpy.data.objects.new("noded", noded))
    _, report = read_scene(bpy.context)
    nodes = [w for w in report.warnings if "light nodes" in w]
    assert nodes == ["Light 'noded': light nodes are ignored"], report.warnings


def test_lamps_of_every_type_and_lamps_off():
    """Point and sun lights become core Lights, area lights patches (or Lights with a spread);
    a lamp at 0 W is kept, off in the photo, at a reference power of 1 W."""
    from relight_addon.core.lights import POINT, SUN
    for name, kind in (("P", "POINT"), ("S", "SUN")):
        light = bpy.data.lights.new(name, kind)
        light.energy = 0.0
        link(bpy.data.objects.new(name, light))
    mesh_object("floor", [(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)], [(0, 1, 2, 3)])
    dark = area_light("dark", "SQUARE", 1.0, power=0.0)
    scene, report = read_scene(bpy.context)
    assert report.lamps == 3 and sorted(scene.lamp_names) == ["P", "S", "dark"]
    assert scene.lamp_intensity.tolist() == [0.0, 0.0, 0.0]
    assert sorted(scene.lights.kind.tolist()) == [POINT, SUN]
    assert all(src["power_ref"] == 1.0 for src in report.lamp_sources)
    assert np.allclose(scene.emission[scene.lamp >= 0], 1.0)       # 1 W over 1 m^2
    assert any("'dark'" in w and "off" in w for w in report.warnings)
    # with every lamp off there is nothing the photo can be explained by
    assert report.errors and "Every lamp is off" in report.errors[0]
    assert scene.n_patches == 2           # the floor and the off area lamp


def _render_setup():
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    sc.cycles.device = "CPU"
    sc.cycles.samples = 64
    sc.cycles.use_denoising = False
    sc.cycles.use_adaptive_sampling = False
    sc.cycles.max_bounces = 0
    sc.cycles.pixel_filter_type = "BOX"
    sc.cycles.filter_width = 1.0
    sc.render.resolution_x = sc.render.resolution_y = N
    sc.render.resolution_percentage = 100
    sc.render.threads_mode = "FIXED"
    sc.render.threads = 2
    sc.view_settings.view_transform = "Standard"
    sc.view_settings.look = "None"
    sc.render.image_settings.file_format = "OPEN_EXR"
    sc.render.image_settings.color_depth = "32"
    cam = bpy.data.cameras.new("cam")
    cam.type = "ORTHO"
    cam.ortho_scale = 2.0
    co = link(bpy.data.objects.new("cam", cam))
    co.location = (0, 0, 5)
    sc.camera = co
    floor = mesh_object("floor", [(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)], [(0, 1, 2, 3)])
    mat = bpy.data.materials.new("white")
    tree = mat.node_tree
    if tree is None:
        mat.use_nodes = True
        tree = mat.node_tree
    tree.nodes.clear()
    diffuse = tree.nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Color"].default_value = (1, 1, 1, 1)
    tree.links.new(diffuse.outputs[0], tree.nodes.new("ShaderNodeOutputMaterial").inputs["Surface"])
    floor.data.materials.append(mat)
    return sc


def _cycles_irradiance(sc):
    """Irradiance (W/m^2, RGB) at the N x N pixel centres of the floor, from a Cycles render."""
    path = os.path.join(tempfile.mkdtemp(prefix="relight_read_"), "out.exr")
    sc.render.filepath = path
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(path)
    buf = np.empty(N * N * 4, np.float32)
    img.pixels.foreach_get(buf)
    bpy.data.images.remove(img)
    os.remove(path)
    return math.pi * buf.reshape(N, N, 4)[..., :3].astype(float)  # radiance of white diffuse = E/pi


def _our_irradiance(scene):
    """Unoccluded direct irradiance at the pixel centres of the floor from every lamp (patches
    and lights), averaged over a 3 x 3 grid in each pixel as the render's box filter does."""
    from relight_addon.core.relight.direct import lamp_irradiance
    sub = (np.arange(3) + 0.5) / 3
    c = (np.arange(N)[:, None] + sub[None]).ravel() * 2.0 / N - 1.0
    x, y = np.meshgrid(c, c)  # row = +y (Blender images start at the bottom), column = +x
    pts = np.stack([x, y, np.zeros_like(x)], -1).reshape(N, 3, N, 3, 3)
    pts = pts.transpose(0, 2, 1, 3, 4).reshape(N * N, 9, 3)
    up = np.tile([0.0, 0.0, 1.0], (N * N, 1))
    U, _ = lamp_irradiance(scene, pts, up, rays=256)
    return U.sum(axis=1).reshape(N, N, 3)


def _point_like(kind):
    light = bpy.data.lights.new(kind, "SPOT" if kind.startswith("SPOT") else "POINT")
    light.energy = 60.0
    light.color = (1.0, 0.7, 0.4)
    if kind == "POINT_RADIUS":
        light.shadow_soft_size = 0.3
    if kind.startswith("SPOT"):
        light.spot_size = math.radians(70)
        light.spot_blend = 0.4
        light.shadow_soft_size = 0.1 if kind == "SPOT_RADIUS" else 0.0
    obj = link(bpy.data.objects.new(kind, light))
    obj.location = (0.2, -0.15, 0.7)
    obj.rotation_euler = (0.3, -0.2, 0.4)
    obj.scale = (1.0, 1.4, 1.0)              # an elliptic cone for the spot
    return obj


@pytest.mark.parametrize("kind", ["RECTANGLE", "ELLIPSE", "EMISSIVE", "EMISSIVE_BACK",
                                  "UNNORMALIZED", "MIRRORED", "SPREAD", "POINT", "POINT_RADIUS",
                                  "SPOT", "SPOT_RADIUS", "SUN"])
def test_exitance_matches_cycles(kind):
    """Every light type as read (and computed by lamp_irradiance) against a Cycles render of a
    white floor under it: the totals within 3 %, pixel by pixel within 5 % where well lit."""
    sc = _render_setup()
    if kind.startswith("EMISSIVE"):
        quad = np.array([(-0.3, -0.2, 0.9), (0.35, -0.2, 0.9), (0.35, 0.3, 0.9), (-0.3, 0.3, 0.9)])
        if kind == "EMISSIVE":
            quad = quad[::-1]            # faces the floor; EMISSIVE_BACK lights it with its back
        em = mesh_object("emitter", quad, [(0, 1, 2, 3)])
        em.visible_camera = False
        mat, _, _ = material("glow", base=(0, 0, 0), emission=(1.0, 0.6, 0.3), strength=4.0)
        em.data.materials.append(mat)
    elif kind.startswith(("POINT", "SPOT")):
        _point_like(kind)
    elif kind == "SUN":
        light = bpy.data.lights.new("Sun", "SUN")
        light.energy = 3.0
        light.angle = math.radians(10)
        obj = link(bpy.data.objects.new("Sun", light))
        obj.rotation_euler = (0.5, 0.3, 0.0)
    else:
        shape = "ELLIPSE" if kind == "ELLIPSE" else "RECTANGLE"
        obj = area_light("L", shape, 0.7, 0.4, power=80.0, location=(0.15, -0.1, 0.8),
                         rotation=(0.25, -0.2, 0.5), scale=(1.2, 1.0, 1.0))
        obj.data.color = (1.0, 0.5, 0.25)
        if hasattr(obj.data, "exposure"):              # Blender 4.3+
            obj.data.exposure = 0.5
        if kind == "UNNORMALIZED":
            if not hasattr(obj.data, "normalize"):       # Blender 4.3+
                pytest.skip("this Blender has no unnormalized light power")
            obj.data.normalize = False
        if kind == "MIRRORED":  # negative scale: Cycles emits along the transformed -Z axis
            obj.rotation_euler = (math.pi + 0.25, -0.2, 0.5)
            obj.scale = (1.2, 1.0, -1.0)
        if kind == "SPREAD":
            obj.data.spread = math.radians(70)
    scene, report = read_scene(bpy.context)
    assert report.lamps == 1 and report.errors == []
    if kind.startswith("EMISSIVE"):
        assert report.emissive_faces == 1 and scene.lamp_names == ["emitter/glow"]
        assert not any("glow" in w for w in report.warnings)
        assert (scene.lamp == 0).sum() == 2                  # both sides emit
        assert np.allclose(scene.emission[scene.lamp == 0], np.pi * 4.0 * np.array([1.0, 0.6, 0.3]))
    ours = _our_irradiance(scene)
    cycles = _cycles_irradiance(sc)
    assert ours.sum() > 0
    ratio = cycles.sum(axis=(0, 1)) / ours.sum(axis=(0, 1))
    assert np.allclose(ratio, 1.0, atol=0.03), ratio
    # and pixel by pixel where the floor is well lit (Monte Carlo noise of 64 samples)
    lit = ours[..., 0] > 0.3 * ours[..., 0].max()
    assert np.median(np.abs(cycles[lit, 0] / ours[lit, 0] - 1)) < 0.05


# -- materials, images, UVs --------------------------------------------------------------------

def _quad_with_two_uv_maps():
    obj = mesh_object("card", [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], [(0, 1, 2, 3)])
    me = obj.data
    a = me.uv_layers.new(name="UVA")
    b = me.uv_layers.new(name="UVB")
    a.uv.foreach_set("vector", np.array([0, 0, 1, 0, 1, 1, 0, 1], np.float32))
    b.uv.foreach_set("vector", np.array([0.1, 0.2, 0.3, 0.2, 0.3, 0.4, 0.1, 0.4], np.float32))
    a.active_render = True
    return obj


def test_base_colour_and_clamp():
    obj = mesh_object("card", [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], [(0, 1, 2, 3)])
    mat, _, _ = material("plain", base=(0.2, 0.5, 1.0))
    obj.data.materials.append(mat)
    area_light("L", "SQUARE", 1.0, location=(0, 0, 3))
    scene, report = read_scene(bpy.context)
    geo = scene.lamp < 0
    assert np.allclose(scene.rho[geo], [[0.2, 0.5, 0.99]])
    assert any("No image texture on material 'plain'" in w for w in report.warnings)
    assert report.groups[scene.group[geo][0]] == ("card", "plain")


@pytest.mark.parametrize("bits", [8, 16])
def test_image_mean_linear_and_uv_map(tmp_path, bits):
    values = np.array([[[128, 255, 64], [10, 200, 30]], [[250, 0, 90], [40, 60, 80]]], np.uint16)
    path = str(tmp_path / f"tex{bits}.png")
    write_png(path, values * (257 if bits == 16 else 1), bits)
    obj = _quad_with_two_uv_maps()
    mat, tree, bsdf = material("photo", base=(0.5, 0.5, 0.5))
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image = bpy.data.images.load(path)
    uvnode = tree.nodes.new("ShaderNodeUVMap")
    uvnode.uv_map = "UVB"
    tree.links.new(uvnode.outputs["UV"], tex.inputs["Vector"])
    tree.links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    obj.data.materials.append(mat)
    area_light("L", "SQUARE", 1.0, location=(0, 0, 3))
    scene, report = read_scene(bpy.context)
    geo = np.flatnonzero(scene.lamp < 0)
    expected = srgb_decode(values / 255.0).reshape(-1, 3).mean(axis=0)
    assert np.allclose(scene.rho[geo[0]], expected, atol=2e-3)
    assert np.allclose(scene.uv[geo[0]], [[0.1, 0.2], [0.3, 0.2], [0.3, 0.4], [0.1, 0.4]], atol=1e-6)
    assert scene.image[geo[0]] == 0 and len(scene.images) == 1
    tx = scene.images[0].texels
    assert tx.shape == (2, 2, 3)
    # Blender rows start at the bottom: the PNG's top row is texel row 1
    assert np.allclose(tx[1, 0], srgb_decode(values[0, 0] / 255.0), atol=2e-3)
    assert not any("photo" in w for w in report.warnings)


def test_active_render_uv_map_without_uv_node(tmp_path):
    path = str(tmp_path / "t.png")
    write_png(path, np.full((1, 1, 3), 100, np.uint16))
    obj = _quad_with_two_uv_maps()
    mat, tree, bsdf = material("photo")
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image = bpy.data.images.load(path)
    tree.links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    obj.data.materials.append(mat)
    area_light("L", "SQUARE", 1.0, location=(0, 0, 3))
    scene, _ = read_scene(bpy.context)
    geo = np.flatnonzero(scene.lamp < 0)
    assert np.allclose(scene.uv[geo[0]], [[0, 0], [1, 0], [1, 1], [0, 1]])


# -- bad input ---------------------------------------------------------------------------------

def test_image_without_uv_map_and_missing_file(tmp_path):
    path = str(tmp_path / "t.png")
    write_png(path, np.full((1, 1, 3), 100, np.uint16))
    a = mesh_object("no_uv", [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], [(0, 1, 2, 3)])
    mat, tree, bsdf = material("photo")
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image = bpy.data.images.load(path)
    tree.links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    a.data.materials.append(mat)

    b = mesh_object("lost", [(0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)], [(0, 1, 2, 3)])
    b.data.uv_layers.new(name="UVMap")
    mat2, tree2, bsdf2 = material("gone", base=(0.3, 0.3, 0.3))
    tex2 = tree2.nodes.new("ShaderNodeTexImage")
    img = bpy.data.images.new("gone.png", 4, 4)
    img.source = "FILE"
    img.filepath = str(tmp_path / "does_not_exist.png")
    tex2.image = img
    tree2.links.new(tex2.outputs["Color"], bsdf2.inputs["Base Color"])
    b.data.materials.append(mat2)
    area_light("L", "SQUARE", 1.0, location=(0, 0, 3))
    scene, report = read_scene(bpy.context)
    assert any("No UV map on object 'no_uv'" in w for w in report.warnings)
    assert any("'gone.png'" in w and "missing" in w for w in report.warnings)
    rho_lost = scene.rho[scene.group == report.groups.index(("lost", "gone"))]
    assert np.allclose(rho_lost, 0.3)


def test_zero_area_faces_counted():
    verts = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (2, 0, 0), (3, 0, 0), (4, 0, 0)]
    mesh_object("bad", verts, [(0, 1, 2, 3), (4, 5, 6)])
    area_light("L", "SQUARE", 1.0, location=(0, 0, 3))
    scene, report = read_scene(bpy.context)
    assert report.zero_area_skipped == 1 and report.faces == 2
    assert (scene.lamp < 0).sum() == 1
    assert any("zero-area" in w for w in report.warnings)


def test_roles_and_hidden_objects():
    quad = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]
    mesh_object("relit", quad, [(0, 1, 2, 3)])
    occ = mesh_object("blocker", quad, [(0, 1, 2, 3)], location=(0, 0, 1))
    occ["relight_role"] = "occluder"
    ign = mesh_object("skip", quad, [(0, 1, 2, 3)], location=(0, 0, 2))
    ign["relight_role"] = "ignored"
    hid = mesh_object("hidden", quad, [(0, 1, 2, 3)], location=(0, 0, 3))
    hid.hide_render = True
    other = mesh_object("by_arg", quad, [(0, 1, 2, 3)], location=(0, 0, 4))
    area_light("L", "SQUARE", 1.0, location=(0, 0, 6))
    scene, report = read_scene(bpy.context, roles={"by_arg": "ignored"})
    names = {report.groups[g][0] for g in scene.group}
    assert names == {"relit", "blocker", "L"}
    assert set(report.ignored_objects) == {"skip", "hidden", "by_arg"}
    blocker = scene.group == [i for i, g in enumerate(report.groups) if g[0] == "blocker"][0]
    assert np.all(scene.rho[blocker] == 0) and np.all(scene.occluder[blocker])
    assert other.name == "by_arg"


def test_camera_viewpoint_and_solver_runs():
    from relight_addon.core.radiosity.precompute import solve_radiosity

    bpy.ops.mesh.primitive_plane_add(size=2.0)
    cam = link(bpy.data.objects.new("cam", bpy.data.cameras.new("cam")))
    cam.location = (1.0, 2.0, 3.0)
    bpy.context.scene.camera = cam
    area_light("L", "DISK", 0.5, power=10.0, location=(0, 0, 1))
    scene, report = read_scene(bpy.context)
    assert report.viewpoint == pytest.approx((1.0, 2.0, 3.0))
    assert np.allclose(scene.viewpoint, [1, 2, 3])
    scene2, report2 = read_scene(bpy.context.scene)  # a Scene works as well as a Context
    assert np.allclose(scene2.corners, scene.corners) and report2.viewpoint == report.viewpoint
    sol = solve_radiosity(scene, "draft")
    b = sol.patch_radiosity()
    assert np.all(np.isfinite(b)) and b[scene.lamp < 0].max() > 0


def test_emission_kept_on_the_front_by_a_backfacing_mix_is_one_sided():
    quad = [(-0.3, -0.2, 0.9), (0.35, -0.2, 0.9), (0.35, 0.3, 0.9), (-0.3, 0.3, 0.9)]
    em = mesh_object("panel", quad, [(0, 1, 2, 3)])
    mat = bpy.data.materials.new("front glow")
    tree = mat.node_tree
    if tree is None:
        mat.use_nodes = True
        tree = mat.node_tree
    tree.nodes.clear()
    out = tree.nodes.new("ShaderNodeOutputMaterial")
    emit = tree.nodes.new("ShaderNodeEmission")
    emit.inputs["Strength"].default_value = 5.0
    geo = tree.nodes.new("ShaderNodeNewGeometry")
    black = tree.nodes.new("ShaderNodeBsdfDiffuse")
    mix = tree.nodes.new("ShaderNodeMixShader")
    tree.links.new(geo.outputs["Backfacing"], mix.inputs["Fac"])
    tree.links.new(emit.outputs[0], mix.inputs[1])
    tree.links.new(black.outputs[0], mix.inputs[2])
    tree.links.new(mix.outputs[0], out.inputs["Surface"])
    em.data.materials.append(mat)
    scene, report = read_scene(bpy.context)
    assert report.lamps == 1 and (scene.lamp == 0).sum() == 1
    assert np.allclose(scene.emission[scene.lamp == 0], np.pi * 5.0)
