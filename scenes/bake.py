"""Cycles DIFFUSE bakes of every surface object: the "photographs" of the evaluation harness.

``bake_lighting(lamp_powers, samples=64, seed=0, cache_dir=None, objects=None, ...)`` ->
``{object name: (H, W, 3) float32}``: one Cycles DIFFUSE bake (pass filter direct + indirect +
colour) per surface object into a float image of the object's texture size (the size of its
albedo image), with the lamps set to the given powers (lamps not in ``lamp_powers`` keep their
current power; everything is restored afterwards).  All objects are baked by one
``bpy.ops.object.bake`` call (one scene sync).  Rows are in Blender order (row 0 at v = 0).

Units (measured by ``tests/test_office_bakes.py::test_bake_unit_factor``, Blender 5.0.1): the
DIFFUSE bake with colour is the OUTGOING RADIANCE of the Lambertian surface,
``bake = albedo * E / pi`` with E the irradiance (W/m^2), i.e. the radiosity ``B = albedo * E``
divided by pi.  A white 2 x 2 m plane 1 m under a 100 W, 1 m square light (Normalize on:
exitance 100 W/m^2), 16 x 16 texels, 256 samples: sum(bake) / sum(point_to_polygon x 100) =
0.3182 (1/pi = 0.3183), so ``bake * BAKE_TO_RADIOSITY`` (= pi) / prediction = 0.9997, and texel by
texel within 8 %.  Multiply bakes by ``BAKE_TO_RADIOSITY`` to get radiosity units.

Cost and noise (office, 2 lamps, 9 objects x 48^2 texels, 2 CPU cores): adaptive sampling is
OFF (with it Cycles stops at its noise threshold, and 2048 samples were no less noisy than 256).
Lamp A alone, CIEDE2000 between seeds 0 and 1 over the covered texels: 256 samples 10 s, mean
1.18; 2048 samples 84 s, mean 0.41 (relative RMS 4.2 % -> 1.45 %).

Cycles settings used: CPU, no adaptive sampling, no clamping (clamping would break linearity in the lamp powers),
``diffuse_bounces`` / ``max_bounces`` = ``bounces`` (default 16: with albedos <= 0.8 the missing
tail is < 0.8^17 ~ 2 % of the indirect light at worst, far less in practice), black world.

Cache: key = sha256 of (evaluated world-space vertices and UVs of every baked object, the pixels of
every image its materials use, every light's matrix / type / shape / size / colour / effective
power (and radius / spot / sun angle for non-area lights), every emissive mesh's geometry /
colour / effective strength, samples, seed, bounces, margin, bake size, bpy version) -> ``<cache_dir>/<key>.npz``.
``cache_dir`` defaults to ``$RELIGHT_BAKE_CACHE`` or ``<repo>/.cache/bakes``.  ``CACHE_STATS``
counts hits and misses (tests use it).

``noise_floor(...)``: CIEDE2000 between two bakes with different seeds (linear -> LAB), mean and
95th percentile over all texels, for several sample counts.
"""
from __future__ import annotations

import hashlib
import os
import time

import numpy as np

BAKE_TO_RADIOSITY = np.pi  # bake value x this = radiosity (exitance, W/m^2), measured
CACHE_STATS = {"hits": 0, "misses": 0, "bake_seconds": []}
# The last bake_lighting call: {"seconds": time of the Cycles bake (for a cache hit: as recorded
# when it was baked, None for entries older than this record), "cached": bool}.
LAST_BAKE = {"seconds": None, "cached": False}
_REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def default_cache_dir() -> str:
    return os.environ.get("RELIGHT_BAKE_CACHE") or os.path.join(_REPO, ".cache", "bakes")


def _bpy():
    import bpy  # noqa: PLC0415
    return bpy


