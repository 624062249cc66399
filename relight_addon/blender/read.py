"""Read a Blender scene into a :class:`SceneData` (the bpy -> maths half of the bridge).

``read_scene(context_or_scene, depsgraph=None, roles=None) -> (SceneData, ReadReport)``

Geometry: every renderable mesh-like object (mesh, curve, surface, text, metaball) of the
depsgraph, instances included (``depsgraph.object_instances``: collection, particle and
geometry-nodes instances, labelled ``"<instancer>/<object>"``), is evaluated (modifiers applied,
``to_mesh`` / ``to_mesh_clear``), its world matrix is applied, triangles become ``(a, b, c, c)`` and quads ``(a, b, c, d)`` in Blender's loop order
(counter-clockwise around the face normal), n-gons are split with ``mesh.loop_triangles``.
SceneData itself splits non-planar quads and drops zero-area faces (counted in the report).
Everything is gathered with ``foreach_get`` into float32/int32 buffers and numpy, never with
per-face Python loops; the loops below run over objects, materials and lamps only.

Conventions established by experiment with Cycles in Blender 5.0.1 (the measurements are
repeated by ``tests/test_bridge_read.py``):

* ``Image.pixels`` of a byte (8-bit) image returns the stored values / 255, still encoded in the
  image's colour space (an sRGB byte 128 reads 0.50196); float images (16-bit PNG, EXR, HDR)
  come back already converted to linear (the same 16-bit PNG tagged sRGB reads 0.21586).  So
  byte images in sRGB are decoded with the sRGB curve here, float images are used as they are,
  and images tagged Non-Color / Linear are used as they are.  Alpha is ignored.
* Area light (Normalize on, the default): a white diffuse plane under a 100 W, 1 m square light
  measured 100 W/m^2 exitance (ratio 0.9998 to the point-to-polygon prediction), the same light
  at 0.5 m measured 400 W/m^2: exitance ``M = P * 2**exposure * colour / A`` with ``A`` the
  world-space area (object scale included: a 0.6 m disk scaled (1, 2, 1) matched to 0.05 %),
  i.e. the lamp emits its power ``P`` as a Lambertian emitter (radiance ``M / pi``).  With
  Normalize off the power is per unit area: ``M = P * 2**exposure * colour``.  The light's
  ``diffuse_factor`` scales what diffuse surfaces receive and is folded into M.
* Emission shader / Principled "Emission Strength" ``S`` with colour ``C``: radiance ``S * C``
  (a surface of strength 1 renders as pixel value 1), so exitance ``M = pi * S * C``
  (measured 3.1398 / pi = 0.9994), on both sides of the face as in Cycles: each emissive face
  is read with a copy facing the other way, unless a Mix Shader driven by Geometry >
  Backfacing keeps the emission on the front.
* Point, spot and sun lights, and area lights with a spread below 180 degrees, are read as the
  core's ``Lights`` (core/lights.py, whose units were measured against Cycles:
  benchmarks/results/light_units.md): point and spot intensity P / (4 pi) W/sr with their
  radius and soft falloff, spot cone and blend, sun strength in W/m^2 and its angle.  The
  colour of every light is colour x 2**exposure (x its blackbody colour); ``diffuse_factor`` is
  ignored, as Cycles does.

The depsgraph defaults to the context's (viewport) one, so modifiers use their viewport levels;
pass ``depsgraph=`` a render-mode depsgraph to read render levels.

Roles (object custom property ``relight_role`` or the ``roles`` argument, name -> role):
``"relit"`` (default for renderable mesh objects), ``"occluder"`` (patches with reflectance 0
and no emission that only block rays and take no part in the display), ``"ignored"`` (not read).
An instancer's role, when set, applies to its instances.  Objects hidden from rendering
(``hide_render``, on the object or its instancer) are ignored.

Nothing in the user's data is modified: evaluated meshes are freed with ``to_mesh_clear``, no
selection, mode, or datablock changes.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import bpy
import numpy as np

from ..core.geometry.patch import reverse_winding
from ..core.lights import Lights
from ..core.scene import RHO_MAX, ImageTexels, SceneData
from ..core.texture.colour import srgb_to_linear
from . import ids
from .materials import original_material
from .roles import has_role, moving, object_role

# Material.use_nodes is deprecated (always on) from Blender 5.0.
_LEGACY_USE_NODES = bpy.app.version < (5, 0, 0)

GEOMETRY_TYPES = {"MESH", "CURVE", "SURFACE", "FONT", "META"}
AREA_SHAPES = {"SQUARE", "RECTANGLE", "DISK", "ELLIPSE"}
LIGHT_TYPES = {"POINT", "SPOT", "SUN", "AREA"}
# A disk/ellipse lamp is a fan of this many planar quads around its centre (2 * DISK_QUADS
# polygon vertices), scaled so that its area equals the ellipse's.
DISK_QUADS = 8
DEFAULT_RHO = 0.8  # Blender's default base colour
# A virtual emissive mesh of at most this many emitting faces (both sides counted) is read as
# polygon lights, so Update adds it to the solved room like a light; a larger one is patches
# of the room (a new solve), since each polygon light is cast on every texel on its own.
MAX_POLYGON_LIGHT_FACES = 64
# Colour spaces whose byte values are already linear (everything else is decoded as sRGB).
_LINEAR_SPACES = {"Non-Color", "Linear Rec.709", "Linear Rec.2020", "Linear CIE-XYZ D65",
                  "Linear CIE-XYZ E", "Linear DCI-P3 D65", "Linear FilmLight E-Gamut", "ACEScg",
                  "ACES2065-1", "Working Space", "Raw", "Linear", "XYZ"}


@dataclass
class ReadReport:
    objects: int = 0            # objects read as geometry (relit + occluder)
    faces: int = 0              # input faces (polygons of the evaluated meshes)
    triangles: int = 0
    quads: int = 0
    ngons_split: int = 0        # n-gons split into triangles
    ngon_triangles: int = 0     # triangles they produced
    zero_area_skipped: int = 0  # faces dropped by SceneData as degenerate
    duplicates_skipped: int = 0
    lamps: int = 0
    lamp_patches: int = 0
    emissive_faces: int = 0
    patches: int = 0
    ignored_objects: list = field(default_factory=list)
    groups: list = field(default_factory=list)  # group index -> (object name, material name)
    warnings: list = field(default_factory=list)
    errors: list = field(default_factory=list)
    viewpoint: tuple | None = None
    # per lamp index: {"name", "object", "kind" ("light" | "emissive"), "power_photo" (its power
    # as read), "power_ref" (the power its emission here stands for)}
    lamp_sources: list = field(default_factory=list)
    moving_objects: list = field(default_factory=list)   # virtual, shadows by spheres: not read
    sources: dict = field(default_factory=dict)   # label -> object whose slots it uses
    uv_maps: dict = field(default_factory=dict)   # (label, material) -> UV map read

    @property
    def ok(self) -> bool:
        return not self.errors

    def warn(self, message: str):
        if message not in self.warnings:
            self.warnings.append(message)


# -- colour ------------------------------------------------------------------------------------


def _light_nodes_matter(light) -> bool:
    """Whether the light's node tree changes its light: anything beyond Blender 5.x's default
    tree (every new light gets one, use_nodes on: a white, strength-1 Emission into the Light
    Output), which lights exactly as no nodes do."""
    tree = light.node_tree if getattr(light, "use_nodes", False) else None
    if tree is None:
        return False
    kinds = sorted(n.bl_idname for n in tree.nodes)
    if kinds != ["ShaderNodeEmission", "ShaderNodeOutputLight"]:
        return True
    emit = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeEmission")
    colour, strength = emit.inputs["Color"], emit.inputs["Strength"]
    return (colour.is_linked or strength.is_linked
            or any(abs(c - 1.0) > 1e-6 for c in colour.default_value[:3])
            or abs(strength.default_value - 1.0) > 1e-6)

def image_texels(image, report=None):
    """Linear RGB texels (h, w, 3) float32 of a bpy image, or None when it has no pixels.
    NaN, infinite and negative texels (float images) are read as 0, with a warning."""
    try:
        w, h = image.size[:]
    except Exception:
        return None
    if w == 0 or h == 0 or not image.has_data:
        return None
    channels = image.channels
    buf = np.empty(w * h * channels, dtype=np.float32)
    image.pixels.foreach_get(buf)
    px = buf.reshape(h, w, channels)
    if channels >= 3:
        rgb = px[..., :3]
    else:
        rgb = np.repeat(px[..., :1], 3, axis=-1)
    space = image.colorspace_settings.name
    if not image.is_float and space not in _LINEAR_SPACES:
        rgb = srgb_to_linear(rgb)
    rgb = np.ascontiguousarray(rgb, dtype=np.float32)
    bad = ~(np.isfinite(rgb) & (rgb >= 0))
    if bad.any():
        texels = int(bad.any(axis=-1).sum())
        rgb[bad] = 0.0
        if report is not None:
            report.warn(f"Image '{image.name}': {texels} texel(s) are NaN, infinite or negative; "
                        "they are read as black")
    return rgb


# -- materials ---------------------------------------------------------------------------------

def _output_surface_node(tree):
    outputs = [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial"]
    if not outputs:
        return None
    active = [n for n in outputs if n.is_active_output] or outputs
    for n in active:
        if n.target in {"ALL", "CYCLES"}:
            active = [n]
            break
    sock = active[0].inputs.get("Surface")
    if sock is None or not sock.is_linked:
        return None
    return _through_reroutes(sock.links[0].from_node)


def _through_reroutes(node):
    while node is not None and node.bl_idname == "NodeReroute":
        sock = node.inputs[0]
        node = _through_reroutes(sock.links[0].from_node) if sock.is_linked else None
    return node


def _find_image_node(sock, depth=6):
    """The Image Texture node feeding a socket, directly or through a few nodes.
    Returns (node, direct)."""
    if sock is None or not sock.is_linked:
        return None, True
    node = _through_reroutes(sock.links[0].from_node)
    if node is None:
        return None, True
    if node.bl_idname == "ShaderNodeTexImage":
        return node, True
    if depth == 0:
        return None, False
    for inp in node.inputs:
        found, _ = _find_image_node(inp, depth - 1)
        if found is not None:
            return found, False
    return None, False


def _rgb(value):
    v = np.asarray(value[:], dtype=np.float64)
    return np.broadcast_to(v[:3] if v.size >= 3 else v[:1], (3,)).copy()


def _socket_value(node, *names):
    for name in names:
        s = node.inputs.get(name)
        if s is not None and hasattr(s, "default_value"):
            return s
    return None


@dataclass
class _MaterialInfo:
    rho: np.ndarray
    emission_radiance: np.ndarray  # W/(m^2 sr); exitance is pi times this
    image_node: object = None
    uv_map: str = ""               # "" -> the active render UV map
    two_sided: bool = True         # emission from both sides (Cycles' default)
    strength: tuple = ()           # (node name, input name, value): the emission's Strength


def _one_sided_emission(shader):
    """An emission restricted to the front by a Mix Shader whose factor is Geometry >
    Backfacing (emission in the first slot, nothing or a black shader in the second): returns
    the Emission node, else None."""
    if shader is None or shader.bl_idname != "ShaderNodeMixShader":
        return None
    fac = shader.inputs[0]
    src = _through_reroutes(fac.links[0].from_node) if fac.is_linked else None
    if src is None or src.bl_idname != "ShaderNodeNewGeometry" or \
            fac.links[0].from_socket.name != "Backfacing":
        return None
    front = shader.inputs[1]
    em = _through_reroutes(front.links[0].from_node) if front.is_linked else None
    return em if em is not None and em.bl_idname == "ShaderNodeEmission" else None


def _material_info(mat, report: ReadReport, images: dict, wants_texture: bool) -> _MaterialInfo:
    """What the reader needs of a material (``mat`` is the user's material: relit copies are
    resolved by the caller, see :func:`user_material`)."""
    black = np.zeros(3)
    if mat is None:
        return _MaterialInfo(np.full(3, DEFAULT_RHO), black)
    name = mat.name
    tree = mat.node_tree
    if tree is not None and _LEGACY_USE_NODES and not mat.use_nodes:
        tree = None  # Blender < 5: node tree present but switched off
    if tree is None:
        return _MaterialInfo(_rgb(mat.diffuse_color), black)
    shader = _output_surface_node(tree)
    if shader is None:
        report.warn(f"Material '{name}' has no surface shader: reflectance 0 used")
        return _MaterialInfo(np.zeros(3), black)
    kind = shader.bl_idname
    emission = black
    front_only = _one_sided_emission(shader)
    if kind == "ShaderNodeEmission" or front_only is not None:
        node = front_only or shader
        strength = float(node.inputs["Strength"].default_value)
        emission = _rgb(node.inputs["Color"].default_value) * strength
        if not (np.isfinite(emission) & (emission < MAX_VALUE)).all():
            report.errors.append(f"Material '{name}': its emission strength is {strength:g}: "
                                 "set a finite strength")
            emission = black
        return _MaterialInfo(np.zeros(3), np.maximum(emission, 0.0),
                             two_sided=front_only is None,
                             strength=(node.name, "Strength", strength))
    colour_sock = _socket_value(shader, "Base Color", "Color")
    if colour_sock is None:
        report.warn(f"Material '{name}' uses an unsupported shader ({shader.name}): "
                    f"default reflectance {DEFAULT_RHO} used")
        return _MaterialInfo(np.full(3, DEFAULT_RHO), black)
    if kind == "ShaderNodeBsdfPrincipled":
        strength_sock = shader.inputs.get("Emission Strength")
        colour_e = shader.inputs.get("Emission Color")
        if strength_sock is not None and colour_e is not None:
            s = float(strength_sock.default_value)
            if not np.isfinite(s) or s >= MAX_VALUE:
                report.errors.append(f"Material '{name}': its Emission Strength is {s:g}: set a "
                                     "finite strength")
            elif s > 0:
                emission = np.maximum(_rgb(colour_e.default_value) * s, 0.0)
                if colour_e.is_linked or strength_sock.is_linked:
                    report.warn(f"Material '{name}': linked emission inputs are not read, "
                                "their default values are used")
    elif kind != "ShaderNodeBsdfDiffuse":
        report.warn(f"Material '{name}' uses {shader.name}: its '{colour_sock.name}' is read "
                    "as a diffuse reflectance")
    base = _rgb(colour_sock.default_value)
    info = _MaterialInfo(base, emission)
    if np.any(emission > 0) and kind == "ShaderNodeBsdfPrincipled":
        info.strength = (shader.name, "Emission Strength",
                         float(shader.inputs["Emission Strength"].default_value))
    node, direct = _find_image_node(colour_sock)
    if node is None:
        if colour_sock.is_linked:
            report.warn(f"Material '{name}': base colour comes from nodes that are not read; "
                        "its default value is used")
        elif wants_texture and not np.any(emission > 0):
            report.warn(f"No image texture on material '{name}' (base colour used)")
        return info
    if not direct:
        report.warn(f"Material '{name}': the image '{node.image.name if node.image else '?'}' "
                    "reaches the base colour through other nodes, which are ignored")
    image = node.image
    if image is None:
        report.warn(f"Material '{name}': its Image Texture node has no image (base colour used)")
        return info
    image = getattr(image, "original", image) or image
    key = image.name
    if key not in images:
        texels = image_texels(image, report)
        if texels is None:
            images[key] = None
            report.warn(f"Image '{image.name}' of material '{name}' has no pixels "
                        f"(missing file '{image.filepath}'?): base colour used")
        else:
            images[key] = ImageTexels(image.name, texels, texels.reshape(-1, 3).mean(axis=0, dtype=np.float64),
                                      image.filepath, image.colorspace_settings.name)
    if images[key] is None:
        return info
    info.rho = images[key].mean.astype(np.float64)
    info.image_node = key
    vec = node.inputs.get("Vector")
    if vec is not None and vec.is_linked:
        src = _through_reroutes(vec.links[0].from_node)
        if src is not None and src.bl_idname == "ShaderNodeUVMap":
            info.uv_map = src.uv_map
        elif src is not None:
            report.warn(f"Material '{name}': image '{key}' uses {src.name} coordinates; "
                        "the active render UV map is read instead")
    return info


# -- geometry ----------------------------------------------------------------------------------

def _get(collection, attr, count, width, dtype):
    buf = np.empty(count * width, dtype=dtype)
    if count:
        collection.foreach_get(attr, buf)
    return buf.reshape(count, width) if width > 1 else buf


def _transform(matrix, points):
    m = np.array(matrix, dtype=np.float64)
    return points @ m[:3, :3].T + m[:3, 3]


def _mesh_faces(me, report: ReadReport):
    """Per patch: corner loop indices (p, 4) and source polygon index (p,)."""
    n_poly = len(me.polygons)
    start = _get(me.polygons, "loop_start", n_poly, 1, np.int32)
    total = _get(me.polygons, "loop_total", n_poly, 1, np.int32)
    tri = np.flatnonzero(total == 3)
    quad = np.flatnonzero(total == 4)
    ngon = np.flatnonzero(total > 4)
    parts = [start[tri, None] + np.array([0, 1, 2, 2], np.int32),
             start[quad, None] + np.array([0, 1, 2, 3], np.int32)]
    polys = [tri, quad]
    if len(ngon):
        lt = me.loop_triangles
        n_lt = len(lt)
        lt_loops = _get(lt, "loops", n_lt, 3, np.int32)
        lt_poly = _get(lt, "polygon_index", n_lt, 1, np.int32)
        keep = np.flatnonzero(total[lt_poly] > 4)
        parts.append(lt_loops[keep][:, [0, 1, 2, 2]])
        polys.append(lt_poly[keep])
        report.ngon_triangles += len(keep)
    report.faces += n_poly
    report.triangles += len(tri)
    report.quads += len(quad)
    report.ngons_split += len(ngon)
    return np.concatenate(parts).astype(np.int64), np.concatenate(polys).astype(np.int64)


def _uv_layer(me, name):
    layers = me.uv_layers
    if name:
        layer = layers.get(name)
        if layer is not None:
            return layer
    for layer in layers:
        if layer.active_render:
            return layer
    return layers.active if len(layers) else None


def _uv_array(layer, n_loops):
    buf = np.empty(n_loops * 2, dtype=np.float32)
    if n_loops:
        layer.uv.foreach_get("vector", buf)
    return buf.reshape(n_loops, 2).astype(np.float64)


# -- lamps -------------------------------------------------------------------------------------

def _area_light_polygon(light):
    """Local-space quads (q, 4, 3) of an area light, facing local -Z (normal (c-a)x(d-b) = -Z)."""
    sx = float(light.size)
    sy = float(light.size_y) if light.shape in {"RECTANGLE", "ELLIPSE"} else sx
    if light.shape in {"SQUARE", "RECTANGLE"}:
        hx, hy = sx / 2, sy / 2
        return np.array([[[-hx, -hy, 0], [-hx, hy, 0], [hx, hy, 0], [hx, -hy, 0]]], float)
    n = 2 * DISK_QUADS
    # Regular n-gon with the ellipse's area: (n/2) sin(2 pi/n) r^2 = pi r^2 * scale^2.
    scale = np.sqrt(np.pi / (0.5 * n * np.sin(2 * np.pi / n)))
    t = -np.arange(n + 1) * (2 * np.pi / n)  # clockwise seen from +Z = counter-clockwise from -Z
    ring = np.stack([0.5 * sx * scale * np.cos(t), 0.5 * sy * scale * np.sin(t), np.zeros_like(t)], 1)
    i = np.arange(0, n, 2)
    centre = np.zeros((len(i), 3))
    return np.stack([centre, ring[i], ring[i + 1], ring[(i + 2)]], axis=1)


def light_colour(light) -> np.ndarray:
    """A light's radiant colour (3,): colour x 2**exposure (x its blackbody colour with
    ``use_temperature``).  ``diffuse_factor`` is left out: Cycles ignores it for diffuse bakes
    and renders (measured, benchmarks/results/light_units.md)."""
    colour = _rgb(light.color) * 2.0 ** float(getattr(light, "exposure", 0.0))
    if getattr(light, "use_temperature", False):
        colour = colour * _rgb(light.temperature_color)
    return colour


def area_light_exitance(light, area: float, energy=None) -> np.ndarray:
    """Exitance (W/m^2, RGB) of a Blender area light of world-space area ``area``, at its own
    power or at ``energy``."""
    energy = float(light.energy if energy is None else energy)
    if getattr(light, "normalize", True):
        return light_colour(light) * energy / max(area, 1e-300)
    return light_colour(light) * energy


def point_light_intensity(light, energy) -> np.ndarray:
    """Radiant intensity (W/sr, RGB) of a point or spot light at power ``energy``: P / (4 pi),
    or, with Normalize off, the radiance P / pi over its disk (x 4 pi r^2; x 4 at radius 0)."""
    r = float(light.shadow_soft_size)
    power = float(energy)
    if not getattr(light, "normalize", True):
        power *= 4.0 * np.pi * r * r if r > 0 else 4.0
    return light_colour(light) * power / (4.0 * np.pi)


def sun_irradiance(light, energy) -> np.ndarray:
    """Irradiance (W/m^2, RGB) of a sun on a plane facing it; with Normalize off its strength is
    the disc's radiance (x pi sin^2(angle / 2); angle 0 unchanged)."""
    s = float(energy)
    sb = np.sin(0.5 * float(light.angle))
    if not getattr(light, "normalize", True) and sb > 1e-6:
        s *= np.pi * sb * sb
    return light_colour(light) * s


