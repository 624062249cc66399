"""Write a precompute back into Blender (the maths -> bpy half of the bridge).

``write_results(context, scene_data, report, result) -> dict``

``result`` is a :class:`~relight_addon.core.relight.shadowfree.ShadowFreeResult`: per image the
shadow-free texture ``T_final`` and one display map ``M_k`` per lamp, so that the relit colour is
``T_final * sum_k I_k M_k`` (per-texel or per-element shadow removal; with the correction off,
the DRB97 baseline, ``T`` is the original image and ``M_k = B_k / sum_k B_k``, the maps that
:func:`display_maps` also gives for a bare RadiositySolution).

* ``T_final`` is written as ``"<image>.relight.T"`` (half float, Non-Color = linear, unclamped
  above 1, packed) and replaces the image of the relit material's copy of the texture node
  (named ``"T"``); the original image is never modified.
* Images ``"<image>.relight.<lamp>"``: float, Non-Color, RGBA, half-float OpenEXR (ZIP), packed
  into the .blend; their user is the relit material.  Alpha (channel-packed) is the part of the
  map that is the lamp's direct light (per-texel runs; 1 otherwise).  Half floats quantise M_k
  (spacing 2**-11 just below 1), so the written maps sum to 1 within about 1e-3.
* Materials ``"<material>.relight"``: a copy of the original whose tree keeps only the original
  Image Texture node and what feeds its Vector input (UV Map node, mapping...; a UV Map node
  names the UV map the reader actually used, e.g. "RelightUV" after Unwrap Missing UVs), plus
  ``T * sum_k(I_k * C_k * M_k * S_k)`` -> Emission (strength 1) -> Material Output.  ``I_k`` is a
  Value node whose output is driven by the SCRIPTED simple expression ``p / P0`` (``p`` = the
  light data's ``energy``, ``P0`` the power its map was computed at, written as a literal: its
  power at precompute time, or a reference power for a lamp that was off then); ``C_k`` a
  Combine XYZ node whose three inputs follow the light's colour channel by channel (``c / c0``,
  ``c0`` its colour then); ``S_k`` a Vector Math Scale node whose factor is 1, or the moving
  objects' sphere shadows of that lamp (sphere_nodes.py).  Simple expressions evaluate with
  Python auto-run off and without the extension (``add_driver``).  ``P0`` is also kept as
  ``light.data["relight_power0"]``.  Exposure and temperature changes are not followed.  An
  emissive mesh's ``I_k`` follows its material's emission Strength (``s / s0``); its colour is
  not followed.
* The user's material stays alive: the relit copy holds it in the ID property
  ``relight_original`` (an ID reference counts as a user, so it survives save and reopen), and
  the reader reads through a relit material to it.
* Objects: slots holding a relit material get the ``.relight`` copy.  A library-override
  object whose slot lives in its linked mesh gets an object-level slot instead (recorded on the
  relit material, undone by Restore); linked objects are left alone.
* Every generated datablock carries ``relight_generated = 1`` and the key of the scene it was
  made for (``relight_scene``; the scene keeps its key in ``relight_id``), so Restore and Clear
  act on that scene's results only, and on nothing else.
"""
from __future__ import annotations

import uuid

import bpy
import numpy as np

from ..core.relight.maps import DISPLAY_EPS, SEAM_PIXELS, map_images, ratio_maps
from ..core.texture.mapping import rasterize_patches

GENERATED = "relight_generated"
SCENE_KEY = "relight_scene"         # on generated datablocks: the key of their scene
SCENE_ID = "relight_id"             # on a scene: its key
SCENE_OWNER = "relight_id_owner"    # on a scene: the name it had when the key was made
ORIGINAL = "relight_original"       # on a relit material: the user's material (keeps it alive)
OBJECT_LINKS = "relight_object_slots"  # on a relit material: override objects whose slot we linked
POWER0 = "relight_power0"
HALF_MAX = 65504.0
T_NODE = "T"
MAP_PREFIX = "M "          # the node of lamp k's map image: "M <lamp name>"
SHADOW_PREFIX = "S "       # lamp k's moving-shadow factor: "S <lamp name>" (Scale input)
MAP_SOURCE = "relight_map_source"   # on a map image: the photo's name (names may be renamed)
MAP_LAMP = "relight_map_lamp"       # on a map image: its lamp's name
MAT_SUFFIX = ".relight"
_LEGACY_USE_NODES = bpy.app.version < (5, 0, 0)