def surface_objects(scene=None):
    """Renderable mesh objects of the scene (the relit surfaces), sorted by name; emissive
    meshes (lamps, see ``emission_nodes``) are not surfaces."""
    bpy = _bpy()
    scene = scene or bpy.context.scene
    return sorted((o for o in scene.objects
                   if o.type == "MESH" and not o.hide_render and not emission_nodes(o)),
                  key=lambda o: o.name)


def emission_nodes(obj) -> list:
    """The Emission nodes of an emissive mesh (a lamp made of geometry): a mesh whose materials
    have Emission nodes and no Principled BSDF.  Its "power" in ``bake_lighting`` is their
    Strength (outgoing radiance; exitance pi x Strength per emitting side).  [] otherwise."""
    if obj.type != "MESH":
        return []
    nodes = []
    for slot in obj.material_slots:
        mat = slot.material
        if mat is None or mat.node_tree is None:
            continue
        if any(nd.bl_idname == "ShaderNodeBsdfPrincipled" for nd in mat.node_tree.nodes):
            return []
        nodes += [nd for nd in mat.node_tree.nodes if nd.bl_idname == "ShaderNodeEmission"]
    return nodes


def _lamp_power(obj) -> float:
    """A light's energy, or an emissive mesh's Emission strength."""
    if obj.type == "LIGHT":
        return float(obj.data.energy)
    return float(emission_nodes(obj)[0].inputs["Strength"].default_value)


def _set_lamp_power(obj, value):
    if obj.type == "LIGHT":
        obj.data.energy = float(value)
    else:
        for nd in emission_nodes(obj):
            nd.inputs["Strength"].default_value = float(value)


def _is_lamp(obj) -> bool:
    return obj.type == "LIGHT" or bool(emission_nodes(obj))


def _albedo_image(obj):
    """The image feeding the Base Color of the object's first material (None if there is none)."""
    for slot in obj.material_slots:
        mat = slot.material
        if mat is None or mat.node_tree is None:
            continue
        for node in mat.node_tree.nodes:
            if node.bl_idname == "ShaderNodeBsdfPrincipled":
                sock = node.inputs["Base Color"]
                if sock.is_linked and sock.links[0].from_node.bl_idname == "ShaderNodeTexImage":
                    return sock.links[0].from_node.image
    return None


def _bake_size(obj, default):
    img = _albedo_image(obj)
    if img is not None and img.size[0] > 0:
        return int(img.size[0]), int(img.size[1])
    return default, default


def _lights(scene):
    return sorted((o for o in scene.objects if o.type == "LIGHT"), key=lambda o: o.name)


