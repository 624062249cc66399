"""Measure Cycles' own radiometry for every Blender light type (Blender 5.0, Cycles CPU bakes).

Each experiment bakes a set of small square "probes" (receiver patches: centre, normal, side,
k x k texels) with a DIFFUSE bake (pass filter DIRECT + COLOR, black world, no adaptive sampling,
no clamping).  All probes of one experiment are faces of ONE mesh whose UVs tile one atlas image
(k x k texels per probe), so one experiment is one ``bpy.ops.object.bake`` call.  Irradiance is
``E = bake * pi / albedo`` (scenes/bake.py's measured unit).  Predictions come from
``scenes/light_models.py`` evaluated at the same texel centres.

Writes benchmarks/results/light_units.md and PNG plots.  Cache: .cache/light_units/<key>.npz.
Run:  PYTHONPATH=. .venv/bin/python benchmarks/light_units.py
"""
from __future__ import annotations

import hashlib
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

RESULTS = ROOT / "benchmarks" / "results"
CACHE = ROOT / ".cache" / "light_units"
ALBEDO = 0.8
STATS = {"bakes": 0, "hits": 0, "seconds": 0.0}


# --------------------------------------------------------------------------- probes
def frame(normal):
    """Orthonormal tangents (u, v) with u x v = normal."""
    n = np.asarray(normal, float)
    n = n / np.linalg.norm(n)
    a = np.array([1.0, 0, 0]) if abs(n[0]) < 0.9 else np.array([0, 1.0, 0])
    u = np.cross(a, n)
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    return u, v


def probe(centre, normal, side=0.01, k=4):
    return {"c": [float(x) for x in centre], "n": [float(x) for x in np.asarray(normal, float)
                                                   / np.linalg.norm(normal)],
            "s": float(side), "k": int(k)}


def texel_points(p):
    """(k*k, 3) texel centres of probe p, row-major (row = v, column = u), and (k*k, 3) normals."""
    c, n, s, k = np.array(p["c"]), np.array(p["n"]), p["s"], p["k"]
    u, v = frame(n)
    t = ((np.arange(k) + 0.5) / k - 0.5) * s
    vv, uu = np.meshgrid(t, t, indexing="ij")
    pts = c + uu.reshape(-1, 1) * u + vv.reshape(-1, 1) * v
    return pts, np.tile(n, (k * k, 1))


# --------------------------------------------------------------------------- bpy scene
def _bpy():
    import bpy
    return bpy


def _diffuse_material(bpy, name, albedo=ALBEDO):
    mat = bpy.data.materials.new(name)      # 5.0: a new material already has a node tree
    nt = mat.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    bsdf = nt.nodes.new("ShaderNodeBsdfDiffuse")
    bsdf.inputs["Color"].default_value = (albedo, albedo, albedo, 1.0)
    nt.links.new(bsdf.outputs[0], out.inputs["Surface"])
    return mat


def _probe_mesh(bpy, probes, name="Probes"):
    """One mesh, one quad per probe, UVs tiling an atlas of k x k tiles -> (obj, W, H, cols)."""
    k = probes[0]["k"]
    assert all(p["k"] == k for p in probes)
    cols = int(math.ceil(math.sqrt(len(probes))))
    rows = int(math.ceil(len(probes) / cols))
    W, H = cols * k, rows * k
    verts, faces, uvs = [], [], []
    for i, p in enumerate(probes):
        c, n, s = np.array(p["c"]), np.array(p["n"]), p["s"]
        u, v = frame(n)
        h = s / 2
        corners = [c - h * u - h * v, c + h * u - h * v, c + h * u + h * v, c - h * u + h * v]
        base = len(verts)
        verts += [tuple(x) for x in corners]
        faces.append((base, base + 1, base + 2, base + 3))
        r, q = divmod(i, cols)
        u0, v0, u1, v1 = q * k / W, r * k / H, (q + 1) * k / W, (r + 1) * k / H
        uvs += [u0, v0, u1, v0, u1, v1, u0, v1]
    me = bpy.data.meshes.new(name)
    me.from_pydata(verts, [], faces)
    uv = me.uv_layers.new(name="UVMap")
    uv.data.foreach_set("uv", np.array(uvs, np.float32))
    me.update()
    obj = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(obj)
    me.materials.append(_diffuse_material(bpy, name + "Mat"))
    return obj, W, H, cols


def _set_props(idblock, props):
    for key, val in props.items():
        if key == "cycles":
            _set_props(idblock.cycles, val)
        else:
            setattr(idblock, key, tuple(val) if isinstance(val, list) else val)


def _add_light(bpy, spec, i):
    """spec: {"type", "props": {...light data...}, "loc", "rot" (euler XYZ, rad), "scale",
    "obj": {...object props...}}."""
    L = bpy.data.lights.new(f"L{i}", spec["type"])
    _set_props(L, spec.get("props", {}))
    lo = bpy.data.objects.new(f"L{i}", L)
    lo.location = spec.get("loc", (0, 0, 0))
    lo.rotation_euler = spec.get("rot", (0, 0, 0))
    lo.scale = spec.get("scale", (1, 1, 1))
    _set_props(lo, spec.get("obj", {}))
    bpy.context.scene.collection.objects.link(lo)
    return lo


def _add_emitter(bpy, spec, i):
    """A mesh emitter: spec {"verts": [[x,y,z],...], "faces": [[...]], "shader": "EMISSION" |
    "PRINCIPLED", "strength", "color", "base_color"}."""
    me = bpy.data.meshes.new(f"E{i}")
    me.from_pydata([tuple(v) for v in spec["verts"]], [], [tuple(f) for f in spec["faces"]])
    me.update()
    obj = bpy.data.objects.new(f"E{i}", me)
    bpy.context.scene.collection.objects.link(obj)
    mat = bpy.data.materials.new(f"E{i}Mat")
    nt = mat.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    col = tuple(spec.get("color", (1, 1, 1))) + (1.0,)
    if spec.get("shader", "EMISSION") == "EMISSION":
        em = nt.nodes.new("ShaderNodeEmission")
        em.inputs["Color"].default_value = col
        em.inputs["Strength"].default_value = spec["strength"]
    else:
        em = nt.nodes.new("ShaderNodeBsdfPrincipled")
        bc = tuple(spec.get("base_color", (0, 0, 0))) + (1.0,)
        em.inputs["Base Color"].default_value = bc
        em.inputs["Emission Color"].default_value = col
        em.inputs["Emission Strength"].default_value = spec["strength"]
    nt.links.new(em.outputs[0], out.inputs["Surface"])
    if "emission_sampling" in spec:
        mat.cycles.emission_sampling = spec["emission_sampling"]
    me.materials.append(mat)
    return obj