# -- maths (numpy only) ------------------------------------------------------------------------

def display_maps(scene_data, solution, seam_pixels=SEAM_PIXELS, eps=DISPLAY_EPS, warnings=None):
    """Texture correction off (DRB97): per image used by some patch ``(coverage (H, W) bool,
    maps (k, H, W, 3) float32)`` with ``maps[k] = B_k / D`` (0 where D < floor), dilated across
    seams (core/relight/maps.py ratio_maps and map_images).  Overlapping UVs (a texel
    claimed by several faces: it can show one face's light only) are appended to ``warnings``
    when a list is given."""
    shapes = [im.texels.shape[:2] for im in scene_data.images]
    tm = rasterize_patches(scene_data.uv, scene_data.image, shapes)
    if warnings is not None:
        warnings.extend(_overlap_warnings(scene_data, tm))
    maps, coverage = map_images(tm, ratio_maps(solution, tm, eps), seam_pixels)
    return {i: (coverage[i], maps[i]) for i in maps}


def _overlap_warnings(scene_data, tm):
    return [f"Image '{scene_data.images[i].name}': {im.n_overlap} texel(s) are used by several "
            "faces (overlapping UVs); they show the light of one face only"
            for i, im in enumerate(tm.images) if im.n_overlap]


# -- bpy helpers -------------------------------------------------------------------------------

def _is_generated(idb) -> bool:
    return bool(idb.get(GENERATED, 0))


def _tag(idb, key):
    idb[GENERATED] = 1
    idb[SCENE_KEY] = key


def scene_key(scene, create=False):
    """The key that ties generated data to ``scene`` (made on the first write; ``create`` is
    only allowed where ID properties may be written, never in a poll or a draw).  A copied
    scene (Full Copy) carries its original's key: the key stays with the scene that still has
    the name it was made under, and the copy gets its own on its first write."""
    key = scene.get(SCENE_ID)
    if key is not None and scene.get(SCENE_OWNER) != scene.name:
        if any(s != scene and s.get(SCENE_ID) == key and s.get(SCENE_OWNER) == s.name
               for s in bpy.data.scenes):
            key = None                               # a copy: not its key
        elif create:
            scene[SCENE_OWNER] = scene.name          # renamed
    if key is None and create:
        key = scene[SCENE_ID] = uuid.uuid4().hex
        scene[SCENE_OWNER] = scene.name
    return key


def _ours(idb, key) -> bool:
    return key is not None and _is_generated(idb) and idb.get(SCENE_KEY) == key


def original_material(mat):
    """The user's material behind a relit one (``mat`` itself when it is not relit)."""
    for _ in range(8):                       # a relit material is never relit again; be safe
        if mat is None or not _is_generated(mat):
            return mat
        nxt = mat.get(ORIGINAL)
        if nxt is None:                      # relit data written before the reference existed
            nxt = bpy.data.materials.get(mat.name[: -len(MAT_SUFFIX)]) \
                if mat.name.endswith(MAT_SUFFIX) else None
        mat = nxt
    return None


def _float_image(name, rgb, alpha=None):
    hh, ww = rgb.shape[:2]
    img = bpy.data.images.new(name, ww, hh, alpha=True, float_buffer=True)
    img.colorspace_settings.name = "Non-Color"
    img.alpha_mode = "CHANNEL_PACKED"        # alpha is data (the direct fraction), not coverage
    rgba = np.ones((hh, ww, 4), np.float32)
    rgba[..., :3] = rgb
    if alpha is not None:
        rgba[..., 3] = alpha
    img.pixels.foreach_set(rgba.reshape(-1))
    return img