def _analytic_light(light, matrix, lamp, energy):
    """The core's Lights row of a point, spot or sun light, or of an area light with a
    spread below 180 degrees (``energy``: the power it is read at)."""
    from ..core.lights import AREA, POINT, SPOT, SUN, Lights
    t = light.type
    soft = bool(getattr(light, "use_soft_falloff", True))
    if t in ("POINT", "SPOT"):
        kw = dict(radius=float(light.shadow_soft_size), soft_falloff=soft)
        if t == "SPOT":
            kw.update(spot_size=float(light.spot_size), spot_blend=float(light.spot_blend))
        return Lights.make(SPOT if t == "SPOT" else POINT, lamp, matrix,
                           point_light_intensity(light, energy), **kw)
    if t == "SUN":
        return Lights.make(SUN, lamp, matrix, sun_irradiance(light, energy),
                           angle=float(light.angle))
    sx = float(light.size)
    sy = float(light.size_y) if light.shape in {"RECTANGLE", "ELLIPSE"} else sx
    scale = np.linalg.norm(np.asarray(matrix, float)[:3, :3], axis=0)
    rnd = light.shape in {"DISK", "ELLIPSE"}
    area = sx * scale[0] * sy * scale[1] * (np.pi / 4 if rnd else 1.0)
    return Lights.make(AREA, lamp, matrix, area_light_exitance(light, area, energy),
                       size=(sx * scale[0], sy * scale[1]), round=rnd, spread=float(light.spread))


