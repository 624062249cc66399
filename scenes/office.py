"""A small photographed-office generator with known albedo (the shadow-free-texture harness).

Two halves:

* ``office_geometry(seed, n_lamps, texture_size, variant)`` -> :class:`OfficeData`: plain numpy,
  no bpy.  Surface objects as lists of planar quads (world corners, counter-clockwise around the
  outward/visible normal, and the UV rectangle each quad occupies), the TRUE ALBEDO image of each
  object (linear RGB, ``(H, W, 3)`` float32, row 0 at v = 0 as in Blender's ``Image.pixels``),
  and the rectangular ceiling lamps (centre, size, power).  The bpy-free core and its tests can
  use it directly.
* ``build_office(...)`` -> :class:`OfficeInfo`: creates that scene in the current (empty) bpy
  scene: one mesh object per surface (floor, ceiling, 4 walls, table, boxes), each with its own
  material (Principled BSDF, roughness 1, specular 0, Base Color <- Image Texture holding the
  albedo as a float, linear, packed image), RECTANGLE area lights "Lamp A", "Lamp B", ... just
  under the ceiling facing down, and a camera looking into the room.

Room: x in [0, 5], y in [0, 4], z in [0, 2.8] (metres), room faces point inward.  UVs: walls,
floor and ceiling are single quads covering [0, 1]^2; the table and boxes are atlases of their
visible box faces in a grid of cells, each face inset by one texel so that faces never share a
texel (no overlaps).  Box bottoms resting on the floor and leg tops hidden under the slab are
left out (they receive no light and are never seen).

Lamp power: 1.2 x 0.6 m lamps of DEFAULT_LAMP_POWER * 2 / n_lamps W each (Blender, Normalize
on: exitance P / A).  With 2 lamps of 40 W the Cycles DIFFUSE bakes of the floor have mean 0.31,
5th-95th percentiles 0.05-0.62 (see bake.py for the unit factor: the bake is albedo x
irradiance / pi, i.e. outgoing radiance; radiosity = pi x bake).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

ROOM = (5.0, 4.0, 2.8)
LAMP_SIZE = (1.2, 0.6)
DEFAULT_LAMP_POWER = 40.0  # W per lamp (Normalize on)
LAMP_GAP = 0.02            # lamps hang this far under the ceiling
LAMP_LETTERS = "ABCDEFGH"
TABLE = dict(x=(0.9, 2.3), y=(1.5, 2.5), z=(0.70, 0.76), leg=0.06)
# Centre of the floor region shadowed by the table slab (for tests).
TABLE_CENTRE_XY = (0.5 * (TABLE["x"][0] + TABLE["x"][1]), 0.5 * (TABLE["y"][0] + TABLE["y"][1]))


@dataclass
class SurfaceData:
    """One surface object: quads (n, 4, 3) world corners, uvs (n, 4, 2), albedo (H, W, 3)."""
    name: str
    quads: np.ndarray
    uvs: np.ndarray
    albedo: np.ndarray


@dataclass
class LampData:
    name: str
    location: np.ndarray   # centre (3,)
    size: tuple            # (size_x, size_y) metres
    power: float           # W (Normalize on)

    @property
    def corners(self) -> np.ndarray:
        """(4, 3) world corners, counter-clockwise seen from below (emitting normal -z)."""
        sx, sy = self.size[0] / 2, self.size[1] / 2
        c = self.location
        return np.array([[c[0] - sx, c[1] - sy, c[2]], [c[0] - sx, c[1] + sy, c[2]],
                         [c[0] + sx, c[1] + sy, c[2]], [c[0] + sx, c[1] - sy, c[2]]])


@dataclass
class OfficeData:
    surfaces: list
    lamps: list
    texture_size: int
    seed: int
    camera_location: tuple = (4.7, 0.3, 1.7)
    camera_target: tuple = (1.8, 2.8, 0.7)

    def surface(self, name) -> SurfaceData:
        return next(s for s in self.surfaces if s.name == name)


@dataclass
class OfficeInfo:
    """What ``build_office`` created."""
    objects: list                  # surface object names
    lamps: list                    # lamp object names
    lamp_powers: dict              # lamp name -> W
    albedo_images: dict            # object name -> bpy image name (true albedo)
    materials: dict                # object name -> material name
    texture_size: int
    camera: str
    data: OfficeData = field(repr=False, default=None)


# -- albedo patterns (numpy) -------------------------------------------------------------------

def _smooth_noise(rng, h, w, cells=6):
    """Value noise in [0, 1]: a coarse random grid, bilinearly upsampled."""
    g = rng.random((cells + 1, cells + 1))
    yy = np.linspace(0, cells, h, endpoint=False) + 0.5 * cells / h
    xx = np.linspace(0, cells, w, endpoint=False) + 0.5 * cells / w
    y0, x0 = np.floor(yy).astype(int), np.floor(xx).astype(int)
    fy, fx = (yy - y0)[:, None], (xx - x0)[None, :]
    y1, x1 = np.minimum(y0 + 1, cells), np.minimum(x0 + 1, cells)
    return ((1 - fy) * ((1 - fx) * g[np.ix_(y0, x0)] + fx * g[np.ix_(y0, x1)])
            + fy * ((1 - fx) * g[np.ix_(y1, x0)] + fx * g[np.ix_(y1, x1)]))


def _colour(rng, lo=0.25, hi=0.75):
    return rng.uniform(lo, hi, 3)


def _pattern(kind, rng, n, periods=4):
    """(n, n, 3) linear albedo in [0.2, 0.8] with two colours mixed by a pattern."""
    a, b = _colour(rng), _colour(rng)
    v, u = np.meshgrid((np.arange(n) + 0.5) / n, (np.arange(n) + 0.5) / n, indexing="ij")
    if kind == "checker":
        t = ((np.floor(u * periods) + np.floor(v * periods)) % 2).astype(float)
    elif kind == "stripes":
        t = (np.floor(u * periods * 2) % 2).astype(float)
    elif kind == "hstripes":
        t = (np.floor(v * periods) % 2).astype(float)
    else:  # noise
        t = _smooth_noise(rng, n, n, cells=4)
    img = a[None, None] * (1 - t[..., None]) + b[None, None] * t[..., None]
    return np.clip(img, 0.2, 0.8).astype(np.float32)


# -- geometry (numpy) --------------------------------------------------------------------------

def _quad(origin, du, dv):
    """Corners o, o+du, o+du+dv, o+dv (normal along du x dv)."""
    o, du, dv = (np.asarray(x, float) for x in (origin, du, dv))
    return np.array([o, o + du, o + du + dv, o + dv])


def _full_uv():
    return np.array([[[0, 0], [1, 0], [1, 1], [0, 1]]], float)


def _box_faces(lo, hi, skip=()):
    """Outward quads of an axis-aligned box; skip is a subset of {'-x','+x','-y','+y','-z','+z'}."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    dx, dy, dz = x1 - x0, y1 - y0, z1 - z0
    faces = {
        "-x": _quad((x0, y1, z0), (0, -dy, 0), (0, 0, dz)),
        "+x": _quad((x1, y0, z0), (0, dy, 0), (0, 0, dz)),
        "-y": _quad((x0, y0, z0), (dx, 0, 0), (0, 0, dz)),
        "+y": _quad((x1, y1, z0), (-dx, 0, 0), (0, 0, dz)),
        "-z": _quad((x0, y1, z0), (dx, 0, 0), (0, -dy, 0)),
        "+z": _quad((x0, y0, z1), (dx, 0, 0), (0, dy, 0)),
    }
    return [f for k, f in faces.items() if k not in skip]


