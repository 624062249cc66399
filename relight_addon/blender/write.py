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

from dataclasses import dataclass

import bpy
import numpy as np

from ..core.relight.maps import DISPLAY_EPS, SEAM_PIXELS, map_images, ratio_maps
from ..core.texture.mapping import rasterize_patches
from . import ids, materials
from .drivers import ratio_driver
from .images import CONTENT, MapWriter
from .nodes import Builder

T_NODE = "T"
MAP_PREFIX = "M "          # the node of lamp k's map image: "M <lamp name>"
SHADOW_PREFIX = "S "       # lamp k's moving-shadow factor: "S <lamp name>" (Scale input)
_LEGACY_USE_NODES = bpy.app.version < (5, 0, 0)


@dataclass
class LampTerm:
    """One lamp of the maps as the relit materials follow it: its label, the light object it
    follows (None for an emissive mesh or a lamp whose light is gone), the power ``p0`` and
    colour ``color0`` its map was computed at, an emissive mesh's strength (material, node,
    input, strength then), and whether its light was deleted (then its term is off)."""
    label: str
    obj: object = None
    p0: float = 1.0
    color0: tuple = (1.0, 1.0, 1.0)
    strength: tuple | None = None
    gone: bool = False

    @property
    def light(self):
        return self.obj.data if self.obj is not None else None


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


def _relit_material(orig, image_name, maps, lamps, key, t_image=None, uv_map=None):
    """The relit copy of ``orig``: ``maps`` one bpy image per lamp, ``lamps`` their LampTerms,
    ``t_image`` the shadow-free texture T_final (None: the original image is T), ``uv_map`` the
    UV map the reader used for this material (its UV Map nodes are pointed at it)."""
    mat = orig.copy()
    mat.name = orig.name + ids.MAT_SUFFIX
    ids.tag(mat, key)
    mat[ids.ORIGINAL] = orig
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
    b = Builder(tree, tex.location.x + 300, tex.location.y)
    total = None
    for j, (img, lamp) in enumerate(zip(maps, lamps)):
        # one row of columns per lamp: map, intensity, colour, shadow factor, sum
        b.at(col=0, row=1 + 2 * j)
        mnode = b.node("ShaderNodeTexImage", f"{MAP_PREFIX}{lamp.label}", image=img,
                       interpolation=tex.interpolation, extension=tex.extension)
        if vec_src is not None:
            b.link(vec_src, mnode.inputs["Vector"])
        val = b.node("ShaderNodeValue", f"I {lamp.label}")
        val.outputs[0].default_value = 1.0
        if lamp.gone:           # its light was deleted: the lamp is off
            val.outputs[0].default_value = 0.0
        elif lamp.light is not None and lamp.p0 > 0:
            ratio_driver(val.outputs[0], "p", "LIGHT", lamp.light, "energy", lamp.p0)
        elif lamp.strength is not None and lamp.strength[3] > 0:
            material, node_name, input_name, s0 = lamp.strength
            ratio_driver(val.outputs[0], "s", "MATERIAL", material,
                         f'node_tree.nodes["{node_name}"].inputs["{input_name}"].default_value',
                         s0)
        elif lamp.light is not None:  # lamp off at precompute time: its basis is 0 anyway
            val.outputs[0].default_value = 0.0
        b.column().at(row=1 + 2 * j)
        scale = b.node("ShaderNodeVectorMath", operation="SCALE")
        b.link(mnode.outputs["Color"], scale.inputs[0])
        b.link(val.outputs[0], scale.inputs["Scale"])
        term = scale.outputs[0]
        if lamp.light is not None and not lamp.gone:
            # the light's colour, relative to its colour when the map was computed
            colour = b.node("ShaderNodeCombineXYZ", f"C {lamp.label}")
            for ch in range(3):
                colour.inputs[ch].default_value = 1.0
                if lamp.color0[ch] > 0:
                    ratio_driver(colour.inputs[ch], "c", "LIGHT", lamp.light, f"color[{ch}]",
                                 lamp.color0[ch])
            b.column().at(row=1 + 2 * j)
            tint = b.node("ShaderNodeVectorMath", operation="MULTIPLY")
            b.link(term, tint.inputs[0])
            b.link(colour.outputs[0], tint.inputs[1])
            term = tint.outputs[0]
        # The moving objects' shadows (sphere_nodes.py link their factor here; 1 without)
        b.at(col=3, row=1 + 2 * j)
        shadow = b.node("ShaderNodeVectorMath", f"{SHADOW_PREFIX}{lamp.label}",
                        operation="SCALE")
        shadow.inputs["Scale"].default_value = 1.0
        b.link(term, shadow.inputs[0])
        term = shadow.outputs[0]
        if total is None:
            total = term
        else:
            b.at(col=4, row=1 + 2 * j)
            add = b.node("ShaderNodeVectorMath", operation="ADD")
            b.link(total, add.inputs[0])
            b.link(term, add.inputs[1])
            total = add.outputs[0]
    b.at(col=5, row=0)
    mul = b.node("ShaderNodeVectorMath", operation="MULTIPLY")
    b.link(tex.outputs["Color"], mul.inputs[0])
    if total is not None:
        b.link(total, mul.inputs[1])
    b.column()
    emit = b.node("ShaderNodeEmission")
    emit.inputs["Strength"].default_value = 1.0
    b.link(mul.outputs[0], emit.inputs["Color"])
    b.column()
    out = b.node("ShaderNodeOutputMaterial", target="ALL")
    b.link(emit.outputs["Emission"], out.inputs["Surface"])
    out.is_active_output = True
    return mat