# -- the reader --------------------------------------------------------------------------------

def user_material(mat):
    """The user's material behind a slot's material: a relit copy (our Emission material) is
    read through to the original it keeps (write.py)."""
    return original_material(getattr(mat, "original", mat) or mat) if mat is not None else None


class _Instance:
    __slots__ = ("object", "parent", "is_instance", "matrix_world")

    def __init__(self, inst):
        self.object, self.parent, self.is_instance = inst.object, inst.parent, inst.is_instance
        self.matrix_world = inst.matrix_world.copy()


def _ordered_instances(depsgraph):
    """The depsgraph's object instances with the objects themselves in name order, so that a
    read does not depend on the depsgraph's order (drivers added by Relight reorder it: the
    same scene would otherwise read as a changed one).  Instances (collection, geometry-nodes,
    particles) come first, as they are met: their evaluated objects may be temporary, so they
    are read during the iteration."""
    objects = []
    for inst in depsgraph.object_instances:
        if inst.is_instance:
            yield inst
        else:
            objects.append(_Instance(inst))
    yield from sorted(objects, key=lambda e: e.object.original.name_full)


def reference_power(light) -> float:
    """The power a lamp that is off at precompute time is computed at: the highest value its
    ``energy`` is keyframed to, or 1 (W, or W/m^2 for a sun).  Its driver divides by it."""
    best = 0.0
    ad = getattr(light, "animation_data", None)
    action = getattr(ad, "action", None) if ad is not None else None
    if action is not None:
        curves = list(getattr(action, "fcurves", ()) or ())
        if not curves:                              # Blender 4.4+: slotted actions
            try:
                from bpy_extras import anim_utils
                bag = anim_utils.action_get_channelbag_for_slot(action, ad.action_slot)
                curves = list(bag.fcurves) if bag is not None else []
            except Exception:
                curves = []
        for fc in curves:
            if fc.data_path == "energy":
                best = max([best] + [float(k.co[1]) for k in fc.keyframe_points])
    return best if best > 0 else 1.0