class _HalfWriter:
    """Half-float OpenEXR through ``Image.save_render`` with a temporary scene whose output
    settings are EXR / 16 bit / ZIP (``Image.save`` + ``use_half_precision`` writes 32-bit
    float in Blender 5.0.1: measured from the EXR channel list).  The file is loaded, packed
    and deleted; the image keeps the relative path ``//relight/<name>.exr`` for unpacking.
    Linear EXR output gets no view transform (values above 1 round-trip unchanged)."""

    def __init__(self, key):
        import tempfile
        self.key = key
        self.dir = tempfile.mkdtemp(prefix="relight_")
        self.scene = bpy.data.scenes.new("relight_tmp_exr_settings")
        s = self.scene.render.image_settings
        s.file_format = "OPEN_EXR"
        s.color_mode = "RGBA"
        s.color_depth = "16"
        s.exr_codec = "ZIP"

    def write(self, name, rgb, alpha=None):
        import os
        rgb = np.clip(np.nan_to_num(rgb), -HALF_MAX, HALF_MAX)   # half floats end at 65504
        if alpha is not None:
            alpha = np.clip(np.nan_to_num(alpha, nan=1.0), 0.0, 1.0)
        tmp = _float_image("relight_tmp_image", rgb, alpha)
        path = os.path.join(self.dir, "image.exr")
        try:
            tmp.save_render(path, scene=self.scene)
            img = bpy.data.images.load(path, check_existing=False)
            img.colorspace_settings.name = "Non-Color"
            img.alpha_mode = "CHANNEL_PACKED"
            img.pack()
            img.name = name
            img.filepath_raw = f"//relight/{bpy.path.clean_name(name)}.exr"
        except Exception:       # fall back to a packed 32-bit float image
            img = None
        finally:
            bpy.data.images.remove(tmp)
            if os.path.exists(path):
                os.remove(path)
        if img is None:
            img = _float_image(name, rgb, alpha)
            img.file_format = "OPEN_EXR"
            img.pack()
        _tag(img, self.key)
        return img

    def close(self):
        import shutil
        bpy.data.scenes.remove(self.scene)
        shutil.rmtree(self.dir, ignore_errors=True)


def _upstream(node, keep):
    if node is None or node in keep:
        return
    keep.add(node)
    for sock in node.inputs:
        for link in sock.links:
            _upstream(link.from_node, keep)


def _source_image_node(tree, image_name):
    cands = [n for n in tree.nodes if n.bl_idname == "ShaderNodeTexImage"
             and n.image is not None and n.image.name == image_name]
    linked = [n for n in cands if any(s.is_linked for s in n.outputs)]
    return (linked or cands or [None])[0]


def add_driver(socket, expression, variables):
    """A SCRIPTED driver on ``socket``'s default value:
    ``expression`` over ``variables``, each (name, kind, target, what): kind "TRANSFORMS" reads
    the world-space transform channel ``what`` of the object ``target`` (rotations as a
    quaternion), any other kind is the ID type of ``target`` whose property at the data path
    ``what`` is read.  Kept to simple expressions, drivers run without Python (auto-run off, no
    extension)."""
    fc = socket.driver_add("default_value")
    for mod in list(fc.modifiers):
        fc.modifiers.remove(mod)
    drv = fc.driver
    drv.type = "SCRIPTED"
    for name, kind, target, what in variables:
        var = drv.variables.new()
        var.name = name
        t = var.targets[0]
        if kind == "TRANSFORMS":
            var.type = "TRANSFORMS"
            t.id = target
            t.transform_type = what
            t.transform_space = "WORLD_SPACE"
            if what.startswith("ROT"):
                t.rotation_mode = "QUATERNION"
        else:
            var.type = "SINGLE_PROP"
            t.id_type = kind
            t.id = target
            t.data_path = what
    drv.expression = expression
    return fc


def _ratio_driver(socket, var, kind, idb, data_path, value0):
    """``socket`` follows a property (the variable ``var``) over its value ``value0`` at
    precompute: ``var / value0``."""
    return add_driver(socket, f"{var} / {float(value0)!r}", [(var, kind, idb, data_path)])