def _cache_key(scene, objs, lamp_powers, samples, seed, bounces, margin, default_size):
    bpy = _bpy()
    h = hashlib.sha256()

    def add(x):
        if isinstance(x, np.ndarray):
            h.update(str(x.dtype).encode() + str(x.shape).encode())
            h.update(np.ascontiguousarray(x).tobytes())
        else:
            h.update(repr(x).encode())

    add(("relight-office-bake-v2-no-adaptive", bpy.app.version, samples, seed, bounces, margin))
    seen_images = set()
    for o in objs:
        me = o.data
        co = np.empty(len(me.vertices) * 3, np.float32)
        me.vertices.foreach_get("co", co)
        mw = np.array(o.matrix_world, np.float64)
        co = co.reshape(-1, 3) @ mw[:3, :3].T + mw[:3, 3]
        add(o.name)
        add(np.round(co, 6))
        loops = np.empty(len(me.loops), np.int32)
        me.loops.foreach_get("vertex_index", loops)
        add(loops)
        if me.uv_layers.active is not None:
            uv = np.empty(len(me.loops) * 2, np.float32)
            me.uv_layers.active.data.foreach_get("uv", uv)
            add(uv)
        add(_bake_size(o, default_size))
        for slot in o.material_slots:
            mat = slot.material
            if mat is None or mat.node_tree is None:
                continue
            for node in mat.node_tree.nodes:
                if node.bl_idname == "ShaderNodeBsdfPrincipled":
                    add([(i.name, tuple(i.default_value) if hasattr(i.default_value, "__len__")
                          else i.default_value) for i in node.inputs
                         if hasattr(i, "default_value") and not i.is_linked])
                if node.bl_idname == "ShaderNodeTexImage" and node.image is not None:
                    img = node.image
                    add((img.name, tuple(img.size), img.colorspace_settings.name))
                    if img.name not in seen_images:
                        seen_images.add(img.name)
                        px = np.empty(len(img.pixels), np.float32)
                        img.pixels.foreach_get(px)
                        add(px)
    for lo in _lights(scene):
        L = lo.data
        power = float(lamp_powers.get(lo.name, L.energy))
        add((lo.name, L.type, getattr(L, "shape", None), getattr(L, "size", None),
             getattr(L, "size_y", None), tuple(L.color), power, getattr(L, "normalize", True),
             getattr(L, "exposure", 0.0), lo.hide_render))
        add(np.round(np.array(lo.matrix_world, np.float64), 6))
        if L.type != "AREA":  # (only for these types: area-light keys stay as they were)
            add((getattr(L, "shadow_soft_size", None), getattr(L, "spot_size", None),
                 getattr(L, "spot_blend", None), getattr(L, "angle", None),
                 getattr(L, "use_soft_falloff", None)))
    for eo in sorted((o for o in scene.objects if o.type == "MESH" and emission_nodes(o)),
                     key=lambda o: o.name):
        me = eo.data
        co = np.empty(len(me.vertices) * 3, np.float32)
        me.vertices.foreach_get("co", co)
        loops = np.empty(len(me.loops), np.int32)
        me.loops.foreach_get("vertex_index", loops)
        nodes = emission_nodes(eo)
        power = float(lamp_powers.get(eo.name, _lamp_power(eo)))
        mats = [(s.material.name, getattr(s.material, "emission_sampling", None),
                 sorted(nd.bl_idname for nd in s.material.node_tree.nodes))
                for s in eo.material_slots if s.material is not None]
        add(("emitter", eo.name, power, tuple(nodes[0].inputs["Color"].default_value),
             len(nodes), mats, eo.hide_render))
        add(np.round(co, 6))
        add(loops)
        add(np.round(np.array(eo.matrix_world, np.float64), 6))
    # Meshes in the scene that are neither baked nor lamps still cast shadows (a virtual
    # object in a truth bake): they are part of the key.  (None: the key is as it was.)
    baked = {o.name for o in objs}
    for xo in sorted((o for o in scene.objects if o.type == "MESH" and o.name not in baked
                      and not emission_nodes(o) and not o.hide_render), key=lambda o: o.name):
        me = xo.data
        co = np.empty(len(me.vertices) * 3, np.float32)
        me.vertices.foreach_get("co", co)
        mw = np.array(xo.matrix_world, np.float64)
        add(("unbaked", xo.name))
        add(np.round(co.reshape(-1, 3) @ mw[:3, :3].T + mw[:3, 3], 6))
    w = scene.world
    add(None if w is None else (w.name, tuple(getattr(w, "color", ()))))
    return h.hexdigest()