class _AsRecorded:
    """A light seen with the colour its map was computed at (a lamp record's), the rest as it
    is now."""

    def __init__(self, light, color):
        self._light, self.color = light, tuple(float(c) for c in color)

    def __getattr__(self, name):
        return getattr(self._light, name)


def _claim_lamps(scene, records):
    """{light object name: its lamp record} for the scene's lights that carry a record's
    identity (one light per record: a duplicate of a lamp is not that lamp)."""
    if not records:
        return {}
    by_uid = {r["uid"]: r for r in records if r.get("uid")}
    holders = {}
    for obj in scene.objects:
        u = ids.uid(obj) if obj.type == "LIGHT" else None
        if u in by_uid:
            holders.setdefault(u, []).append(obj)
    claims = {}
    for u, objs in holders.items():
        named = [o for o in objs if o.name == by_uid[u].get("object")]
        claims[(named or sorted(objs, key=lambda o: o.name))[0].name] = by_uid[u]
    return claims


def _unique(label, taken):
    """``label``, or ``label.1``, ``label.2``... when a lamp of the maps already has it."""
    if label not in taken:
        return label
    n = 1
    while f"{label}.{n}" in taken:
        n += 1
    return f"{label}.{n}"


# Blender stores an infinite strength as the largest float32 (3.4e38): anything this large is one
MAX_VALUE = 1e30
# A lamp this much weaker than the strongest of its unit is a typing slip (1e-9 W beside 60 W),
# not a lamp of the photo: the photo's estimate would replace its power by 1e8 times it.
WEAKEST_LAMP = 1e-6