def _version():
    return tuple(_bpy().app.version)


def measure(config, samples=256, seed=0, use_cache=True):
    """Bake the probes of ``config`` ({"probes": [...], "lights": [...], "emitters": [...],
    "passes": ["DIRECT", "COLOR"]}); returns (n_probes, k*k, 3) irradiance E (W/m^2)."""
    key_src = json.dumps([config, samples, seed, "light-units-v2", _version()], sort_keys=True)
    key = hashlib.sha256(key_src.encode()).hexdigest()[:24]
    path = CACHE / f"{key}.npz"
    if use_cache and path.exists():
        STATS["hits"] += 1
        return np.load(path)["E"]
    bpy = _bpy()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    world = bpy.data.worlds.new("Black")  # 5.0: a new world has nodes, background 0.05 grey
    world.color = (0, 0, 0)
    for nd in world.node_tree.nodes:
        if nd.type == "BACKGROUND":
            nd.inputs["Color"].default_value = (0, 0, 0, 1)
            nd.inputs["Strength"].default_value = 0.0
    scene.world = world
    probes = config["probes"]
    obj, W, H, cols = _probe_mesh(bpy, probes)
    for i, spec in enumerate(config.get("lights", [])):
        _add_light(bpy, spec, i)
    for i, spec in enumerate(config.get("emitters", [])):
        _add_emitter(bpy, spec, i)
    for i, spec in enumerate(config.get("occluders", [])):
        me = bpy.data.meshes.new(f"O{i}")
        me.from_pydata([tuple(v) for v in spec["verts"]], [], [tuple(f) for f in spec["faces"]])
        me.update()
        me.materials.append(_diffuse_material(bpy, f"O{i}Mat"))
        oo = bpy.data.objects.new(f"O{i}", me)
        bpy.context.scene.collection.objects.link(oo)
        _set_props(oo, spec.get("obj", {}))
    if config.get("link_receiver_only_to_nothing"):
        # light linking: every light lights only a collection holding one dummy mesh (an empty
        # collection would mean "no linking") -> the probes are unlit
        coll = bpy.data.collections.new("LinkTargets")
        dummy = bpy.data.objects.new("LinkDummy", bpy.data.meshes.new("LinkDummy"))
        bpy.context.scene.collection.objects.link(dummy)
        coll.objects.link(dummy)
        for lo in [o for o in scene.objects if o.type == "LIGHT"]:
            lo.light_linking.receiver_collection = coll
    cy = scene.cycles
    scene.render.engine = "CYCLES"
    cy.device = "CPU"
    cy.samples = int(samples)
    cy.seed = int(seed)
    cy.use_adaptive_sampling = False
    cy.sample_clamp_direct = cy.sample_clamp_indirect = 0.0
    cy.max_bounces = cy.diffuse_bounces = int(config.get("bounces", 4))
    cy.use_light_tree = bool(config.get("light_tree", True))
    img = bpy.data.images.new("Atlas", W, H, alpha=False, float_buffer=True)
    img.colorspace_settings.name = "Linear Rec.709"
    nt = obj.data.materials[0].node_tree
    node = nt.nodes.new("ShaderNodeTexImage")
    node.image = img
    nt.nodes.active = node
    vl = bpy.context.view_layer
    obj.select_set(True)
    vl.objects.active = obj
    bk = scene.render.bake
    bk.margin = 0
    bk.target = "IMAGE_TEXTURES"
    passes = set(config.get("passes", ["DIRECT", "COLOR"]))
    t0 = time.perf_counter()
    bpy.ops.object.bake(type="DIFFUSE", pass_filter=passes, margin=0, use_clear=True,
                        target="IMAGE_TEXTURES")
    STATS["seconds"] += time.perf_counter() - t0
    STATS["bakes"] += 1
    px = np.empty(W * H * 4, np.float32)
    img.pixels.foreach_get(px)
    px = px.reshape(H, W, 4)[..., :3]
    k = probes[0]["k"]
    out = np.empty((len(probes), k * k, 3))
    for i in range(len(probes)):
        r, q = divmod(i, cols)
        out[i] = px[r * k:(r + 1) * k, q * k:(q + 1) * k].reshape(-1, 3)
    albedo = ALBEDO if "COLOR" in passes else 1.0
    E = out * np.pi / albedo
    CACHE.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, E=E)
    return E


# --------------------------------------------------------------------------- comparison
def fib_dirs(n, offset=0.5):
    """n well-spread unit vectors (Fibonacci sphere)."""
    i = np.arange(n) + offset
    z = 1 - 2 * i / n
    r = np.sqrt(np.maximum(1 - z * z, 0))
    ph = i * math.pi * (3 - math.sqrt(5))
    return np.stack([r * np.cos(ph), r * np.sin(ph), z], 1)


def tilted_normal(to_light, theta_deg, seed_vec=(0.3, 0.7, 0.2)):
    """Unit normal at angle theta from the unit vector to_light."""
    w = np.asarray(to_light, float)
    w = w / np.linalg.norm(w)
    t = np.cross(w, seed_vec)
    t /= np.linalg.norm(t)
    th = math.radians(theta_deg)
    return math.cos(th) * w + math.sin(th) * t