def _run_bake(scene, objs, samples, seed, bounces, margin, default_size):
    """One bpy.ops.object.bake over all objects; returns {name: (H, W, 3) float32}."""
    bpy = _bpy()
    cy = scene.cycles
    saved = dict(engine=scene.render.engine, device=cy.device, samples=cy.samples, seed=cy.seed,
                 diffuse_bounces=cy.diffuse_bounces, max_bounces=cy.max_bounces,
                 clamp_d=cy.sample_clamp_direct, clamp_i=cy.sample_clamp_indirect,
                 adaptive=cy.use_adaptive_sampling)
    scene.render.engine = "CYCLES"
    cy.device = "CPU"
    cy.samples = int(samples)
    cy.seed = int(seed)
    cy.diffuse_bounces = cy.max_bounces = int(bounces)
    cy.sample_clamp_direct = cy.sample_clamp_indirect = 0.0
    # Adaptive sampling stops at its noise threshold: more samples would not lower the noise.
    cy.use_adaptive_sampling = False
    bk = scene.render.bake
    bk.use_pass_direct = bk.use_pass_indirect = bk.use_pass_color = True
    bk.margin = int(margin)
    bk.target = "IMAGE_TEXTURES"

    targets = []  # (obj, node_tree, node, image, previous active node)
    vl = bpy.context.view_layer
    prev_sel = [o for o in vl.objects if o.select_get()]
    prev_active = vl.objects.active
    try:
        for o in vl.objects:
            o.select_set(False)
        for o in objs:
            w, h = _bake_size(o, default_size)
            img = bpy.data.images.new(f"__relight_bake_{o.name}", w, h, alpha=False,
                                      float_buffer=True)
            img.colorspace_settings.name = "Linear Rec.709"
            for slot in o.material_slots:
                mat = slot.material
                if mat is None:
                    continue
                nt = mat.node_tree
                node = nt.nodes.new("ShaderNodeTexImage")
                node.image = img
                targets.append((nt, node, nt.nodes.active))
                nt.nodes.active = node
            o.select_set(True)
            vl.objects.active = o
        t0 = time.perf_counter()
        bpy.ops.object.bake(type="DIFFUSE", pass_filter={"DIRECT", "INDIRECT", "COLOR"},
                            margin=int(margin), use_clear=True, target="IMAGE_TEXTURES")
        CACHE_STATS["bake_seconds"].append(time.perf_counter() - t0)
        out = {}
        for o in objs:
            img = bpy.data.images[f"__relight_bake_{o.name}"]
            w, h = img.size
            px = np.empty(w * h * 4, np.float32)
            img.pixels.foreach_get(px)
            out[o.name] = px.reshape(h, w, 4)[..., :3].copy()
        return out
    finally:
        for nt, node, prev in targets:
            img = node.image
            nt.nodes.remove(node)
            if prev is not None:
                nt.nodes.active = prev
            if img is not None and img.users == 0:
                bpy.data.images.remove(img)
        for o in objs:
            name = f"__relight_bake_{o.name}"
            if name in bpy.data.images:
                bpy.data.images.remove(bpy.data.images[name])
        for o in vl.objects:
            o.select_set(o in prev_sel)
        vl.objects.active = prev_active
        scene.render.engine = saved["engine"]
        cy.device, cy.samples, cy.seed = saved["device"], saved["samples"], saved["seed"]
        cy.diffuse_bounces, cy.max_bounces = saved["diffuse_bounces"], saved["max_bounces"]
        cy.sample_clamp_direct, cy.sample_clamp_indirect = saved["clamp_d"], saved["clamp_i"]
        cy.use_adaptive_sampling = saved["adaptive"]