def _check_powers(report):
    """Errors for lamps of the photo set far weaker than the others of their unit (W, or W/m^2
    for suns): their power must be what lit the photo, or 0 for a lamp that was off."""
    by_unit = {}
    for src in report.lamp_sources:
        if src.get("kind") == "light" and not src.get("virtual") and src["power_photo"] > 0:
            by_unit.setdefault(src["type"] == "SUN", []).append(src)
    for group in by_unit.values():
        top = max(group, key=lambda s: s["power_photo"])
        strongest = top["power_photo"]
        for s in group:
            if s["power_photo"] < WEAKEST_LAMP * strongest:
                unit = "W/m^2" if s["type"] == "SUN" else "W"
                # the strongest is named too: either may be the slip (1e-9 W, or 1e9 W)
                report.errors.append(
                    f"Light '{s['name']}' is set to {s['power_photo']:g} {unit}, "
                    f"{s['power_photo'] / strongest:.0e} of '{top['name']}' ({strongest:g} "
                    f"{unit}): set each lamp's power in the photo (0 if it was off)")


class _Reader:
    """What read_scene gathers, object by object, before it becomes a SceneData."""

    def __init__(self, scene, report, virtual, lamps):
        self.report = report
        self.virtual, self.lamps = virtual, lamps
        self.images: dict = {}       # image name -> ImageTexels | None
        self.mat_cache: dict = {}
        self.corners, self.rho, self.emission, self.lamp = [], [], [], []
        self.occluder, self.group, self.uvs, self.image_idx = [], [], [], []
        self.lamp_names: list = []
        self.lamp_intensity: list = []   # per lamp: its power in the photo over the power read
        self.light_rows: list = []       # core Lights of the lamps that are not patches
        self.virtual_patch: list = []    # per patch: part of a virtual object (role "virtual")
        self.emissive_lamp: dict = {}    # (object, material) -> lamp index
        self.claims = _claim_lamps(scene, lamps)
        self.taken_labels = {r["label"] for r in (lamps or ())}

    def light(self, obj, ev, label, matrix, parent):
        """One light: as patches (an area light of 180 degrees' spread) or a core Light."""
        corners, rho, emission, lamp, occluder, group, uvs, image_idx = (
            self.corners, self.rho, self.emission, self.lamp, self.occluder, self.group,
            self.uvs, self.image_idx)
        lamp_names, lamp_intensity, light_rows = self.lamp_names, self.lamp_intensity, \
            self.light_rows
        virtual_patch, report = self.virtual_patch, self.report
        claims, taken_labels, virtual, lamps = self.claims, self.taken_labels, \
            self.virtual, self.lamps
        light = ev.data
        if light.type not in LIGHT_TYPES or (light.type == "AREA" and
                                             light.shape not in AREA_SHAPES):
            report.warn(f"Light '{label}' ({light.type.lower()}) is not supported and is "
                        "ignored")
            return
        if _light_nodes_matter(light):
            report.warn(f"Light '{label}': light nodes are ignored")
        # A lamp that is off in the photo still gets its basis (light transport is linear),
        # computed at a reference power; the photo sees it at intensity 0.
        record = claims.get(obj.name) if parent is None else None
        power = float(light.energy)
        if not np.isfinite(power) or power < 0 or power >= MAX_VALUE:
            report.errors.append(f"Light '{label}' has power {power:g}: set a finite power, "
                                 "0 or more")
            return
        power_ref = power if power > 0 else reference_power(light)
        if record is not None:
            light = _AsRecorded(light, record.get("color0") or light.color)
            power_ref = float(record["p0"])
            power = float(record.get("photo", power_ref))
            label = record["label"]
        elif lamps is not None:
            label = _unique(label, taken_labels)
        taken_labels.add(label)
        if not np.any(light_colour(light) > 0):
            report.warn(f"Light '{label}' is black (colour or exposure): it is ignored")
            return
        is_virtual = bool(record.get("virtual")) if record is not None else \
            (label in virtual or obj.name in virtual or lamps is not None)
        patches = light.type == "AREA" and not is_virtual and \
            float(getattr(light, "spread", np.pi)) >= np.pi - 1e-6
        if patches:
            local = _area_light_polygon(light)
            if np.linalg.det(matrix[:3, :3]) < 0:
                local = local[:, ::-1]
            quads = _transform(matrix, local.reshape(-1, 3)).reshape(-1, 4, 3)
            cross = np.cross(quads[:, 2] - quads[:, 0], quads[:, 3] - quads[:, 1])
            area = 0.5 * float(np.linalg.norm(cross, axis=-1).sum())
            if not area > 0:
                report.warn(f"Light '{label}' has zero area and is ignored")
                return
        if record is None and is_virtual and power <= 0:
            report.warn(f"Virtual lamp '{label}' has no power: it is ignored")
            return
        if record is None and power <= 0:
            unit = "W/m^2" if light.type == "SUN" else "W"
            report.warn(f"Light '{label}' is off (power 0): it is taken as off in the photo; "
                        f"its map is computed at {power_ref:g} {unit}, so raising its power "
                        "switches it on")
        k = len(lamp_names)
        lamp_names.append(label)
        lamp_intensity.append(0.0 if is_virtual else max(power, 0.0) / power_ref)
        report.lamp_sources.append({"name": label, "object": obj.name, "kind": "light",
                                    "type": light.type, "virtual": is_virtual,
                                    "power_photo": 0.0 if is_virtual else power,
                                    "power_ref": power_ref,
                                    "uid": None if record is None else record["uid"],
                                    "color0": [float(c) for c in light.color],
                                    "exposure": float(getattr(light, "exposure", 0.0)),
                                    "temperature": float(light.temperature) if getattr(
                                        light, "use_temperature", False) else 0.0})
        report.lamps += 1
        if not patches:
            light_rows.append(_analytic_light(light, matrix, k, power_ref))
            return
        exitance = area_light_exitance(light, area, power_ref)
        q = len(quads)
        corners.append(quads)
        virtual_patch.append(np.zeros(q, bool))
        rho.append(np.zeros((q, 3)))
        emission.append(np.tile(exitance, (q, 1)))
        lamp.append(np.full(q, k))
        occluder.append(np.zeros(q, bool))
        group.append(np.full(q, len(report.groups)))
        report.groups.append((label, ""))
        uvs.append(np.zeros((q, 4, 2)))
        image_idx.append(np.full(q, -1))
        report.lamp_patches += q
        return


    def mesh(self, obj, ev, label, matrix, parent, role):
        """One evaluated mesh-like object: its faces, materials, UVs, images and emissive
        faces (lamps)."""
        corners, rho, emission, lamp, occluder, group, uvs, image_idx = (
            self.corners, self.rho, self.emission, self.lamp, self.occluder, self.group,
            self.uvs, self.image_idx)
        lamp_names, lamp_intensity = self.lamp_names, self.lamp_intensity
        virtual_patch, emissive_lamp, report = self.virtual_patch, self.emissive_lamp, \
            self.report
        images, mat_cache = self.images, self.mat_cache
        try:
            me = ev.to_mesh()
        except RuntimeError:
            me = None
        if me is None:
            return
        try:
            n_v = len(me.vertices)
            n_loops = len(me.loops)
            if n_v == 0 or len(me.polygons) == 0:
                return
            report.objects += 1
            co = _transform(matrix, _get(me.vertices, "co", n_v, 3, np.float32).astype(np.float64))
            loop_vert = _get(me.loops, "vertex_index", n_loops, 1, np.int32)
            loops, poly = _mesh_faces(me, report)
            # (Blender stores an infinite coordinate as the largest float32: MAX_VALUE)
            c = co[loop_vert[loops]]
            finite = (np.isfinite(c) & (np.abs(c) < MAX_VALUE)).all(axis=(1, 2))
            if not finite.all():
                report.warn(f"Object '{label}': {int((~finite).sum())} face(s) have non-finite "
                            "vertex coordinates (NaN or infinite) and are skipped")
                loops, poly = loops[finite], poly[finite]
            if np.linalg.det(matrix[:3, :3]) < 0:
                loops = reverse_winding(loops)   # mirrored: keep the faces' outward side
            p = len(loops)
            obj_corners = co[loop_vert[loops]]
            mat_index = _get(me.polygons, "material_index", len(me.polygons), 1, np.int32)[poly]
            slots = ev.material_slots
            obj_rho = np.zeros((p, 3))
            obj_em = np.zeros((p, 3))
            obj_lamp = np.full(p, -1)
            obj_group = np.zeros(p, np.int64)
            obj_uv = np.zeros((p, 4, 2))
            obj_img = np.full(p, -1)
            obj_two_sided = np.zeros(p, bool)
            uv_cache: dict = {}
            for mi in np.unique(mat_index):
                sel = mat_index == mi
                mat = user_material(slots[int(mi)].material) if 0 <= mi < len(slots) else None
                mkey = (mat.name if mat is not None else None)
                if mkey not in mat_cache:
                    mat_cache[mkey] = _material_info(mat, report, images, role == "relit")
                info = mat_cache[mkey]
                obj_group[sel] = len(report.groups)
                report.groups.append((label, mat.name if mat is not None else ""))
                if role in ("occluder", "receiver"):
                    continue
                obj_rho[sel] = np.clip(info.rho, 0.0, RHO_MAX)
                if np.any(info.emission_radiance > 0):
                    # A virtual emissive mesh is a lamp that is off in the photo (intensity 0):
                    # it gets its map like any lamp, and its light is added at render time.
                    in_photo = role != "virtual"
                    key = (label, mkey)
                    if key not in emissive_lamp:
                        emissive_lamp[key] = len(lamp_names)
                        lamp_names.append(f"{label}/{mkey}")
                        lamp_intensity.append(1.0 if in_photo else 0.0)
                        report.lamp_sources.append({"name": f"{label}/{mkey}", "object": obj.name,
                                                    "material": mkey, "kind": "emissive",
                                                    "virtual_mesh": not in_photo,
                                                    "strength": list(info.strength),
                                                    "power_photo": 1.0 if in_photo else 0.0,
                                                    "power_ref": 1.0})
                        report.lamps += 1
                    obj_lamp[sel] = emissive_lamp[key]
                    obj_em[sel] = np.pi * info.emission_radiance
                    obj_two_sided[sel] = info.two_sided
                    report.emissive_faces += int(sel.sum())
                if role == "virtual":   # not in the photo: no texels, its material's colour
                    continue
                layer = _uv_layer(me, info.uv_map)
                if layer is None:
                    if info.image_node is not None:
                        report.warn(f"No UV map on object '{label}': image '{info.image_node}' "
                                    "cannot be mapped (its mean colour is used)")
                    continue
                if info.uv_map and layer.name != info.uv_map:
                    report.warn(f"Object '{label}' has no UV map '{info.uv_map}' used by "
                                f"material '{mkey}': '{layer.name}' is read instead")
                report.uv_maps[(label, mkey or "")] = layer.name
                if layer.name not in uv_cache:
                    uv_cache[layer.name] = _uv_array(layer, n_loops)
                obj_uv[sel] = uv_cache[layer.name][loops[sel]]
                if info.image_node is not None:
                    names = list(k for k, v in images.items() if v is not None)
                    obj_img[sel] = names.index(info.image_node)
            report.sources[label] = obj.name
            if parent is not None and np.any(obj_img >= 0):
                report.warn(f"'{label}' is an instance of '{obj.name}': instances share its "
                            "texture, so they all show the light of one place (Make Instances "
                            "Real gives each its own)")
            corners.append(obj_corners)
            rho.append(obj_rho)
            emission.append(obj_em)
            lamp.append(obj_lamp)
            # A virtual emissive mesh was not in the photo: it must not darken the room the
            # photo is explained by (measured: as an occluder it raised the shadow-free texture
            # near it 4 % and its own light 8 %); it stays a lamp.
            occluder.append(~((role == "virtual") & (obj_lamp >= 0)))
            group.append(obj_group)
            uvs.append(obj_uv)
            image_idx.append(obj_img)
            # (a virtual mesh's emissive faces are lamp patches, not a virtual object's)
            virtual_patch.append((role == "virtual") & (obj_lamp < 0))
            # Cycles' mesh emission is two-sided: the back of an emissive face emits too (a
            # copy facing the other way; the front already blocks rays).
            em = np.flatnonzero((obj_lamp >= 0) & obj_two_sided)
            if len(em):
                corners.append(reverse_winding(obj_corners[em]))
                rho.append(np.zeros((len(em), 3)))
                emission.append(obj_em[em])
                lamp.append(obj_lamp[em])
                occluder.append(np.zeros(len(em), bool))
                group.append(obj_group[em])
                uvs.append(reverse_winding(obj_uv[em]))
                image_idx.append(np.full(len(em), -1))
                virtual_patch.append(np.zeros(len(em), bool))
        finally:
            ev.to_mesh_clear()