def compare(config, model, samples=256, seeds=(0, 1)):
    """Bake ``config`` with each seed; ``model(points, normals) -> (m, 3)``.  Returns per-probe
    dict rows: measured mean E (mean over texels and channels, seeds averaged), predicted mean,
    ratio, 1-sigma relative noise of the ratio (from the seed-to-seed texel differences)."""
    Es = [measure(config, samples, s) for s in seeds]
    E = np.mean(Es, 0)
    rows = []
    for i, p in enumerate(config["probes"]):
        pts, nrm = texel_points(p)
        pred = np.asarray(model(pts, nrm), float)
        m, q = E[i].mean(), pred.mean()
        if len(Es) > 1:
            diff = (Es[0][i] - Es[1][i]).mean(1)
            sig = diff.std() / math.sqrt(2) / math.sqrt(diff.size * len(Es))
        else:
            sig = float("nan")
        ok = q > 1e-6     # W/m^2: below this the prediction is a numerical zero
        rows.append({"meas": m, "pred": q, "ratio": m / q if ok else float("nan"),
                     "noise": sig / q if ok else float("nan"), "abs_noise": sig,
                     "meas_rgb": E[i].mean(0), "pred_rgb": pred.mean(0)})
    return rows


def loc_rot_scale(loc=(0, 0, 0), rot=(0, 0, 0), scale=(1, 1, 1)):
    """4x4 world matrix of an object (Euler XYZ: R = Rz Ry Rx), as Blender builds it."""
    cx, cy, cz = np.cos(rot)
    sx, sy, sz = np.sin(rot)
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    M = np.eye(4)
    M[:3, :3] = Rz @ Ry @ Rx @ np.diag(scale)
    M[:3, 3] = loc
    return M


def summarise(label, rows, frac=0.05):
    """One table row for a set of probes: sum ratio, min / max ratio over probes whose predicted
    E exceeds ``frac`` of the largest, median relative noise, largest |meas - pred| / E_max."""
    m = np.array([r["meas"] for r in rows])
    p = np.array([r["pred"] for r in rows])
    ns = np.array([r["abs_noise"] for r in rows])
    lit = p > frac * p.max()
    q = m[lit] / p[lit]
    return {"label": label, "n": len(rows), "sum_ratio": m.sum() / p.sum(), "min": q.min(),
            "max": q.max(), "noise": float(np.median(ns[lit] / p[lit])),
            "dev_max": float(np.abs(m - p).max() / p.max()),
            "unlit_max": float(m[p <= 0].max() / p.max()) if (p <= 0).any() else None}


# --------------------------------------------------------------------------- experiments
import scenes.light_models as LM  # noqa: E402

P = 100.0


def exp_point_far():
    """Point light, radius 0: distance and incidence (one probe per (d, theta))."""
    cases = [(d, 0) for d in (0.1, 0.2, 0.5, 1.0, 2.0, 3.0)] + \
            [(1.0, th) for th in (30, 60, 80, 89)] + [(0.3, th) for th in (45, 85)]
    D = fib_dirs(len(cases))
    probes = [probe(d * u, tilted_normal(-u, th), side=min(0.01, 0.05 * d), k=4)
              for (d, th), u in zip(cases, D)]
    cfg = {"probes": probes, "lights": [{"type": "POINT", "props": {
        "energy": P, "shadow_soft_size": 0.0, "color": [1.0, 0.5, 0.25]}}]}
    rows = compare(cfg, lambda p, n: LM.irradiance_point(p, n, (0, 0, 0), P, (1, .5, .25)), 16)
    out = []
    for (d, th), r, pr in zip(cases, rows, probes):
        pts, nrm = texel_points(pr)                 # the guess at the same texel centres
        dd = np.linalg.norm(pts, axis=1)
        cos = -np.einsum("ij,ij->i", pts, nrm) / dd
        guess = (P * np.mean([1, .5, .25]) * cos / (4 * math.pi ** 2 * dd * dd)).mean()
        out.append({"label": f"d = {d} m, theta = {th} deg", **r,
                    "extra": f"{r['meas'] / guess:.4f}"})
    return out


def exp_point_radius():
    r0 = 0.1
    cases = [(q, 0) for q in (0.5, 0.9, 1.05, 1.2, 1.5, 2, 3, 5, 10, 30)] + \
            [(q, th) for q in (0.5, 1.2, 2, 5) for th in (45, 90, 100, 110, 135)]
    D = fib_dirs(len(cases))
    probes = [probe(q * r0 * u, tilted_normal(-u, th), side=min(0.01, 0.02 * q * r0), k=4)
              for (q, th), u in zip(cases, D)]
    res = {}
    for soft in (True, False):
        cfg = {"probes": probes, "lights": [{"type": "POINT", "props": {
            "energy": P, "shadow_soft_size": r0, "use_soft_falloff": soft}}]}
        rows = compare(cfg, lambda p, n: LM.irradiance_point(p, n, (0, 0, 0), P, radius=r0,
                                                             soft_falloff=soft), 256)
        res[soft] = [{"label": f"soft_falloff={soft}, d/r = {q}, theta = {th}", "q": q,
                      "th": th, **r} for (q, th), r in zip(cases, rows)]
    return res


def _spot_probes(angles, az, d, M, tilt=0.0, side=None):
    axis = -M[:3, 2] / np.linalg.norm(M[:3, 2])
    u, v = frame(axis)
    out = []
    for a, ph in zip(np.radians(angles), np.radians(az)):
        dv = math.cos(a) * axis + math.sin(a) * (math.cos(ph) * u + math.sin(ph) * v)
        out.append(probe(M[:3, 3] + d * dv, tilted_normal(-dv, tilt),
                         side=side or 0.002 * d, k=4))
    return out


