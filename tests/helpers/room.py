"""The suite's test room, built in code (factory-empty): a closed 4 x 4 x 3 m room of six
inward-facing planes, each with its own material (UV Map node -> 16 x 16 Image Texture ->
Principled base colour), a 0.8 m box on the floor (one material, one image), two 0.5 m area
lights under the ceiling (``LAMPS``) and a camera."""
import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

TEX = 16                                    # texels a side of each surface's photo
LAMPS = {"LampA": ((-1.0, 0.0, 2.9), 60.0), "LampB": ((1.0, 0.5, 2.9), 30.0)}


def _image(name, seed):
    img = bpy.data.images.new(name, TEX, TEX)
    rng = np.random.default_rng(seed)
    px = np.ones((TEX, TEX, 4), np.float32)
    px[..., :3] = 0.3 + 0.6 * rng.random((TEX, TEX, 3))
    img.pixels.foreach_set(px.reshape(-1))
    return img


def textured_material(name, seed):
    mat = bpy.data.materials.new(name)
    if mat.node_tree is None:
        mat.use_nodes = True
    nt = mat.node_tree
    bsdf = next(n for n in nt.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = _image(name + "_img", seed)
    uvn = nt.nodes.new("ShaderNodeUVMap")
    uvn.uv_map = "UVMap"
    nt.links.new(uvn.outputs["UV"], tex.inputs["Vector"])
    nt.links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    return mat


def mesh_object(name, verts, faces, mat):
    """Faces get non-overlapping UV cells: one face -> the unit square, more -> a 3 x 2 atlas."""
    me = bpy.data.meshes.new(name)
    me.from_pydata([tuple(v) for v in verts], [], [tuple(f) for f in faces])
    uv = me.uv_layers.new(name="UVMap")
    square = np.array([(0, 0), (1, 0), (1, 1), (0, 1)], float)
    for i, poly in enumerate(me.polygons):
        cell = square if len(faces) == 1 else (square + (i % 3, i // 3)) / (3, 2)
        for j, li in enumerate(poly.loop_indices):
            uv.data[li].uv = tuple(cell[j % 4])
    me.materials.append(mat)
    obj = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def _quad(c, n, half):
    """Corners of a square centred at c with normal n (counter-clockwise around n)."""
    c, n = np.asarray(c, float), np.asarray(n, float)
    a = np.array([1.0, 0, 0]) if abs(n[0]) < 0.9 else np.array([0, 1.0, 0])
    u = np.cross(n, a)
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    return [c - half[0] * u - half[1] * v, c + half[0] * u - half[1] * v,
            c + half[0] * u + half[1] * v, c - half[0] * u + half[1] * v]


def build_scene(lamps=True):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    walls = {  # name: (centre, inward normal, half sizes)
        "Floor": ((0, 0, 0), (0, 0, 1), (2, 2)), "Ceiling": ((0, 0, 3), (0, 0, -1), (2, 2)),
        "WallXn": ((-2, 0, 1.5), (1, 0, 0), (1.5, 2)), "WallXp": ((2, 0, 1.5), (-1, 0, 0), (1.5, 2)),
        "WallYn": ((0, -2, 1.5), (0, 1, 0), (2, 1.5)), "WallYp": ((0, 2, 1.5), (0, -1, 0), (2, 1.5)),
    }
    for i, (name, (c, n, half)) in enumerate(walls.items()):
        # _quad's u is n x a: swap the half sizes if the square is not square-ish; all fit.
        verts = _quad(c, n, (max(half), max(half)) if half[0] == half[1] else half)
        mesh_object(name, verts, [(0, 1, 2, 3)], textured_material(name + "_mat", i))
    # Box 0.8 m on the floor, outward normals.
    x0, y0, s = 0.3, 0.2, 0.8
    v = [(x0 + dx * s, y0 + dy * s, dz * s) for dz in (0, 1) for dy in (0, 1) for dx in (0, 1)]
    faces = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    mesh_object("Box", v, faces, textured_material("Box_mat", 10))
    if lamps:
        for name, (loc, power) in LAMPS.items():
            light = bpy.data.lights.new(name, "AREA")
            light.energy = power
            light.size = 0.5
            obj = bpy.data.objects.new(name, light)
            obj.location = loc
            bpy.context.scene.collection.objects.link(obj)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.location = (0, -1.5, 1.5)
    bpy.context.scene.collection.objects.link(cam)
    bpy.context.scene.camera = cam
    bpy.context.view_layer.update()