def read_scene(context_or_scene, depsgraph=None, roles=None, virtual=(), lamps=None):
    """Read the renderable scene into (SceneData, ReadReport).  Never modifies the scene.

    ``virtual``: names of lights that are not in the photo (virtual lamps, added after the
    precompute): they are read off in the photo (intensity 0) at their current power, and an
    area light among them as a core Light rather than patches (so that it can be added to a
    finished solution without new links).

    ``lamps``: the lamp records of the scene's last precompute (state.py), or None before the
    first.  A light carrying a record's identity is read as that record says: under its label
    (a rename changes nothing), in the photo or not, at the power and colour its map was
    computed at (the light's present power and colour are the drivers' business); a light
    without one is new since, so virtual.  Of two lights with one identity (a duplicate), the
    one named as the record is the lamp, the other is new."""
    if hasattr(context_or_scene, "scene") and hasattr(context_or_scene, "view_layer"):
        scene = context_or_scene.scene
        if depsgraph is None:
            depsgraph = context_or_scene.evaluated_depsgraph_get()
    else:
        scene = context_or_scene
        view_layer = scene.view_layers[0] if depsgraph is None else depsgraph.view_layer
        if depsgraph is None:
            depsgraph = view_layer.depsgraph
    report = ReadReport()
    r = _Reader(scene, report, virtual, lamps)
    labels_seen: dict = {}
    # depsgraph.object_instances: every evaluated object of the view layer plus the instances
    # (collection instances, geometry-nodes and particle instances) with their world matrices.
    for inst in _ordered_instances(depsgraph):
        ev = inst.object
        obj = ev.original
        if obj.type not in GEOMETRY_TYPES and obj.type != "LIGHT":
            continue
        if ids.is_generated(obj):            # Relight's own (the moving shadows' probes)
            continue
        parent = inst.parent.original if inst.is_instance and inst.parent is not None else None
        if parent is not None and parent == obj and obj.type != "MESH":
            # a curve's or text's own geometry, also listed as an instance of itself (it is
            # read once, as the object; a mesh's geometry-nodes instances are its own)
            continue
        label = obj.name if parent is None else f"{parent.name}/{obj.name}"
        if label in labels_seen:
            labels_seen[label] += 1
            label = f"{label}.{labels_seen[label]}"
        else:
            labels_seen[label] = 0
        role_of = parent if parent is not None and has_role(parent, roles) else obj
        role = object_role(role_of, roles)
        if role is None:
            report.warn(f"Object '{role_of.name}': unknown {ids.ROLE} "
                        f"'{role_of.get(ids.ROLE)}', read as relit")
            role = "relit"
        if role == "virtual" and moving(role_of):     # sphere shadows at render time
            report.moving_objects.append(label)
            continue
        if obj.hide_render or (parent is not None and parent.hide_render) or role == "ignored":
            report.ignored_objects.append(label)
            continue
        matrix = np.array(inst.matrix_world, dtype=np.float64)
        if obj.type == "LIGHT":
            r.light(obj, ev, label, matrix, parent)
        else:
            r.mesh(obj, ev, label, matrix, parent, role)
    cam = scene.camera
    viewpoint = None
    if cam is not None:
        viewpoint = np.array(cam.evaluated_get(depsgraph).matrix_world.translation, dtype=np.float64)
        report.viewpoint = tuple(float(x) for x in viewpoint)
    else:
        report.warn("The scene has no active camera: no viewpoint")

    return _scene_data(r, report, viewpoint, lamps)