# -- scene-scoped state ------------------------------------------------------------------------

STALE_PREFIX = "~relight replaced "     # a relit material on its way out (write_results)

def clear_relight_data(scene, keep_volume=False, keep_images=(), stale=None) -> dict:
    """Restore ``scene``'s originals, then remove the materials and images generated for it (and
    generated ones nothing uses any more, e.g. copies made by a Full Copy of the scene) and the
    stored powers of its lights.  Other scenes' results and the user's data are untouched.
    ``keep_images``: images to leave (a write about to take them again).  ``stale`` (a list):
    the materials are renamed and put there instead of removed, for the caller to remove once
    it has made their successors (see write_results)."""
    key = ids.scene_key(scene)
    restored = materials.restore_originals(scene)
    # and generated data nothing uses (a relit material another scene sharing objects with this
    # one took the slots of has a fake user: it stays for that scene)
    mats = [m for m in bpy.data.materials
            if ids.ours(m, key) or (ids.is_generated(m) and m.users == 0)]
    for m in mats:
        if stale is None:
            bpy.data.materials.remove(m)
        else:
            m.name = f"{STALE_PREFIX}{m.name}"
            del m[ids.GENERATED]           # no longer found as ours meanwhile
            stale.append(m)
    keep = {im.as_pointer() for im in keep_images}
    imgs = [im for im in bpy.data.images if im.as_pointer() not in keep and
            (ids.ours(im, key) or (ids.is_generated(im) and im.users == 0))]
    for im in imgs:
        bpy.data.images.remove(im)
    groups = [g for g in bpy.data.node_groups if ids.ours(g, key)]    # lamp and sphere groups
    for g in groups:
        bpy.data.node_groups.remove(g)
    if not keep_volume:
        from . import eevee_shadow
        eevee_shadow.remove(key)          # the moving shadows' probe lights
    for obj in [o for o in bpy.data.objects if ids.ours(o, key) and not keep_volume]:  # EEVEE's
        data = obj.data
        bpy.data.objects.remove(obj)
        if isinstance(data, bpy.types.LightProbe) and data.users == 0:
            bpy.data.lightprobes.remove(data)
    lights = 0
    for obj in scene.objects:
        if obj.type == "LIGHT" and ids.POWER0 in obj.data and ids.editable(obj.data):
            del obj.data[ids.POWER0]
            lights += 1
    return {"restored_slots": restored, "materials": len(mats), "images": len(imgs),
            "lights": lights}


def has_relight_data(scene) -> bool:
    key = ids.scene_key(scene)
    return any(ids.ours(m, key) for m in bpy.data.materials)


# -- entry point -------------------------------------------------------------------------------