def exp_spot():
    """Profiles across the cone edge, scale / rotation, radius blur, use_square."""
    size = math.radians(60)
    prof, summ = {}, []
    angles = np.arange(0.0, 40.0, 0.5)
    az = np.arange(len(angles)) * 137.5
    M = np.eye(4)
    for blend in (0.0, 0.15, 1.0):
        props = dict(energy=P, spot_size=size, spot_blend=blend, shadow_soft_size=0.0)
        cfg = {"probes": _spot_probes(angles, az, 1.0, M), "lights": [{"type": "SPOT",
                                                                         "props": props}]}
        rows = compare(cfg, lambda p, n: LM.irradiance_spot(p, n, M, P, spot_size=size,
                                                            spot_blend=blend), 16)
        prof[f"blend {blend}, r = 0"] = (angles, rows, 1.0, dict(spot_blend=blend))
        summ.append(summarise(f"spot 60 deg, blend {blend}, r = 0, d = 1 m, 80 angles 0-40 deg",
                              rows))
    # radius: near field, soft falloff on / off
    ang_r = np.arange(0.0, 60.0, 1.25)
    az_r = np.arange(len(ang_r)) * 137.5
    for soft in (True, False):
        for d, tilt in ((0.3, 0), (0.15, 0), (0.3, 60), (0.05, 0)):
            props = dict(energy=P, spot_size=size, spot_blend=0.1, shadow_soft_size=0.1,
                         use_soft_falloff=soft)
            cfg = {"probes": _spot_probes(ang_r, az_r, d, M, tilt), "lights": [
                {"type": "SPOT", "props": props}]}
            rows = compare(cfg, lambda p, n: LM.irradiance_spot(
                p, n, M, P, spot_size=size, spot_blend=0.1, radius=0.1, soft_falloff=soft,
                quad=(96, 192)), 512)
            if tilt == 0 and d == 0.3:
                prof[f"blend 0.1, r = 0.1 m, d = 0.3 m, soft_falloff={soft}"] = (
                    ang_r, rows, d, dict(spot_blend=0.1, radius=0.1, soft_falloff=soft))
            summ.append(summarise(f"spot 60 deg, blend 0.1, r = 0.1 m, soft_falloff={soft}, "
                                  f"d = {d} m, tilt {tilt} deg, 48 angles 0-60 deg", rows))
    # object rotation and (non-)uniform scale
    rng = np.random.default_rng(1)
    angles2, az2 = rng.uniform(0, 55, 100), rng.uniform(0, 360, 100)
    for rot, scale in (((0.3, 0.5, 0.2), (1, 2, 1)), ((0.3, 0.5, 0.2), (0.5, 1, 1)),
                       ((0, 0, 0), (1, 1, 2)), ((1.0, -0.4, 2.0), (2, 2, 2)),
                       ((1.0, -0.4, 2.0), (0.7, 1.5, 0.6))):
        Ms = loc_rot_scale((0, 0, 0), rot, scale)
        props = dict(energy=P, spot_size=size, spot_blend=0.3, shadow_soft_size=0.0)
        cfg = {"probes": _spot_probes(angles2, az2, 1.0, Ms), "lights": [
            {"type": "SPOT", "props": props, "rot": list(rot), "scale": list(scale)}]}
        rows = compare(cfg, lambda p, n: LM.irradiance_spot(p, n, Ms, P, spot_size=size,
                                                            spot_blend=0.3), 16)
        summ.append(summarise(f"spot 60 deg, blend 0.3, rot {rot}, scale {scale}", rows))
    props = dict(energy=P, spot_size=size, spot_blend=0.3, shadow_soft_size=0.0,
                 use_square=True)
    cfg = {"probes": _spot_probes(angles2, az2, 1.0, M), "lights": [{"type": "SPOT",
                                                                      "props": props}]}
    rows = compare(cfg, lambda p, n: LM.irradiance_spot(p, n, M, P, spot_size=size,
                                                        spot_blend=0.3), 16)
    summ.append(summarise("spot use_square=True (model: round cone)", rows))
    return prof, summ


def exp_sun():
    rot = (0.4, 0.3, 0.0)
    M = loc_rot_scale((0, 0, 0), rot)
    sdir = -M[:3, 2]
    thetas = [0, 30, 60, 80, 85, 88, 90, 92, 95, 100, 120, 150, 180]
    u, _ = frame(sdir)
    probes = [probe(0.3 * i * u, tilted_normal(-sdir, th), side=0.01, k=4)
              for i, th in enumerate(thetas)]
    out = []
    for ang in (0.0, 10.0, 60.0, 120.0):
        cfg = {"probes": probes, "lights": [{"type": "SUN", "props": {
            "energy": 3.0, "angle": math.radians(ang)}, "rot": list(rot)}]}
        rows = compare(cfg, lambda p, n: LM.irradiance_sun(n, sdir, 3.0,
                                                           angle=math.radians(ang)), 1024)
        for th, r in zip(thetas, rows):
            out.append({"label": f"angle {ang} deg, theta {th} deg", **r,
                        "extra": f"{r['meas'] / (3.0 * max(math.cos(math.radians(th)), 0)):.4f}"
                        if th < 90 else "-"})
    return out