def _relit_material(orig, image_name, maps, lamps, key, t_image=None, uv_map=None):
    """maps: list of bpy images (one per lamp); lamps: list of (name, light data or None, P0);
    t_image: the shadow-free texture T_final (None: the original image is T); uv_map: the UV
    map the reader used for this material (its UV Map nodes are pointed at it)."""
    mat = orig.copy()
    mat.name = orig.name + MAT_SUFFIX
    _tag(mat, key)
    mat[ORIGINAL] = orig
    if _LEGACY_USE_NODES:
        mat.use_nodes = True
    tree = mat.node_tree
    # Drivers copied with the original tree would point at nodes removed below.
    if tree.animation_data is not None:
        tree.animation_data_clear()
    tex = _source_image_node(tree, image_name)
    keep = set()
    _upstream(tex, keep)
    for node in list(tree.nodes):
        if node not in keep:
            tree.nodes.remove(node)
    links = tree.links
    vec_src = None
    if tex is None:  # should not happen: read_scene found it; rebuild a plain one
        tex = tree.nodes.new("ShaderNodeTexImage")
        tex.image = bpy.data.images[image_name]
    elif tex.inputs["Vector"].is_linked:
        vec_src = tex.inputs["Vector"].links[0].from_socket
    if t_image is not None:       # the copy's node only: the original material keeps its image
        tex.image = t_image
    if uv_map:
        for node in keep:
            if node.bl_idname == "ShaderNodeUVMap" and node.uv_map != uv_map:
                node.uv_map = uv_map
    tex.name, tex.label = T_NODE, "T_final" if t_image is not None else "T (original)"
    x0 = tex.location.x + 300
    y0 = tex.location.y
    total = None
    for j, (img, (lname, ldata, p0, *strength)) in enumerate(zip(maps, lamps)):
        y = y0 - 300 * (j + 1)
        mnode = tree.nodes.new("ShaderNodeTexImage")
        mnode.image = img
        mnode.name = mnode.label = f"{MAP_PREFIX}{lname}"
        mnode.interpolation = tex.interpolation
        mnode.extension = tex.extension
        mnode.location = (x0, y)
        if vec_src is not None:
            links.new(vec_src, mnode.inputs["Vector"])
        val = tree.nodes.new("ShaderNodeValue")
        val.name = val.label = f"I {lname}"
        val.location = (x0, y - 180)
        val.outputs[0].default_value = 1.0
        if ldata is not None and p0 > 0:
            _ratio_driver(val.outputs[0], "p", "LIGHT", ldata, "energy", p0)
        elif strength and strength[0][3] > 0:
            material, node_name, input_name, s0 = strength[0]
            _ratio_driver(val.outputs[0], "s", "MATERIAL", material,
                          f'node_tree.nodes["{node_name}"].inputs["{input_name}"].default_value',
                          s0)
        elif ldata is not None:  # lamp off at precompute time: its basis is 0 anyway
            val.outputs[0].default_value = 0.0
        scale = tree.nodes.new("ShaderNodeVectorMath")
        scale.operation = "SCALE"
        scale.location = (x0 + 300, y)
        links.new(mnode.outputs["Color"], scale.inputs[0])
        links.new(val.outputs[0], scale.inputs["Scale"])
        term = scale.outputs[0]
        if ldata is not None:       # the light's colour, relative to its colour at precompute
            colour = tree.nodes.new("ShaderNodeCombineXYZ")
            colour.name = colour.label = f"C {lname}"
            colour.location = (x0 + 300, y - 180)
            c0 = list(ldata.color)
            for ch in range(3):
                colour.inputs[ch].default_value = 1.0
                if c0[ch] > 0:
                    _ratio_driver(colour.inputs[ch], "c", "LIGHT", ldata, f"color[{ch}]",
                                  c0[ch])
            tint = tree.nodes.new("ShaderNodeVectorMath")
            tint.operation = "MULTIPLY"
            tint.location = (x0 + 420, y)
            links.new(term, tint.inputs[0])
            links.new(colour.outputs[0], tint.inputs[1])
            term = tint.outputs[0]
        # The moving objects' shadows (sphere_nodes.py link their factor here; 1 without)
        shadow = tree.nodes.new("ShaderNodeVectorMath")
        shadow.operation = "SCALE"
        shadow.name = shadow.label = f"{SHADOW_PREFIX}{lname}"
        shadow.location = (x0 + 460, y - 120)
        shadow.inputs["Scale"].default_value = 1.0
        links.new(term, shadow.inputs[0])
        term = shadow.outputs[0]
        if total is None:
            total = term
        else:
            add = tree.nodes.new("ShaderNodeVectorMath")
            add.operation = "ADD"
            add.location = (x0 + 500, y)
            links.new(total, add.inputs[0])
            links.new(term, add.inputs[1])
            total = add.outputs[0]
    mul = tree.nodes.new("ShaderNodeVectorMath")
    mul.operation = "MULTIPLY"
    mul.location = (x0 + 700, y0)
    links.new(tex.outputs["Color"], mul.inputs[0])
    if total is not None:
        links.new(total, mul.inputs[1])
    emit = tree.nodes.new("ShaderNodeEmission")
    emit.location = (x0 + 900, y0)
    emit.inputs["Strength"].default_value = 1.0
    links.new(mul.outputs[0], emit.inputs["Color"])
    out = tree.nodes.new("ShaderNodeOutputMaterial")
    out.location = (x0 + 1100, y0)
    out.target = "ALL"
    links.new(emit.outputs["Emission"], out.inputs["Surface"])
    out.is_active_output = True
    return mat