def bake_lighting(lamp_powers: dict, samples: int = 64, seed: int = 0, cache_dir: str | None = None,
                  objects=None, bounces: int = 16, margin: int = 3, texture_size: int = 48,
                  use_cache: bool = True) -> dict:
    """DIFFUSE bakes (direct + indirect + colour) of every surface object under ``lamp_powers``.

    lamp_powers: light object name -> power (W), or emissive mesh name -> Emission strength;
    other lamps keep their power.  objects: names
    (default: every renderable mesh).  texture_size: bake size for objects without an albedo
    image.  Returns {object name: (H, W, 3) float32}, bake units (radiance; x BAKE_TO_RADIOSITY
    for radiosity).
    """
    bpy = _bpy()
    scene = bpy.context.scene
    bpy.context.view_layer.update()  # matrix_world of freshly moved objects
    objs = (surface_objects(scene) if objects is None
            else [bpy.data.objects[n] for n in objects])
    for name in lamp_powers:
        if name not in scene.objects or not _is_lamp(scene.objects[name]):
            raise KeyError(f"no light object or emissive mesh {name!r} in the scene")
    key = _cache_key(scene, objs, lamp_powers, samples, seed, bounces, margin, texture_size)
    cache_dir = cache_dir or default_cache_dir()
    path = os.path.join(cache_dir, key + ".npz")
    if use_cache and os.path.exists(path):
        try:
            with np.load(path) as z:
                out = {o.name: z[f"o{i}"] for i, o in enumerate(objs)}
                secs = float(z["_seconds"]) if "_seconds" in z.files else None
            CACHE_STATS["hits"] += 1
            LAST_BAKE.update(seconds=secs, cached=True)
            return out
        except (OSError, KeyError, ValueError):
            pass  # corrupt entry: bake again
    CACHE_STATS["misses"] += 1
    saved = {}
    try:
        for name, p in lamp_powers.items():
            saved[name] = _lamp_power(scene.objects[name])
            _set_lamp_power(scene.objects[name], p)
        t0 = time.perf_counter()
        out = _run_bake(scene, objs, samples, seed, bounces, margin, texture_size)
        LAST_BAKE.update(seconds=time.perf_counter() - t0, cached=False)
    finally:
        for name, p in saved.items():
            _set_lamp_power(scene.objects[name], p)
    if use_cache:
        os.makedirs(cache_dir, exist_ok=True)
        tmp = path + f".{os.getpid()}.tmp.npz"
        np.savez_compressed(tmp, _seconds=np.float64(LAST_BAKE["seconds"]),
                            **{f"o{i}": out[o.name] for i, o in enumerate(objs)})
        os.replace(tmp, path)
    return out


def target_lightings(lamp_powers: dict) -> dict:
    """The lightings of the evaluation harness: label -> {lamp name: power}.

    "original"; "<lamp> off" for each lamp; "<lamp> doubled" for each lamp; "only <lamp>" (all
    lamps but one off).  With two lamps "A off" and "only B" are the same lighting (and the same
    cache entry when baked with the same seed)."""
    out = {"original": dict(lamp_powers)}
    for name, p in lamp_powers.items():
        out[f"{name} off"] = {**lamp_powers, name: 0.0}
    for name, p in lamp_powers.items():
        out[f"{name} doubled"] = {**lamp_powers, name: 2.0 * p}
    for name, p in lamp_powers.items():
        out[f"only {name}"] = {k: (v if k == name else 0.0) for k, v in lamp_powers.items()}
    return out


def stack(bakes: dict, names=None) -> np.ndarray:
    """Concatenate per-object bakes into one (N, 3) array of texels (names in sorted order)."""
    names = sorted(bakes) if names is None else names
    return np.concatenate([bakes[n].reshape(-1, 3) for n in names])


def delta_e_2000_texels(a: dict, b: dict, masks: dict | None = None) -> np.ndarray:
    """Per-texel CIEDE2000 between two bake dicts (linear RGB -> LAB), optionally masked."""
    from relight_addon.core.texture.colour import delta_e_2000, linear_rgb_to_lab  # noqa: PLC0415
    names = sorted(a)
    x, y = stack(a, names), stack(b, names)
    if masks is not None:
        m = np.concatenate([masks[n].ravel() for n in names])
        x, y = x[m], y[m]
    x, y = np.clip(x, 0.0, None), np.clip(y, 0.0, None)
    return delta_e_2000(linear_rgb_to_lab(x), linear_rgb_to_lab(y))