def _scene_data(r, report, viewpoint, lamps):
    """The SceneData of what ``r`` gathered, checked (the report's warnings and errors)."""
    corners, rho, emission, lamp, occluder, group, uvs, image_idx = (
        r.corners, r.rho, r.emission, r.lamp, r.occluder, r.group, r.uvs, r.image_idx)
    lamp_names, lamp_intensity, light_rows, virtual_patch = (
        r.lamp_names, r.lamp_intensity, r.light_rows, r.virtual_patch)
    image_list = [v for v in r.images.values() if v is not None]

    def cat(parts, shape, dtype):
        return np.concatenate(parts).astype(dtype) if parts else np.zeros(shape, dtype)

    data = SceneData(
        corners=cat(corners, (0, 4, 3), np.float64), rho=cat(rho, (0, 3), np.float64),
        emission=cat(emission, (0, 3), np.float64), lamp=cat(lamp, (0,), np.int32),
        lamp_names=lamp_names, occluder=cat(occluder, (0,), bool), group=cat(group, (0,), np.int32),
        uv=cat(uvs, (0, 4, 2), np.float64), image=cat(image_idx, (0,), np.int32),
        images=image_list, viewpoint=viewpoint, lamp_intensity=np.array(lamp_intensity, float),
        lights=Lights.concat(light_rows), virtual=cat(virtual_patch, (0,), bool))
    report.zero_area_skipped = data.dropped_degenerate
    report.duplicates_skipped = data.dropped_duplicate
    polygons = [k for k, src in enumerate(report.lamp_sources) if src.get("virtual_mesh") and
                0 < int(np.sum(data.lamp == k)) <= MAX_POLYGON_LIGHT_FACES]
    if polygons:
        data = data.lamps_as_polygons(polygons)
        for k in polygons:               # a light now, added after the photo: a virtual lamp
            report.lamp_sources[k]["virtual"] = True
    for dropped, kept in data.duplicate_groups:
        a, b = report.groups[int(dropped)][0], report.groups[int(kept)][0]
        if a == b:
            report.warn(f"'{a}' has faces at the same place as others of its own: they are "
                        "counted once")
        else:
            report.warn(f"'{a}' has faces at the same place as '{b}' (a duplicate?): they are "
                        "counted once, and the copies z-fight in renders: delete or move one")
    report.patches = data.n_patches
    if lamps is None:
        _check_powers(report)
    if report.zero_area_skipped:
        report.warn(f"{report.zero_area_skipped} zero-area face(s) skipped")
    if data.n_patches == 0 or not np.any(data.lamp >= 0):
        if not lamp_names:
            report.errors.append("The scene has no lamps: add an area light or an emissive face")
    # (after a precompute the photo's lamps are read at their power in the photo: lights out
    # is an Update like any other)
    if lamp_names and not any(x > 0 for x in lamp_intensity) and lamps is None:
        report.errors.append("Every lamp is off (power 0): set the real lamps to their power in "
                             "the photo before Precompute (then animate them)")
    if not np.any(data.occluder) and data.n_patches == 0:
        report.errors.append("The scene has no usable faces")
    return data, report