def _atlas_uvs(n_faces, size):
    """UV quads of a cols x rows grid of cells, each inset by one texel (no shared texels)."""
    cols = int(np.ceil(np.sqrt(n_faces)))
    rows = int(np.ceil(n_faces / cols))
    inset = 1.0 / size
    uvs = []
    for i in range(n_faces):
        c, r = i % cols, i // cols
        u0, u1 = c / cols + inset, (c + 1) / cols - inset
        v0, v1 = r / rows + inset, (r + 1) / rows - inset
        uvs.append([[u0, v0], [u1, v0], [u1, v1], [u0, v1]])
    return np.array(uvs, float)


def office_geometry(seed: int = 0, n_lamps: int = 2, texture_size: int = 48,
                    variant: str = "small", lamp_power: float | None = None) -> OfficeData:
    """The office as plain numpy data (see the module docstring).

    lamp_power: W per lamp; default DEFAULT_LAMP_POWER * 2 / n_lamps (same total light whatever
    the number of lamps).  variant: "small" (table + 2 boxes) or "boxes3" (a third box).
    """
    if lamp_power is None:
        lamp_power = DEFAULT_LAMP_POWER * 2.0 / n_lamps
    if not 2 <= n_lamps <= 4:
        raise ValueError("n_lamps must be 2, 3 or 4")
    if variant not in ("small", "boxes3"):
        raise ValueError(f"unknown variant {variant!r}")
    rng = np.random.default_rng(seed)
    W, D, H = ROOM
    n = int(texture_size)
    surfaces = []

    def add(name, quads, uvs, albedo):
        surfaces.append(SurfaceData(name, np.asarray(quads, float), np.asarray(uvs, float),
                                    np.ascontiguousarray(albedo, np.float32)))

    # Room shell, normals inward.
    add("Floor", [_quad((0, 0, 0), (W, 0, 0), (0, D, 0))], _full_uv(), _pattern("checker", rng, n, 5))
    add("Ceiling", [_quad((0, D, H), (W, 0, 0), (0, -D, 0))], _full_uv(), _pattern("noise", rng, n))
    add("Wall South", [_quad((W, 0, 0), (-W, 0, 0), (0, 0, H))], _full_uv(), _pattern("stripes", rng, n))
    add("Wall North", [_quad((0, D, 0), (W, 0, 0), (0, 0, H))], _full_uv(), _pattern("hstripes", rng, n))
    add("Wall West", [_quad((0, 0, 0), (0, D, 0), (0, 0, H))], _full_uv(), _pattern("noise", rng, n))
    add("Wall East", [_quad((W, D, 0), (0, -D, 0), (0, 0, H))], _full_uv(), _pattern("checker", rng, n, 3))

    # Poster on the north wall (fig 4.8): a rectangle of another colour.
    north = next(s for s in surfaces if s.name == "Wall North").albedo
    poster = np.array([0.75, 0.25, 0.2]) if seed % 2 == 0 else np.array([0.2, 0.35, 0.75])
    u0, u1 = int(0.30 * n), int(0.55 * n)
    v0, v1 = int(0.40 * n), int(0.80 * n)
    north[v0:v1, u0:u1] = poster.astype(np.float32)

    # Table: a slab on two side panels (a desk).
    tx, ty, tz, leg = TABLE["x"], TABLE["y"], TABLE["z"], TABLE["leg"]
    faces = _box_faces((tx[0], ty[0], tz[0]), (tx[1], ty[1], tz[1]))
    for x0 in (tx[0] + 0.05, tx[1] - 0.05 - leg):
        faces += _box_faces((x0, ty[0] + 0.05, 0.0), (x0 + leg, ty[1] - 0.05, tz[0]), skip=("-z", "+z"))
    add("Table", faces, _atlas_uvs(len(faces), n), _pattern("noise", rng, n))

    # Boxes on the floor.
    boxes = [((3.2, 0.6), (0.5, 0.4, 0.45)), ((3.6, 2.6), (0.6, 0.6, 0.6))]
    if variant == "boxes3":
        boxes.append(((0.4, 3.2), (0.4, 0.4, 0.3)))
    for i, ((bx, by), (sx, sy, sz)) in enumerate(boxes):
        j = rng.uniform(-0.1, 0.1, 2)
        lo = (bx + j[0], by + j[1], 0.0)
        hi = (bx + j[0] + sx, by + j[1] + sy, sz)
        faces = _box_faces(lo, hi, skip=("-z",))
        add(f"Box {i + 1}", faces, _atlas_uvs(len(faces), n),
            _pattern("stripes" if i % 2 else "checker", rng, n, 2))

    # Lamps, just under the ceiling, facing down.
    z = H - LAMP_GAP
    layouts = {2: [(1.6, 2.0), (3.6, 2.0)],
               3: [(1.2, 2.0), (2.5, 2.0), (3.8, 2.0)],
               4: [(1.5, 1.2), (3.5, 1.2), (1.5, 2.8), (3.5, 2.8)]}
    lamps = []
    for i, (x, y) in enumerate(layouts[n_lamps]):
        j = rng.uniform(-0.1, 0.1, 2)
        lamps.append(LampData(f"Lamp {LAMP_LETTERS[i]}", np.array([x + j[0], y + j[1], z]),
                              LAMP_SIZE, float(lamp_power)))
    return OfficeData(surfaces, lamps, n, seed)