def coverage_masks(objects=None, texture_size: int = 48) -> dict:
    """{object name: (H, W) bool}: texels whose centre lies inside one of the object's UV faces
    (margin texels excluded from statistics)."""
    bpy = _bpy()
    objs = (surface_objects() if objects is None else [bpy.data.objects[n] for n in objects])
    out = {}
    for o in objs:
        w, h = _bake_size(o, texture_size)
        me = o.data
        uv = np.empty(len(me.loops) * 2, np.float32)
        me.uv_layers.active.data.foreach_get("uv", uv)
        uv = uv.reshape(-1, 2)
        mask = np.zeros((h, w), bool)
        u = (np.arange(w) + 0.5) / w
        v = (np.arange(h) + 0.5) / h
        for p in me.polygons:  # few faces per object: a loop over faces is fine here
            f = uv[p.loop_start:p.loop_start + p.loop_total]
            u0, u1, v0, v1 = f[:, 0].min(), f[:, 0].max(), f[:, 1].min(), f[:, 1].max()
            mask[np.ix_((v > v0) & (v < v1), (u > u0) & (u < u1))] = True
        out[o.name] = mask
    return out


def noise_floor(lamp_powers: dict | None = None, samples_list=(16, 64), seeds=(0, 1),
                cache_dir: str | None = None, **kw) -> dict:
    """CIEDE2000 between two bakes that differ only by their seed, per sample count.

    Returns {samples: {"mean": ..., "p95": ..., "max": ...}} over the covered texels of every
    surface object."""
    lamp_powers = lamp_powers or {}
    masks = coverage_masks(kw.get("objects"), kw.get("texture_size", 48))
    out = {}
    for s in samples_list:
        a = bake_lighting(lamp_powers, samples=s, seed=seeds[0], cache_dir=cache_dir, **kw)
        b = bake_lighting(lamp_powers, samples=s, seed=seeds[1], cache_dir=cache_dir, **kw)
        de = delta_e_2000_texels(a, b, masks)
        out[s] = {"mean": float(de.mean()), "p95": float(np.percentile(de, 95)),
                  "max": float(de.max())}
    return out


# -- what a render shows of the relit materials ---------------------------------------------

def _image_pixels(img):
    buf = np.empty(len(img.pixels), np.float32)
    img.pixels.foreach_get(buf)
    return buf.reshape(img.size[1], img.size[0], -1)


def emit_bake(bpy, names, materials=None):
    """{object: (H, W, 3)} Cycles EMIT bake (1 sample) of each object's first material (or of
    ``materials[name]``, assigned for the bake) at the size of its texture."""
    scene = bpy.context.scene
    cy = scene.cycles
    saved = (scene.render.engine, cy.device, cy.samples, cy.use_adaptive_sampling)
    scene.render.engine = "CYCLES"
    cy.device, cy.samples, cy.use_adaptive_sampling = "CPU", 1, False
    vl = bpy.context.view_layer
    for o in vl.objects:
        o.select_set(False)
    made = []
    try:
        for name in names:
            obj = bpy.data.objects[name]
            relit = obj.material_slots[0].material
            size = relit.node_tree.nodes["T"].image.size if "T" in relit.node_tree.nodes else \
                (48, 48)
            mat = relit
            if materials is not None:
                mat = materials[name]
                obj.material_slots[0].material = mat
            img = bpy.data.images.new(f"__bench_emit_{name}", size[0], size[1], float_buffer=True)
            img.colorspace_settings.name = "Linear Rec.709"
            node = mat.node_tree.nodes.new("ShaderNodeTexImage")
            node.image = img
            prev = mat.node_tree.nodes.active
            mat.node_tree.nodes.active = node
            made.append((obj, relit, mat, node, img, prev))
            obj.select_set(True)
            vl.objects.active = obj
        assert bpy.ops.object.bake(type="EMIT", margin=2, use_clear=True,
                                   target="IMAGE_TEXTURES") == {"FINISHED"}
        return {obj.name: _image_pixels(img)[..., :3].astype(np.float64).copy()
                for obj, _, _, _, img, _ in made}
    finally:
        for obj, relit, mat, node, img, prev in made:
            mat.node_tree.nodes.remove(node)
            if prev is not None:
                mat.node_tree.nodes.active = prev
            bpy.data.images.remove(img)
            obj.material_slots[0].material = relit
            obj.select_set(False)
        scene.render.engine, cy.device, cy.samples, cy.use_adaptive_sampling = saved