# -- scene-scoped state ------------------------------------------------------------------------

def _scene_objects(scene):
    """The objects of ``scene``, and those of the collections its objects instance."""
    seen, todo, out = set(), list(scene.objects), []
    while todo:
        obj = todo.pop()
        if obj.name_full in seen:
            continue
        seen.add(obj.name_full)
        out.append(obj)
        coll = obj.instance_collection if obj.instance_type == "COLLECTION" else None
        if coll is not None:
            todo.extend(coll.all_objects)
    return out


def _relit_slots(scene):
    """(object, slot index, relit material) for every slot of ``scene``'s objects that holds a
    relit material."""
    for obj in _scene_objects(scene):
        for i, slot in enumerate(obj.material_slots):
            if slot.material is not None and _is_generated(slot.material):
                yield obj, i, slot.material


def restore_originals(scene) -> int:
    """Put the original materials back in every slot of ``scene``'s objects that holds a relit
    material (an override object's slot goes back to its mesh).  Returns the number of slots
    restored.  Relit materials and images are kept until Clear (to compare, or to reassign by
    hand)."""
    count = 0
    for obj, i, mat in list(_relit_slots(scene)):
        slot = obj.material_slots[i]
        orig = original_material(mat)
        if orig is None:
            continue
        slot.material = orig
        if obj.name in mat.get(OBJECT_LINKS, ()) and slot.link == "OBJECT":
            slot.link = "DATA"
        count += 1
    return count


def clear_relight_data(scene, keep_volume=False) -> dict:
    """Restore ``scene``'s originals, then remove the materials and images generated for it (and
    generated ones nothing uses any more, e.g. copies made by a Full Copy of the scene) and the
    stored powers of its lights.  Other scenes' results and the user's data are untouched."""
    key = scene_key(scene)
    restored = restore_originals(scene)
    mats = [m for m in bpy.data.materials if _ours(m, key) or (_is_generated(m) and m.users == 0)]
    for m in mats:
        bpy.data.materials.remove(m)
    imgs = [im for im in bpy.data.images if _ours(im, key) or (_is_generated(im) and im.users == 0)]
    for im in imgs:
        bpy.data.images.remove(im)
    groups = [g for g in bpy.data.node_groups if _ours(g, key)]    # lamp and sphere groups
    for g in groups:
        bpy.data.node_groups.remove(g)
    for obj in [o for o in bpy.data.objects if _ours(o, key) and not keep_volume]:  # EEVEE's volume
        data = obj.data
        bpy.data.objects.remove(obj)
        if isinstance(data, bpy.types.LightProbe) and data.users == 0:
            bpy.data.lightprobes.remove(data)
    lights = 0
    for obj in scene.objects:
        if obj.type == "LIGHT" and POWER0 in obj.data and _editable(obj.data):
            del obj.data[POWER0]
            lights += 1
    return {"restored_slots": restored, "materials": len(mats), "images": len(imgs),
            "lights": lights}


