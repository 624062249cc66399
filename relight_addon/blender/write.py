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
* Per-lamp leaf radiosity is turned into element-vertex values and interpolated per texel
  (:func:`vertex_interpolate` twin: ``vertex_values`` once per lamp, then per image).
* ``D`` is floored at ``DISPLAY_EPS * max(D)`` (per channel, max over every written texel):
  where ``D`` is below it every ``M_k`` is 0 (unlit texels render black), never NaN/Inf.
* Seams are dilated (``SEAM_PIXELS`` rings) so bilinear filtering does not pull in black.
* Images ``"<image>.relight.<lamp>"``: float, Non-Color, RGBA (alpha 1), half-float OpenEXR
  (ZIP), packed into the .blend; their user is the relit material.  Half floats quantise M_k
  (spacing 2**-11 just below 1), so the written maps sum to 1 within about 1e-3, while
  :func:`display_maps` sums to 1 within float rounding.
* Materials ``"<material>.relight"``: a copy of the original whose tree keeps only the original
  Image Texture node and what feeds its Vector input (UV Map node, mapping...), plus
  ``T * sum_k(I_k * M_k)`` -> Emission (strength 1) -> Material Output.  ``I_k`` is a Value
  node whose output is driven by the SCRIPTED simple expression ``p / P0`` (``p`` = the light
  data's ``energy``, ``P0`` its value at precompute time written as a literal); simple
  expressions evaluate with Python auto-run off and without the extension.  ``P0`` is also
  kept as ``light.data["relight_power0"]``.  Only ``energy`` is tracked: colour / exposure
  changes of a light are not followed.  Emissive-face lamps have no light to follow: their
  ``I_k`` is a constant 1 (reported).
* Objects: slots holding a relit material get the ``.relight`` copy; the original names are
  kept in the object property ``relight_original_materials`` (one name per slot, "" for
  slots left alone) for :func:`restore_originals`.
* Every generated datablock carries the ID property ``relight_generated = 1`` so
  :func:`clear_relight_data` removes exactly those, and nothing else.
"""
from __future__ import annotations

from contextlib import contextmanager

import bpy
import numpy as np

from ..core.relight.maps import DISPLAY_EPS, SEAM_PIXELS, map_images, ratio_maps
from ..core.texture.mapping import rasterize_patches

GENERATED = "relight_generated"
ORIGINALS = "relight_original_materials"
POWER0 = "relight_power0"
HALF_MAX = 65504.0
T_NODE = "T"
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


def _float_image(name, rgb):
    hh, ww = rgb.shape[:2]
    img = bpy.data.images.new(name, ww, hh, alpha=True, float_buffer=True)
    img.colorspace_settings.name = "Non-Color"
    rgba = np.ones((hh, ww, 4), np.float32)
    rgba[..., :3] = rgb
    img.pixels.foreach_set(rgba.reshape(-1))
    return img


class _HalfWriter:
    """Half-float OpenEXR through ``Image.save_render`` with a temporary scene whose output
    settings are EXR / 16 bit / ZIP (``Image.save`` + ``use_half_precision`` writes 32-bit
    float in Blender 5.0.1: measured from the EXR channel list).  The file is loaded, packed
    and deleted; the image keeps the relative path ``//relight/<name>.exr`` for unpacking.
    Linear EXR output gets no view transform (values above 1 round-trip unchanged)."""

    def __init__(self):
        import tempfile
        self.dir = tempfile.mkdtemp(prefix="relight_")
        self.scene = bpy.data.scenes.new("relight_tmp_exr_settings")
        s = self.scene.render.image_settings
        s.file_format = "OPEN_EXR"
        s.color_mode = "RGBA"
        s.color_depth = "16"
        s.exr_codec = "ZIP"

    def write(self, name, rgb):
        import os
        rgb = np.clip(np.nan_to_num(rgb), -HALF_MAX, HALF_MAX)   # half floats end at 65504
        tmp = _float_image("relight_tmp_image", rgb)
        path = os.path.join(self.dir, "image.exr")
        try:
            tmp.save_render(path, scene=self.scene)
            img = bpy.data.images.load(path, check_existing=False)
            img.colorspace_settings.name = "Non-Color"
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
            img = _float_image(name, rgb)
            img.file_format = "OPEN_EXR"
            img.pack()
        img[GENERATED] = 1
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


def _add_driver(socket, light_data, p0, label):
    fc = socket.driver_add("default_value")
    for mod in list(fc.modifiers):
        fc.modifiers.remove(mod)
    drv = fc.driver
    drv.type = "SCRIPTED"
    var = drv.variables.new()
    var.name = "p"
    var.type = "SINGLE_PROP"
    var.targets[0].id_type = "LIGHT"
    var.targets[0].id = light_data
    var.targets[0].data_path = "energy"
    drv.expression = f"p / {float(p0)!r}"
    return fc


def _relit_material(orig, image_name, maps, lamps, t_image=None):
    """maps: list of bpy images (one per lamp); lamps: list of (name, light data or None, P0);
    t_image: the shadow-free texture T_final (None: the original image is T)."""
    mat = orig.copy()
    mat.name = orig.name + MAT_SUFFIX
    mat[GENERATED] = 1
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
    tex.name, tex.label = T_NODE, "T_final" if t_image is not None else "T (original)"
    x0 = tex.location.x + 300
    y0 = tex.location.y
    total = None
    for j, (img, (lname, ldata, p0)) in enumerate(zip(maps, lamps)):
        y = y0 - 300 * (j + 1)
        mnode = tree.nodes.new("ShaderNodeTexImage")
        mnode.image = img
        mnode.name = mnode.label = f"M {lname}"
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
            _add_driver(val.outputs[0], ldata, p0, lname)
        elif ldata is not None:  # lamp off at precompute time: its basis is 0 anyway
            val.outputs[0].default_value = 0.0
        scale = tree.nodes.new("ShaderNodeVectorMath")
        scale.operation = "SCALE"
        scale.location = (x0 + 300, y)
        links.new(mnode.outputs["Color"], scale.inputs[0])
        links.new(val.outputs[0], scale.inputs["Scale"])
        if total is None:
            total = scale.outputs[0]
        else:
            add = tree.nodes.new("ShaderNodeVectorMath")
            add.operation = "ADD"
            add.location = (x0 + 500, y)
            links.new(total, add.inputs[0])
            links.new(scale.outputs[0], add.inputs[1])
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


@contextmanager
def originals_swapped(context=None):
    """Temporarily put the original materials back (e.g. to read the scene), then re-apply."""
    swaps = _swap_to_originals()
    try:
        yield swaps
    finally:
        for slot_owner, i, relit in swaps:
            slot_owner.material_slots[i].material = relit


def _swap_to_originals():
    swaps = []
    for obj in bpy.data.objects:
        names = obj.get(ORIGINALS)
        if names is None:
            continue
        for i, slot in enumerate(obj.material_slots):
            if i >= len(names) or not names[i]:
                continue
            cur = slot.material
            orig = bpy.data.materials.get(names[i])
            if cur is not None and _is_generated(cur) and orig is not None:
                slot.material = orig
                swaps.append((obj, i, cur))
    return swaps


def restore_originals(context=None) -> int:
    """Put the original materials back in every slot that holds a relit one; forget the record.
    Returns the number of slots restored.  Relit materials and images are not deleted."""
    swaps = _swap_to_originals()
    for obj in bpy.data.objects:
        if ORIGINALS in obj:
            del obj[ORIGINALS]
    # Slots of objects without a record (e.g. sharing a mesh with a relit object).
    count = len(swaps)
    for obj in bpy.data.objects:
        for slot in obj.material_slots:
            mat = slot.material
            if mat is not None and _is_generated(mat) and mat.name.endswith(MAT_SUFFIX):
                orig = bpy.data.materials.get(mat.name[: -len(MAT_SUFFIX)])
                if orig is not None and not _is_generated(orig):
                    slot.material = orig
                    count += 1
    return count


def clear_relight_data(context=None) -> dict:
    """Restore the originals, then remove every generated material and image and the stored
    properties (``relight_power0`` on lights).  Nothing else is touched."""
    restored = restore_originals(context)
    mats = [m for m in bpy.data.materials if _is_generated(m)]
    imgs = [im for im in bpy.data.images if _is_generated(im)]
    for m in mats:
        bpy.data.materials.remove(m)
    for im in imgs:
        bpy.data.images.remove(im)
    lights = 0
    for light in bpy.data.lights:
        if POWER0 in light:
            del light[POWER0]
            lights += 1
    return {"restored_slots": restored, "materials": len(mats), "images": len(imgs),
            "lights": lights}


def has_relight_data() -> bool:
    return any(_is_generated(m) for m in bpy.data.materials) or \
        any(_is_generated(i) for i in bpy.data.images)


def _editable(idb) -> bool:
    if idb is None:
        return True
    return bool(getattr(idb, "is_editable", idb.library is None)) and idb.library is None


def slots_editable(obj) -> bool:
    """Whether every material slot of ``obj`` can be reassigned (slots linked to the object
    live in the object, the others in its mesh; library data is read-only)."""
    return _editable(obj) and all(_editable(obj.data if slot.link == "DATA" else obj)
                                  for slot in obj.material_slots)


# -- entry point -------------------------------------------------------------------------------

def write_results(context, scene_data, report, solution) -> dict:
    """Write the display maps and relit materials; replaces a previous result (clear first).

    ``solution``: a ShadowFreeResult (T_final and M_k per image; T_final is written as
    ``"<image>.relight.T"`` unless the correction was off).
    Returns a summary dict (images, materials, objects, lamps, skipped, warnings)."""
    warnings = []
    clear_relight_data(context)

    # Lamps: light data and power at precompute time.
    lamps = []
    for name in scene_data.lamp_names:
        obj = bpy.data.objects.get(name)
        if obj is not None and obj.type == "LIGHT":
            p0 = float(obj.data.energy)
            obj.data[POWER0] = p0
            if p0 <= 0:
                warnings.append(f"Lamp '{name}' has no power at precompute time: its map is 0")
            lamps.append((name, obj.data, p0))
        else:
            warnings.append(f"Lamp '{name}' is not a light object: its intensity is fixed at 1")
            lamps.append((name, None, 1.0))

    # Materials with image faces (material name -> image index) and the objects using them.
    group = np.asarray(scene_data.group)
    image = np.asarray(scene_data.image) if scene_data.image is not None else np.full(len(group), -1)
    mat_image, mat_objects, no_image = {}, {}, set()
    for g in np.unique(group):
        obj_name, mat_name = report.groups[int(g)]
        imgs = np.unique(image[group == g])
        with_img = imgs[imgs >= 0]
        if len(with_img) and mat_name:
            mat_image.setdefault(mat_name, int(with_img[0]))
            mat_objects.setdefault(mat_name, set()).add(obj_name)
        if np.any(imgs < 0) and scene_data.lamp is not None and \
                np.any((image < 0) & (group == g) & (np.asarray(scene_data.lamp) < 0)):
            no_image.add((obj_name, mat_name))
    for obj_name, mat_name in sorted(no_image):
        warnings.append(f"'{obj_name}' / material '{mat_name or '(none)'}': faces without an "
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
    writer = _HalfWriter()
    try:
        for i, m in solution.maps.items():
            if i not in used_images:
                continue
            src = scene_data.images[i].name
            made_images[i] = [writer.write(f"{src}.relight.{lname}", m[j])
                              for j, (lname, _, _) in enumerate(lamps)]
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
        relit[mat_name] = _relit_material(orig, scene_data.images[i].name, made_images[i], lamps,
                                          t_images.get(i))

    # Assign: record every object's originals first (meshes may be shared), then swap.
    objects = set()
    for mat_name, names in mat_objects.items():
        if mat_name not in relit:
            continue
        for obj_name in names:
            obj = bpy.data.objects.get(obj_name)
            if obj is None:
                warnings.append(f"'{obj_name}' is an instance: its material is not replaced")
                continue
            objects.add(obj)
    objects = sorted(objects, key=lambda o: o.name)
    for obj in objects:
        obj[ORIGINALS] = [s.material.name if s.material is not None and s.material.name in relit
                          else "" for s in obj.material_slots]
    assigned = 0
    for obj in objects:
        for slot in obj.material_slots:
            if slot.material is not None and slot.material.name in relit:
                slot.material = relit[slot.material.name]
                assigned += 1
    report.warnings.extend(w for w in warnings if w not in report.warnings)
    return {"images": sum(len(v) for v in made_images.values()) + len(t_images),
            "materials": len(relit),
            "objects": len(objects), "slots": assigned, "lamps": len(lamps),
            "warnings": warnings}