def office_scene_data(data: OfficeData, textures: dict | None = None):
    """The office as a SceneData (bpy-free), with ``textures`` {surface name: (H, W, 3) linear}
    as the images (default: the true albedo).  Lamps are one-sided emitting rectangles (exitance
    P / A, Blender's Normalize) that block no rays, like Blender area lights; ``group`` is the
    surface index; the viewpoint is the camera.  Image i belongs to surface i."""
    from types import SimpleNamespace  # noqa: PLC0415

    from relight_addon.core.scene import SceneData  # noqa: PLC0415
    corners, uvs, image, group = [], [], [], []
    images = []
    for i, s in enumerate(data.surfaces):
        tex = s.albedo if textures is None else textures[s.name]
        images.append(SimpleNamespace(name=s.name, texels=np.asarray(tex, np.float32)))
        corners.append(s.quads)
        uvs.append(s.uvs)
        image += [i] * len(s.quads)
        group += [i] * len(s.quads)
    n = sum(len(c) for c in corners)
    k = len(data.lamps)
    lamp_c = np.array([lp.corners for lp in data.lamps])
    exitance = np.array([lp.power / (lp.size[0] * lp.size[1]) for lp in data.lamps])
    emission = np.zeros((n + k, 3))
    emission[n:] = exitance[:, None]
    return SceneData(
        corners=np.concatenate(corners + [lamp_c]),
        rho=np.full((n + k, 3), 0.5) * np.r_[np.ones(n), np.zeros(k)][:, None],
        emission=emission,
        lamp=np.r_[np.full(n, -1), np.arange(k)],
        lamp_names=[lp.name for lp in data.lamps],
        occluder=np.r_[np.ones(n, bool), np.zeros(k, bool)],
        group=np.r_[group, np.full(k, -1)],
        uv=np.concatenate(uvs + [np.zeros((k, 4, 2))]),
        image=np.r_[image, np.full(k, -1)],
        images=images,
        viewpoint=np.asarray(data.camera_location, float))