def has_relight_data(scene) -> bool:
    key = scene_key(scene)
    return any(_ours(m, key) for m in bpy.data.materials)


def relit_slot_count(scene) -> int:
    return sum(1 for _ in _relit_slots(scene))


def _editable(idb) -> bool:
    if idb is None:
        return True
    return bool(getattr(idb, "is_editable", idb.library is None)) and idb.library is None


def slot_access(obj):
    """How ``obj``'s material slots can be reassigned: "direct" (local data), "override" (a
    library-override object whose linked mesh holds the slots: an object-level slot is used),
    or None (linked, read-only)."""
    if not _editable(obj):
        return None
    if all(_editable(obj.data if slot.link == "DATA" else obj) for slot in obj.material_slots):
        return "direct"
    return "override" if obj.override_library is not None else None


def slots_editable(obj) -> bool:
    return slot_access(obj) is not None


# -- entry point -------------------------------------------------------------------------------

def write_results(context, scene_data, report, solution) -> dict:
    """Write the display maps and relit materials for ``context.scene``, replacing its previous
    result.  ``report`` is the ReadReport of the same read (groups, lamps, UV maps, sources).

    ``solution``: a ShadowFreeResult (T_final and M_k per image; T_final is written as
    ``"<image>.relight.T"`` unless the correction was off).
    Returns a summary dict (images, materials, objects, lamps, slots, warnings)."""
    from . import sphere_nodes
    scene = context.scene
    warnings = []
    key = scene_key(scene, create=True)
    clear_relight_data(scene, keep_volume=True)     # its bake is the user's to redo or keep

    # Lamps, in the result's order (its maps' order): light data and the power each map is
    # computed at (P0 of the driver p / P0).
    lamps = []
    sources = {src["name"]: src for src in report.lamp_sources}
    for name in solution.solution.scene.lamp_names:
        src = sources.get(name, {})
        obj = bpy.data.objects.get(src.get("object", name))
        if obj is not None and obj.type == "LIGHT":
            p0 = float(src.get("power_ref", obj.data.energy))
            if _editable(obj.data):
                obj.data[POWER0] = p0
            lamps.append((name, obj.data, p0))
        elif src.get("kind") == "emissive" and len(src.get("strength", ())) == 3 and \
                bpy.data.materials.get(src.get("material") or "") is not None:
            # an emissive mesh follows its material's emission Strength (I = s / s0)
            lamps.append((name, None, 1.0, (bpy.data.materials[src["material"]],
                                            *src["strength"])))
        else:
            warnings.append(f"Lamp '{name}' is not a light object: its intensity is fixed at 1")
            lamps.append((name, None, 1.0))
        # where moving objects' shadows (sphere_nodes.py) see the lamp from
        if obj is not None and obj.type == "LIGHT":
            sphere_nodes.make_lamp_group(name, key, obj)
        elif name in scene_data.lamp_names:
            centre, radius = sphere_nodes.emissive_disk(scene_data,
                                                        scene_data.lamp_names.index(name))
            sphere_nodes.make_lamp_group(name, key, None, centre, radius)

    # Materials with image faces (material name -> image index) and the objects using them.
    group = np.asarray(scene_data.group)
    image = np.asarray(scene_data.image) if scene_data.image is not None else np.full(len(group), -1)
    mat_image, mat_objects, mat_uv, no_image = {}, {}, {}, set()
    for g in np.unique(group):
        label, mat_name = report.groups[int(g)]
        imgs = np.unique(image[group == g])
        with_img = imgs[imgs >= 0]
        if len(with_img) and mat_name:
            mat_image.setdefault(mat_name, int(with_img[0]))
            mat_objects.setdefault(mat_name, set()).add(report.sources.get(label, label))
            mat_uv.setdefault(mat_name, set()).add(report.uv_maps.get((label, mat_name), ""))
        if np.any(imgs < 0) and scene_data.lamp is not None and \
                np.any((image < 0) & (group == g) & (np.asarray(scene_data.lamp) < 0)
                       & ~scene_data.virtual):
            no_image.add((label, mat_name))
    for label, mat_name in sorted(no_image):
        warnings.append(f"'{label}' / material '{mat_name or '(none)'}': faces without an "
                        "image texture are left unchanged")

    # Library (read-only) objects keep their materials: no relit copy, no maps for them.
    for mat_name in list(mat_objects):
        keep = set()
        for obj_name in sorted(mat_objects[mat_name]):
            obj = bpy.data.objects.get(obj_name)
            if obj is not None and not slots_editable(obj):
                warnings.append(f"'{obj_name}' is linked from a library (read-only): its "
                                "material is left as is; it still casts shadows")
                continue
            keep.add(obj_name)
        if keep:
            mat_objects[mat_name] = keep
        else:
            del mat_objects[mat_name]
            mat_image.pop(mat_name, None)
    used_images = set(mat_image.values())

    textures = solution.texture if solution.options.mode != "none" else {}
    warnings.extend(_overlap_warnings(scene_data, solution.texel_map))

    # Images, one per (used image, lamp).
    made_images, t_images = {}, {}
    writer = _HalfWriter(key)
    try:
        for i, m in solution.maps.items():
            if i not in used_images:
                continue
            src = scene_data.images[i].name
            direct = solution.direct.get(i) if getattr(solution, "direct", None) else None
            made_images[i] = []
            for j, (lname, *_) in enumerate(lamps):
                img = writer.write(f"{src}.relight.{lname}", m[j],
                                   None if direct is None else direct[j])
                img[MAP_SOURCE], img[MAP_LAMP] = src, lname
                made_images[i].append(img)
            if i in textures:
                t_images[i] = writer.write(f"{src}.relight.T", textures[i])
    finally:
        writer.close()

    # Relit materials.
    relit = {}
    for mat_name, i in mat_image.items():
        orig = bpy.data.materials.get(mat_name)
        if orig is None or i not in made_images:
            continue
        uv_maps = {u for u in mat_uv.get(mat_name, ()) if u}
        if len(uv_maps) > 1:
            warnings.append(f"Material '{mat_name}' is read through different UV maps on "
                            f"different objects ({', '.join(sorted(uv_maps))}): its relit copy "
                            "keeps the material's own UV Map node")
        relit[mat_name] = _relit_material(orig, scene_data.images[i].name, made_images[i], lamps,
                                          key, t_images.get(i),
                                          next(iter(uv_maps)) if len(uv_maps) == 1 else None)

    # Assign.
    objects, assigned = set(), 0
    for mat_name, names in mat_objects.items():
        if mat_name not in relit:
            continue
        for obj_name in names:
            obj = bpy.data.objects.get(obj_name)
            if obj is not None:
                objects.add(obj)
    for obj in sorted(objects, key=lambda o: o.name):
        access = slot_access(obj)
        for slot in obj.material_slots:
            orig = original_material(slot.material)
            if orig is None or orig.name not in relit:
                continue
            new = relit[orig.name]
            if access == "override" and slot.link == "DATA" and not _editable(obj.data):
                slot.link = "OBJECT"
                new[OBJECT_LINKS] = list(new.get(OBJECT_LINKS, ())) + [obj.name]
            slot.material = new
            assigned += 1
    report.warnings.extend(w for w in warnings if w not in report.warnings)
    return {"images": sum(len(v) for v in made_images.values()) + len(t_images),
            "materials": len(relit),
            "objects": len(objects), "slots": assigned, "lamps": len(lamps),
            "warnings": warnings}