def exp_area():
    rng = np.random.default_rng(3)
    pts = rng.uniform(-0.8, 0.8, (40, 3))
    nrm = rng.normal(size=(40, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    probes = [probe(p, n, side=0.01, k=4) for p, n in zip(pts, nrm)]
    loc, rot = (0.05, -0.02, 0.03), (0.3, -0.2, 0.5)
    summ = []
    for shape, size, sy, scale, norm, expo, col in (
            ("RECTANGLE", 0.5, 0.3, (1, 1, 1), True, 0.0, (1, 1, 1)),
            ("RECTANGLE", 0.5, 0.3, (2, 0.5, 3), True, 0.0, (1, 1, 1)),
            ("SQUARE", 0.3, 0.9, (1, 1, 1), True, 0.0, (1, 1, 1)),
            ("DISK", 0.4, 0.4, (1, 1, 1), True, 0.0, (1, 1, 1)),
            ("ELLIPSE", 0.4, 0.2, (1, 1, 1), True, 0.0, (1, 1, 1)),
            ("ELLIPSE", 0.4, 0.2, (1.5, 1, 1), True, 0.0, (1, 1, 1)),
            ("RECTANGLE", 0.5, 0.3, (1, 1, 1), False, 0.0, (1, 1, 1)),
            ("DISK", 0.4, 0.4, (1, 2, 1), False, 0.0, (1, 1, 1)),
            ("RECTANGLE", 0.5, 0.3, (1, 1, 1), True, 1.5, (0.2, 0.6, 1.0))):
        M = loc_rot_scale(loc, rot, scale)
        props = {"energy": 50.0, "shape": shape, "size": size, "size_y": sy,
                 "normalize": norm, "exposure": expo, "color": list(col)}
        cfg = {"probes": probes, "lights": [{"type": "AREA", "props": props, "loc": list(loc),
                                             "rot": list(rot), "scale": list(scale)}]}
        rows = compare(cfg, lambda p, n: LM.irradiance_area(
            p, n, M, 50.0, col, shape, size, sy, normalize=norm, exposure=expo), 512)
        label = (f"{shape} {size} x {sy}, scale {scale}, normalize {norm}"
                 + (f", exposure {expo}, colour {col}" if expo else ""))
        summ.append(summarise(label + " (40 random probes)", rows))
    return summ


def exp_spread():
    xs = np.linspace(0, 0.9, 19)
    rows_by = {}
    summ = []
    for shape, size, sy in (("RECTANGLE", 0.5, 0.3), ("DISK", 0.4, 0.4)):
        for sp in (120, 60, 20, 4):
            spread = math.radians(sp)
            props = {"energy": 50.0, "shape": shape, "size": size, "size_y": sy,
                     "spread": spread}
            for z, tilt in ((0.5, 0), (0.15, 0), (0.5, 50)):
                nn = np.array([math.sin(math.radians(tilt)), 0, math.cos(math.radians(tilt))])
                probes = [probe((x, 0.3 * x, -z), nn, side=0.005, k=4) for x in xs]
                cfg = {"probes": probes, "lights": [{"type": "AREA", "props": props}]}
                rows = compare(cfg, lambda p, n: LM.irradiance_area(
                    p, n, np.eye(4), 50.0, shape=shape, size=size, size_y=sy, spread=spread),
                    1024)
                rows_by[(shape, sp, z, tilt)] = (xs, rows)
                summ.append(summarise(f"{shape} {size} x {sy}, spread {sp} deg, receivers "
                                      f"{z} m below, tilt {tilt} deg, x = 0..0.9 m", rows))
    return rows_by, summ


QUAD = [[-.15, -.15, 0], [.15, -.15, 0], [.15, .15, 0], [-.15, .15, 0]]


def exp_emission():
    rng = np.random.default_rng(5)
    probes, sides = [], []
    for side in (1, -1):
        for _ in range(6):
            c = np.array([rng.uniform(-.3, .3), rng.uniform(-.3, .3), side * rng.uniform(.1, .6)])
            n = -np.sign(c[2]) * np.array([0, 0, 1.0]) + rng.normal(size=3) * 0.3
            probes.append(probe(c, n / np.linalg.norm(n), 0.005, 4))
            sides.append("front (+Z, winding side)" if side > 0 else "back")
    out = []
    for shader in ("EMISSION", "PRINCIPLED"):
        for es in ("AUTO", "FRONT_BACK", "FRONT"):
            cfg = {"probes": probes, "emitters": [{
                "verts": QUAD, "faces": [[0, 1, 2, 3]], "shader": shader, "strength": 10.0,
                "color": [1, 0.5, 0.25], "emission_sampling": es}]}
            rows = compare(cfg, lambda p, n: LM.irradiance_emissive_polygon(
                p, n, QUAD, 10.0, (1, .5, .25)), 1024)
            for name in ("front (+Z, winding side)", "back"):
                sel = [r for r, s in zip(rows, sides) if s == name]
                out.append(summarise(f"{shader}, emission_sampling {es}, strength 10: {name}",
                                     sel))
    return out


def exp_scalars():
    """Multipliers on one probe 1 m from a radius-0 point light (noise-free)."""
    pr = [probe((0, 0, -1), (0, 0, 1), side=0.01, k=4)]
    base = {"energy": P, "shadow_soft_size": 0.0}
    ref = measure({"probes": pr, "lights": [{"type": "POINT", "props": base}]}, 16)[0].mean(0)
    out = [{"label": "reference: P = 100 W at 1 m, normal incidence", "meas_rgb": ref,
            "pred_rgb": LM.irradiance_point(texel_points(pr[0])[0], texel_points(pr[0])[1],
                                            (0, 0, 0), P).mean(0)}]
    cases = [({"color": [1, 0.5, 0.25]}, lambda: np.array([1, .5, .25])),
             ({"exposure": 1.0}, lambda: np.full(3, 2.0)),
             ({"exposure": -2.0}, lambda: np.full(3, 0.25)),
             ({"diffuse_factor": 0.5}, lambda: np.ones(3)),
             ({"specular_factor": 0.0}, lambda: np.ones(3)),
             ({"volume_factor": 0.0, "transmission_factor": 0.0}, lambda: np.ones(3))]
    for T in (600.0, 800.0, 1000.0, 1500.0, 3000.0, 4500.0, 6500.0, 10000.0, 12000.0, 20000.0):
        cases.append(({"use_temperature": True, "temperature": T},
                      lambda T=T: LM.blackbody_colour(T)))
    cases.append(({"use_temperature": True, "temperature": 3000.0, "color": [1, 0.5, 0.25]},
                  lambda: LM.blackbody_colour(3000.0) * np.array([1, .5, .25])))
    pts, nrm = texel_points(pr[0])
    e_ref = LM.irradiance_point(pts, nrm, (0, 0, 0), P).mean(0)
    for r, soft in ((0.0, True), (0.1, True), (0.1, False)):
        props = {"normalize": False}
        if r:
            props.update(shadow_soft_size=r, use_soft_falloff=soft)
        cases.append((props, lambda r=r, soft=soft: LM.irradiance_point(
            pts, nrm, (0, 0, 0), P, radius=r, soft_falloff=soft, normalize=False).mean(0)
            / e_ref))
    for props, pred in cases:
        p = dict(base)
        p.update(props)
        m = measure({"probes": pr, "lights": [{"type": "POINT", "props": p}]}, 16)[0].mean(0)
        out.append({"label": ", ".join(f"{k} = {v}" for k, v in props.items()),
                    "meas_rgb": m / ref, "pred_rgb": np.asarray(pred(), float)})
    return out


def exp_backfaces():
    pr = [probe((0, 0, 0), (0, 0, 1), 0.02, 4)]
    front = {"type": "POINT", "props": {"energy": P, "shadow_soft_size": 0.0}, "loc": [0, 0, 1]}
    back = {"type": "POINT", "props": {"energy": 2 * P, "shadow_soft_size": 0.0},
            "loc": [0, 0, -1]}
    backarea = {"type": "AREA", "props": {"energy": P, "size": 0.5}, "loc": [0, 0, -1],
                "rot": [math.pi, 0, 0]}
    emit_back = {"verts": [[-.2, -.2, -.5], [.2, -.2, -.5], [.2, .2, -.5], [-.2, .2, -.5]],
                 "faces": [[0, 1, 2, 3]], "strength": 10.0}
    ref = P / (4 * math.pi)
    out = []
    for name, cfg in (("lamp in front (normal side) only", {"lights": [front]}),
                      ("point lamp behind only (2x power)", {"lights": [back]}),
                      ("area lamp behind, facing the plane", {"lights": [backarea]}),
                      ("emissive quad behind", {"emitters": [emit_back]}),
                      ("lamps on both sides", {"lights": [front, back]}),
                      ("lamps on both sides, pass DIRECT+INDIRECT+COLOR",
                       {"lights": [front, back], "passes": ["DIRECT", "INDIRECT", "COLOR"]})):
        cfg["probes"] = pr
        out.append((name, measure(cfg, 256)[0].mean() / ref))
    return out


def render_backface(cam_side, light_side, flip=False, samples=16):
    """Mean pixel of an 8x8 orthographic render of a 2 x 2 m plane (normal +Z unless flip),
    point lamp 1 m from it, divided by albedo E / pi of the lit front side."""
    key = hashlib.sha256(json.dumps(["render-v1", cam_side, light_side, flip, samples,
                                     _version()]).encode()).hexdigest()[:24]
    path = CACHE / f"render_{key}.npz"
    if path.exists():
        return float(np.load(path)["v"])
    bpy = _bpy()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    w = bpy.data.worlds.new("Black")
    for nd in w.node_tree.nodes:
        if nd.type == "BACKGROUND":
            nd.inputs["Strength"].default_value = 0.0
    sc.world = w
    me = bpy.data.meshes.new("Plane")
    me.from_pydata([(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)], [],
                   [(3, 2, 1, 0)] if flip else [(0, 1, 2, 3)])
    me.update()
    me.materials.append(_diffuse_material(bpy, "White"))
    sc.collection.objects.link(bpy.data.objects.new("Plane", me))
    L = bpy.data.lights.new("L", "POINT")
    L.energy, L.shadow_soft_size = P, 0.0
    lo = bpy.data.objects.new("L", L)
    lo.location = (0, 0, light_side)
    sc.collection.objects.link(lo)
    cd = bpy.data.cameras.new("C")
    cd.type, cd.ortho_scale = "ORTHO", 0.1
    co = bpy.data.objects.new("C", cd)
    co.location = (0, 0, 3 * cam_side)
    co.rotation_euler = (0, 0, 0) if cam_side > 0 else (math.pi, 0, 0)
    sc.collection.objects.link(co)
    sc.camera = co
    sc.render.engine = "CYCLES"
    sc.cycles.device = "CPU"
    sc.cycles.samples = samples
    sc.cycles.use_adaptive_sampling = False
    sc.cycles.use_denoising = False
    sc.render.resolution_x = sc.render.resolution_y = 8
    sc.render.resolution_percentage = 100
    sc.render.image_settings.file_format = "OPEN_EXR"
    CACHE.mkdir(parents=True, exist_ok=True)
    sc.render.filepath = str(CACHE / "render_tmp.exr")
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(sc.render.filepath)
    px = np.empty(len(img.pixels), np.float32)
    img.pixels.foreach_get(px)
    v = float(px.reshape(-1, 4)[:, :3].mean() / (ALBEDO * P / (4 * math.pi) / math.pi))
    np.savez(path, v=v)
    return v


def exp_misc():
    pr = [probe((0, 0, 0), (0, 0, 1), 0.02, 4)]
    occ = {"verts": [[-.3, -.3, .5], [.3, -.3, .5], [.3, .3, .5], [-.3, .3, .5]],
           "faces": [[0, 1, 2, 3]]}
    base = {"type": "POINT", "props": {"energy": P, "shadow_soft_size": 0.0}, "loc": [0, 0, 1]}
    ref = P / (4 * math.pi)

    def L(obj=None, **props):
        d = json.loads(json.dumps(base))
        d["props"].update(props)
        if obj:
            d["obj"] = obj
        return d
    tests = [
        ("occluder (0.6 m square) halfway", {"lights": [base], "occluders": [occ]}),
        ("  + light use_shadow = False", {"lights": [L(use_shadow=False)], "occluders": [occ]}),
        ("  + occluder visible_shadow = False",
         {"lights": [base], "occluders": [dict(occ, obj={"visible_shadow": False})]}),
        ("light cycles.max_bounces = 0", {"lights": [L(cycles={"max_bounces": 0})]}),
        ("light object visible_diffuse = False",
         {"lights": [L(obj={"visible_diffuse": False})]}),
        ("light hide_render = True", {"lights": [L(obj={"hide_render": True})]}),
        ("use_custom_distance, cutoff_distance 0.5 m (lamp 1 m away)",
         {"lights": [L(use_custom_distance=True, cutoff_distance=0.5)]}),
        ("light linking: receiver collection without the probe",
         {"lights": [base], "link_receiver_only_to_nothing": True}),
    ]
    out = []
    for name, cfg in tests:
        cfg["probes"] = pr
        out.append((name, measure(cfg, 64)[0].mean() / ref))
    for ang, expect in ((0.2, math.pi * math.sin(0.1) ** 2), (0.0, 1.0)):
        E = measure({"probes": pr, "lights": [{"type": "SUN", "props": {
            "energy": 3.0, "angle": ang, "normalize": False}}]}, 64)[0].mean() / 3.0
        out.append((f"SUN normalize = False, angle {ang} rad: E / S (model {expect:.5f})", E))
    for r, expect in ((0.0, 4.0), (0.1, 4 * math.pi * 0.01 / 1.01)):
        E = measure({"probes": pr, "lights": [{"type": "SPOT", "loc": [0, 0, 1], "props": {
            "energy": P, "shadow_soft_size": r, "normalize": False}}]}, 64)[0].mean() / ref
        out.append((f"SPOT normalize = False, r = {r}: E / E(normalized) (model {expect:.5f})",
                    E))
    return out


# --------------------------------------------------------------------------- report
def _f(x, nd=4):
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "-"
    if abs(x) >= 1000 or (abs(x) < 1e-3 and x != 0):
        return f"{x:.3e}"
    return f"{x:.{nd}g}" if abs(x) >= 1 else f"{x:.{nd}f}"


def _noise(x):
    return "-" if x is None or math.isnan(x) else ("< 1e-4" if x < 1e-4 else f"{x:.4f}")


def detail_table(rows, extra=None):
    head = "| configuration | measured E (W/m^2) | predicted | ratio | 1-sigma noise (rel.) |"
    sep = "|---|---|---|---|---|"
    if extra:
        head += f" {extra} |"
        sep += "---|"
    lines = [head, sep]
    for r in rows:
        ratio = "-" if math.isnan(r["ratio"]) else f"{r['ratio']:.4f}"
        s = (f"| {r['label']} | {_f(r['meas'])} | {_f(r['pred'])} | "
             f"{ratio} | {_noise(r['noise'])} |")
        if extra:
            s += f" {r.get('extra', '-')} |"
        lines.append(s)
    return "\n".join(lines)


def summary_table(rows):
    lines = ["| configuration | probes | sum(meas) / sum(pred) | min ratio | max ratio | "
             "median noise (rel.) | max abs dev / E_max | max meas where pred = 0 (/ E_max) |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        unlit = "-" if r["unlit_max"] is None else f"{r['unlit_max']:.1e}"
        lines.append(f"| {r['label']} | {r['n']} | {r['sum_ratio']:.4f} | {r['min']:.4f} | "
                     f"{r['max']:.4f} | {_noise(r['noise'])} | {r['dev_max']:.4f} | {unlit} |")
    return "\n".join(lines)


def plot_point(res, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    r0 = 0.1
    q = np.logspace(np.log10(0.3), np.log10(40), 300)
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for soft, colr in ((True, "C0"), (False, "C3")):
        pts = np.stack([np.zeros_like(q), np.zeros_like(q), -q * r0], 1)
        nrm = np.tile([0, 0, 1.0], (len(q), 1))
        model = LM.irradiance_point(pts, nrm, (0, 0, 0), P, radius=r0, soft_falloff=soft)[:, 0]
        ax.plot(q, model * 4 * np.pi * (q * r0) ** 2 / P, color=colr,
                label=f"model, soft_falloff={soft}")
        rows = [r for r in res[soft] if r["th"] == 0]
        ax.plot([r["q"] for r in rows], [r["meas"] * 4 * np.pi * (r["q"] * r0) ** 2 / P
                                         for r in rows], "o", color=colr, mfc="none",
                label=f"Cycles bake, soft_falloff={soft}")
    ax.set_xscale("log")
    ax.set_xlabel("distance / radius  (d / r)")
    ax.set_ylabel("E / (P / (4 pi d^2))  (normal incidence)")
    ax.set_title("POINT light near field (r = 0.1 m, Blender 5.0.1 Cycles)")
    ax.axvline(1.0, color="0.7", lw=0.8)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_spot(prof, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    size = math.radians(60)
    fig, ax = plt.subplots(figsize=(6.8, 4.4))
    a_dense = np.linspace(0, 60, 400)
    for i, (name, (angles, rows, d, kw)) in enumerate(prof.items()):
        c = f"C{i}"
        dv = np.stack([np.sin(np.radians(a_dense)), np.zeros_like(a_dense),
                       -np.cos(np.radians(a_dense))], 1)
        pts, nrm = d * dv, -dv
        model = LM.irradiance_spot(pts, nrm, np.eye(4), P, spot_size=size,
                                   quad=(96, 192), **kw)[:, 0]
        E0 = P / (4 * np.pi * d * d)
        ax.plot(a_dense, model / E0, color=c, lw=1)
        ax.plot(angles, [r["meas"] / E0 for r in rows], "o", ms=3, color=c, mfc="none",
                label=name)
    ax.set_xlim(0, 60)
    ax.set_xlabel("angle from the spot axis (deg); spot_size 60 deg")
    ax.set_ylabel("E / (P / (4 pi d^2))")
    ax.set_title("SPOT profile: Cycles bakes (circles) vs scenes/light_models (lines)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_spread(rows_by, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axs = plt.subplots(1, 2, figsize=(10, 4), sharey=True)
    for ax, shape in zip(axs, ("RECTANGLE", "DISK")):
        for i, sp in enumerate((120, 60, 20, 4)):
            xs, rows = rows_by[(shape, sp, 0.5, 0)]
            ax.plot(xs, [r["pred"] for r in rows], color=f"C{i}", lw=1)
            ax.plot(xs, [r["meas"] for r in rows], "o", ms=3, mfc="none", color=f"C{i}",
                    label=f"spread {sp} deg")
        ax.set_title(f"AREA {shape}, 50 W, receivers 0.5 m below")
        ax.set_xlabel("receiver x (m) (y = 0.3 x)")
    axs[0].set_ylabel("E (W/m^2)")
    axs[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main():
    t0 = time.perf_counter()
    RESULTS.mkdir(parents=True, exist_ok=True)
    far = exp_point_far()
    rad = exp_point_radius()
    prof, spot_summ = exp_spot()
    sun = exp_sun()
    area = exp_area()
    spread_rows, spread_summ = exp_spread()
    emis = exp_emission()
    scal = exp_scalars()
    back = exp_backfaces()
    renders = [(desc, render_backface(*args)) for desc, args in (
        ("camera and lamp on the normal side", (1, 1)),
        ("camera and lamp on the back side", (-1, -1)),
        ("camera on the back side, lamp on the normal side", (-1, 1)),
        ("camera on the normal side, lamp on the back side", (1, -1)),
        ("normals flipped (-Z); camera and lamp at +Z", (1, 1, True)))]
    misc = exp_misc()
    plot_point(rad, RESULTS / "light_units_point.png")
    plot_spot(prof, RESULTS / "light_units_spot.png")
    plot_spread(spread_rows, RESULTS / "light_units_spread.png")
    elapsed = time.perf_counter() - t0

    bpy = _bpy()
    L = []
    w = L.append
    w("# Light units: Cycles vs scenes/light_models.py\n")
    w(f"Blender {bpy.app.version_string}, Cycles CPU, DIFFUSE bakes (pass DIRECT + COLOR, black "
      "world, no adaptive sampling, no clamping) of small receiver probes (4 x 4 texels each, "
      f"albedo {ALBEDO}); E = bake x pi / albedo.  Predictions: `scenes/light_models.py` at the "
      "same texel centres.  Noise: 1 sigma of the two-seed mean, from the seed-to-seed texel "
      "differences (relative to the prediction).  Generated by `benchmarks/light_units.py` "
      f"({STATS['bakes']} bakes this run, {STATS['hits']} cache hits, "
      f"{STATS['seconds']:.0f} s baking, {elapsed:.0f} s total).\n")
    w("## 1. POINT light, radius 0: E = P cos(theta) / (4 pi d^2)\n")
    w("Colour (1, 0.5, 0.25), P = 100 W (E is the channel mean).  Last column: measured / the "
      "guess P cos / (4 pi^2 d^2): it is pi, i.e. the intensity is P / (4 pi) W/sr.\n")
    w(detail_table(far, "meas / (P cos / (4 pi^2 d^2))") + "\n")
    w("## 2. POINT light with radius r = 0.1 m (`shadow_soft_size`)\n")
    w("Uniform radiance L = P / (4 pi^2 r^2) over a cone of half-angle beta: sin(beta) = "
      "r / sqrt(d^2 + r^2) with soft falloff (a disk of radius r facing the receiver), "
      "r / d without (a sphere; inside it, d < r, E = pi L on any plane).  theta = angle "
      "between the receiver normal and the direction to the light centre (90 deg and beyond: "
      "the horizon cases).\n")
    w(detail_table(rad[True] + rad[False]) + "\n")
    w("![point](light_units_point.png)\n")
    w("## 3. SPOT light\n")
    w("Same power convention and radius geometry as POINT, times smoothstep((z - cos(s/2)) / "
      "((1 - cos(s/2)) blend)) of the ray light -> receiver in the object's local frame with "
      "the scale divided out per axis (then normalised); no extra cosine; with a radius the "
      "mask is evaluated per point of the source (model: 96 x 192 cone quadrature).  Inside a "
      "sphere spot (d < r, soft falloff off) there is no mask at all.  `use_square` is "
      "ignored by Cycles.\n")
    w(summary_table(spot_summ) + "\n")
    w("![spot](light_units_spot.png)\n")
    w("## 4. SUN light: E = S cos(theta); `angle` only matters at the horizon\n")
    w("S = 3 W/m^2, rotation (0.4, 0.3, 0) rad: light travels along local -Z.  Model: a disc "
      "of angular diameter `angle` with uniform radiance S / (pi sin^2(angle / 2)).  Last "
      "column: measured / (S cos theta).\n")
    w(detail_table(sun, "meas / (S cos)") + "\n")
    w("## 5. AREA lights: shapes, object scale, normalize, exposure, colour\n")
    w("Exitance M = P x colour x 2^exposure / A (A with the object's scale, ellipse area "
      "pi/4 size_x size_y: sizes are diameters); normalize off: M = P x colour x 2^exposure. "
      "One-sided (local -Z).  Model: exact point-to-polygon (256-gon for round shapes).\n")
    w(summary_table(area) + "\n")
    w("## 6. AREA `spread`\n")
    w("Radiance (M / pi) x (tan(h) - tan(a)) / (tan(h) - h) for emission angle a < h = "
      "spread / 2 (0 beyond; 3 / h^3 replaces 1 / (tan h - h) for h <= 0.05): "
      "power-conserving.  Model: midpoint quadrature (96 x 96) over the light clipped to the "
      "spread disc of each receiver.\n")
    w(summary_table(spread_summ) + "\n")
    w("![spread](light_units_spread.png)\n")
    w("## 7. Mesh emission: two-sided, radiance = strength x colour\n")
    w("A 0.3 m square at z = 0, normal +Z; 6 random probes on each side.  Model: "
      "pi x strength x colour x form factor, on BOTH sides.  `emission_sampling` = FRONT "
      "only changes the noise (the back side is then found by BSDF rays only).\n")
    w(summary_table(emis) + "\n")
    w("## 8. Scalar multipliers (POINT, 1 m, radius 0)\n")
    w("| change | measured / reference (R, G, B) | model (R, G, B) |\n|---|---|---|")
    for r in scal:
        w(f"| {r['label']} | {', '.join(f'{x:.4f}' for x in r['meas_rgb'])} | "
          f"{', '.join(f'{x:.4f}' for x in r['pred_rgb'])} |")
    w("\n(The reference row is absolute E in W/m^2.)  Temperature model: "
      "`blackbody_colour` (Planck x CIE 1931 2 deg -> linear Rec.709, luminance 1).  "
      "`diffuse_factor`, `specular_factor`, `volume_factor`, `transmission_factor` do "
      "nothing in Cycles (EEVEE settings); checked in a render too for diffuse_factor.\n")
    w("## 9. Back faces\n")
    w("Bake of a receiver (normal +Z) with lamps on either side; E relative to the front "
      "lamp's P / (4 pi d^2):\n")
    w("| bake setup | E / E_front |\n|---|---|")
    for name, v in back:
        w(f"| {name} | {v:.4f} |")
    w("\nRenders (8 x 8 px, orthographic camera at 3 m, lamp at 1 m; pixel / "
      "(albedo E / pi)):\n")
    w("| render setup | pixel / expected front-lit value |\n|---|---|")
    for name, v in renders:
        w(f"| {name} | {v:.4f} |")
    w("\nBakes see only the normal (winding) side; renders shade whichever side the camera "
      "sees, lit by lamps on that side.\n")
    w("## 10. Other settings (POINT 1 m above the probe unless stated)\n")
    w("| setting | E / E_reference |\n|---|---|")
    for name, v in misc:
        w(f"| {name} | {v:.4f} |")
    (RESULTS / "light_units.md").write_text("\n".join(L) + "\n")
    print(f"wrote {RESULTS / 'light_units.md'} in {elapsed:.0f} s ({STATS})")


if __name__ == "__main__":
    main()