# -- Blender ------------------------------------------------------------------------------------

def _new_image(bpy, name, pixels_rgb):
    h, w = pixels_rgb.shape[:2]
    img = bpy.data.images.new(name, w, h, alpha=False, float_buffer=True)
    img.colorspace_settings.name = "Linear Rec.709"
    rgba = np.ones((h, w, 4), np.float32)
    rgba[..., :3] = pixels_rgb
    img.pixels.foreach_set(rgba.ravel())
    img.update()
    try:
        img.pack()
    except RuntimeError:  # pragma: no cover - packing is a convenience for saved .blend files
        pass
    return img


def _diffuse_material(bpy, name, image):
    mat = bpy.data.materials.new(name)
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True
    nt = mat.node_tree
    bsdf = next(nd for nd in nt.nodes if nd.bl_idname == "ShaderNodeBsdfPrincipled")
    bsdf.inputs["Roughness"].default_value = 1.0
    for key in ("Specular IOR Level", "Specular"):
        if key in bsdf.inputs:
            bsdf.inputs[key].default_value = 0.0
            break
    for key in ("Coat Weight", "Sheen Weight", "Metallic", "Transmission Weight"):
        if key in bsdf.inputs:
            bsdf.inputs[key].default_value = 0.0
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.name = tex.label = "Albedo"
    tex.image = image
    tex.interpolation = "Closest"
    tex.location = (-400, 200)
    nt.links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    return mat


def build_office(seed: int = 0, n_lamps: int = 2, texture_size: int = 48, variant: str = "small",
                 lamp_power: float | None = None) -> OfficeInfo:
    """Create the office in the current bpy scene (expected empty) and return what was made."""
    import bpy  # noqa: PLC0415

    data = office_geometry(seed, n_lamps, texture_size, variant, lamp_power)
    scene = bpy.context.scene
    coll = scene.collection
    objects, albedo_images, materials = [], {}, {}
    for s in data.surfaces:
        nq = len(s.quads)
        verts = s.quads.reshape(-1, 3)
        faces = np.arange(nq * 4).reshape(nq, 4)
        me = bpy.data.meshes.new(s.name)
        me.from_pydata([tuple(v) for v in verts], [], [tuple(f) for f in faces])
        uv = me.uv_layers.new(name="UVMap")
        uv.data.foreach_set("uv", s.uvs.reshape(-1, 2).astype(np.float32).ravel())
        me.update()
        obj = bpy.data.objects.new(s.name, me)
        coll.objects.link(obj)
        img = _new_image(bpy, f"{s.name} albedo", s.albedo)
        mat = _diffuse_material(bpy, f"{s.name} material", img)
        me.materials.append(mat)
        objects.append(obj.name)
        albedo_images[obj.name] = img.name
        materials[obj.name] = mat.name

    lamps, powers = [], {}
    for lp in data.lamps:
        light = bpy.data.lights.new(lp.name, "AREA")
        light.shape = "RECTANGLE"
        light.size, light.size_y = lp.size
        light.energy = lp.power
        light.color = (1.0, 1.0, 1.0)
        obj = bpy.data.objects.new(lp.name, light)
        obj.location = tuple(lp.location)
        coll.objects.link(obj)
        lamps.append(obj.name)
        powers[obj.name] = lp.power

    cam_data = bpy.data.cameras.new("Office Camera")
    cam_data.lens = 20.0
    cam = bpy.data.objects.new("Office Camera", cam_data)
    cam.location = data.camera_location
    direction = np.subtract(data.camera_target, data.camera_location)
    from mathutils import Vector  # noqa: PLC0415
    cam.rotation_euler = Vector(direction).to_track_quat("-Z", "Y").to_euler()
    coll.objects.link(cam)
    scene.camera = cam
    scene.render.engine = "CYCLES"
    if scene.world is not None:
        scene.world = None  # black background: the room is closed anyway
    bpy.context.view_layer.update()
    return OfficeInfo(objects, lamps, powers, albedo_images, materials, data.texture_size,
                      cam.name, data)