def write_results(context, scene_data, report, solution, lamps) -> dict:
    """Write the display maps and relit materials for ``context.scene``, replacing its previous
    result.  ``report`` is the ReadReport of the same read (groups, UV maps, sources);
    ``lamps`` one LampTerm per lamp of ``solution`` (a ShadowFreeResult), in its maps' order.

    T_final is written as ``"<image>.relight.T"`` unless the correction was off.  Returns a
    summary dict (images, materials, objects, lamps, slots, warnings)."""
    from . import sphere_nodes
    scene = context.scene
    warnings = []
    key = ids.scene_key(scene, create=True)
    # the maps and textures written before: taken again where they hold the same values
    old = {im.name: im for im in bpy.data.images if ids.ours(im, key) and CONTENT in im
           and (ids.MAP_SOURCE in im or im.name.endswith(".relight.T"))}
    # the old materials go only once their successors exist: a new material allocated where a
    # removed one was left a mesh's or object's slot byte for byte as it was, so memfile undo
    # took that datablock as unchanged and kept a pointer to the freed material (Blender
    # crashed building the depsgraph after a redo: deg_tag_eval_copy_id from build_material)
    replaced = []
    clear_relight_data(scene, keep_volume=True, keep_images=old.values(), stale=replaced)  # (the EEVEE volume's
    # bake is the user's to redo or keep)
    try:

        for lamp in lamps:
            if lamp.light is not None and ids.editable(lamp.light):
                lamp.light[ids.POWER0] = float(lamp.p0)
            # where moving objects' shadows (sphere_nodes.py) see the lamp from
            if lamp.obj is not None:
                sphere_nodes.make_lamp_group(lamp.label, key, lamp.obj)
            elif lamp.label in scene_data.lamp_names:
                centre, radius = sphere_nodes.emissive_disk(
                    scene_data, scene_data.lamp_names.index(lamp.label))
                sphere_nodes.make_lamp_group(lamp.label, key, None, centre, radius)

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
                if obj is not None and not materials.slots_editable(obj):
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
        with MapWriter(key, reuse=old) as writer:
            for i, m in solution.maps.items():
                if i not in used_images:
                    continue
                src = scene_data.images[i].name
                direct = solution.direct.get(i) if getattr(solution, "direct", None) else None
                made_images[i] = []
                for j, lamp in enumerate(lamps):
                    img = writer.write(f"{src}.relight.{lamp.label}", m[j],
                                       None if direct is None else direct[j])
                    img[ids.MAP_SOURCE], img[ids.MAP_LAMP] = src, lamp.label
                    made_images[i].append(img)
                if i in textures:
                    t_images[i] = writer.write(f"{src}.relight.T", textures[i])
            for stale in writer.reuse.values():          # old maps nobody writes again
                bpy.data.images.remove(stale)
        if writer.full_float:
            warnings.append(f"{len(writer.full_float)} image(s) hold values above 65504 (photos in "
                            f"absolute units?): written as 32-bit float, not clipped "
                            f"('{writer.full_float[0]}'...)")
        if writer.non_finite:
            warnings.append(f"{len(writer.non_finite)} image(s) had NaN or infinite values, written "
                            f"as 0 ('{writer.non_finite[0]}'...): please report it")

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
        others = [s for s in bpy.data.scenes if s != scene]
        for obj in sorted(objects, key=lambda o: o.name):
            for i, slot in enumerate(obj.material_slots):
                shown = slot.material
                orig = materials.original_material(shown)
                if orig is None or orig.name not in relit:
                    continue
                if shown is not None and ids.is_generated(shown) and not ids.ours(shown, key):
                    sharing = [s.name for s in others if ids.ours(shown, ids.scene_key(s))]
                    warnings.append(f"'{obj.name}' is also in scene "
                                    f"'{sharing[0] if sharing else '?'}': it now shows this "
                                    "scene's relit material (Update there shows that scene's)")
                    shown.use_fake_user = True          # that scene's, kept for it
                materials.assign(obj, i, relit[orig.name], key)
                assigned += 1
        report.warnings.extend(w for w in warnings if w not in report.warnings)
        return {"images": sum(len(v) for v in made_images.values()) + len(t_images),
                "materials": len(relit),
                "objects": len(objects), "slots": assigned, "lamps": len(lamps),
                "warnings": warnings}
    finally:
        for m in replaced:
            bpy.data.materials.remove(m)
