"""Exact virtual objects at many placements (issue 42 item 6): their shadows against Cycles truth.
Writes results/object_placements.md and results/object_placements.png.

Rooms: the demo office (scenes.office, seed 0, 2 lamps, OFFICE_TEXELS per surface) and rooms of
the family (scenes.family, built at FAMILY_TEXELS per wall: 20 a ceiling rectangle and a wall
disk, 21 a pendant point lamp and a wall spot, 12 (held out) a ceiling disk and a pendant point,
14 (held out) four lamps: ellipse, rectangle, a wall point and a spot, 8 a ceiling square and a
glowing lampshade standing 1.2 m over the floor).  Objects (grey Lambertian, albedo 0.5): a
sphere (radius 0.25 m, 32 x 16 faces), a box (0.5 m) and Suzanne (size 0.4), placed on the floor
in the open, near a lamp (on the floor under or beside it), partly under a table, on a table or a
box, against a wall.

Per room: the photo (Cycles DIFFUSE bake of the true-albedo room, every lamp on, seed 0) and per
placement the truth (the same bake with the object really there, seed 1); SAMPLES samples, cached
by scenes/bake.py.  The room is read as photographed (the photo bakes as its textures) and
precomputed per preset (``shadow_free``, per texel); each placement is read with the object's
role 'virtual' (shadows Exact) and inserted with ``core.relight.virtual.add_objects`` (what Update
runs), timed.

Scores (mean CIEDE2000; linear colour over the 99th percentile of the truth's luminance, as
tests/test_virtual_objects.py): over the room's covered texels that the truth shows lit (truth >
0.05 x photo: not the floor hidden under the object), and in the object's shadow: texels the truth
shows darker than the photo by more than 20 % and not hidden (> 0.05 x photo), within NEAR of the
object (photo and truth are two seeds: far from the object a texel is darker by noise only).
Beside "Exact", "ignored": the room's maps without the object (the baseline).  Target (issue 42):
Exact <= 3.0 in the shadow at every placement and at least 3x better than ignored.

    python benchmarks/bench_object_placements.py                 # bakes (cached), reads, scores
    python benchmarks/bench_object_placements.py --rooms 21,12 --presets medium
    python benchmarks/bench_object_placements.py --score-only    # from the state of a former run

The bpy part (build, bake, read) writes each room's scene reads and bakes to --state; the scoring
part is bpy-free and keeps each room's precompute there too (keyed by the core's source, less
object_change.py and virtual.py), so that reruns after a change to the object insertion cost
only the insertions.
"""
from __future__ import annotations

import argparse
import glob
import hashlib
import json
import os
import pickle
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, ROOT)

LUM = np.array([0.2126, 0.7152, 0.0722])
SAMPLES = 512
OFFICE_TEXELS = 48
FAMILY_TEXELS = 32
TABLE_SCALE = 3       # family tables' textures at 3 x FAMILY_TEXELS / 2 (their tops 8 texels a side)
PRESETS = ("draft", "medium")
DARKER = 0.8          # truth below this x photo: in the object's shadow
HIDDEN = 0.05         # truth below this x photo: hidden under the object (not scored)
NEAR = 2.0            # m from the object's centre: where its shadow is looked for
NOISE = 0.02          # of white: a shadow texel is darker than the photo by more than this
TARGET, BETTER = 3.0, 3.0
STATE = os.path.join(tempfile.gettempdir(), "relight_bench_object_placements")
SPHERE_R, BOX, SUZANNE = 0.25, 0.5, 0.4

# (label, category, shape, (x, y), height of the surface it rests on)
PLACEMENTS = {
    "office": [
        ("sphere, open floor", "floor in the open", "sphere", (2.9, 3.3), 0.0),
        ("sphere under lamp B", "near a lamp", "sphere", (3.6, 2.0), 0.0),
        ("sphere under lamp A, beside the table", "near a lamp", "sphere", (1.6, 1.2), 0.0),
        ("sphere partly under the table", "partly under a table", "sphere", (1.6, 2.45), 0.0),
        ("sphere on the table", "on a table", "sphere", (1.6, 2.0), 0.76),
        ("sphere against the east wall", "against a wall", "sphere", (4.74, 1.6), 0.0),
        ("box, open floor", "floor in the open", "box", (2.7, 3.2), 0.0),
        ("Suzanne on the table", "on a table", "suzanne", (1.85, 1.85), 0.76),
    ],
    "room 20": [
        ("sphere, open floor", "floor in the open", "sphere", (0.9, 0.7), 0.0),
        ("sphere under the wall disk", "near a lamp", "sphere", (3.5, 2.0), 0.0),
        ("sphere under the ceiling lamp", "near a lamp", "sphere", (0.9, 1.6), 0.0),
        ("sphere partly under the table", "partly under a table", "sphere", (2.4, 1.6), 0.0),
        ("sphere on the table", "on a table", "sphere", (1.8, 1.6), 0.74),
    ],
    "room 21": [
        ("sphere, open floor", "floor in the open", "sphere", (2.0, 2.3), 0.0),
        ("sphere under the pendant point", "near a lamp", "sphere", (2.4, 1.0), 0.0),
        ("sphere beside the pendant point", "near a lamp", "sphere", (2.9, 0.6), 0.0),
        ("sphere on the box", "on a table", "sphere", (1.1, 1.05), 0.5),
        ("sphere against the east wall", "against a wall", "sphere", (3.24, 1.8), 0.0),
        ("box under the pendant point", "near a lamp", "box", (2.4, 1.0), 0.0),
    ],
    "room 12": [
        ("sphere, open floor", "floor in the open", "sphere", (3.0, 0.9), 0.0),
        ("sphere under the pendant point", "near a lamp", "sphere", (4.5, 2.4), 0.0),
        ("sphere under the ceiling disk", "near a lamp", "sphere", (2.0, 0.7), 0.0),
        ("sphere partly under the table", "partly under a table", "sphere", (1.8, 1.51), 0.0),
        ("sphere on the table", "on a table", "sphere", (1.25, 1.5), 0.72),
        ("sphere against the east wall", "against a wall", "sphere", (5.24, 1.0), 0.0),
        ("Suzanne on the table", "on a table", "suzanne", (1.3, 1.5), 0.72),
    ],
    "room 14": [
        ("sphere, open floor", "floor in the open", "sphere", (1.0, 2.9), 0.0),
        ("sphere by the wall point lamp", "near a lamp", "sphere", (2.7, 0.55), 0.0),
        ("sphere under the ellipse", "near a lamp", "sphere", (1.2, 1.2), 0.0),
        ("sphere on box 1", "on a table", "sphere", (1.96, 1.66), 0.5),
        ("sphere against the west wall", "against a wall", "sphere", (0.26, 2.0), 0.0),
    ],
    "room 8": [
        ("sphere, open floor", "floor in the open", "sphere", (1.6, 1.0), 0.0),
        ("sphere beside the lampshade", "near a lamp", "sphere", (0.95, 4.2), 0.0),
        ("sphere under the ceiling square", "near a lamp", "sphere", (1.2, 2.0), 0.0),
        ("sphere against the west wall", "against a wall", "sphere", (0.26, 3.0), 0.0),
    ],
}


# -- bpy part: build, bake, read ------------------------------------------------------------------

def _add_object(bpy, shape, xy, z0, name="VObject"):
    from scenes.materials import grey_diffuse
    if shape == "sphere":
        bpy.ops.mesh.primitive_uv_sphere_add(radius=SPHERE_R, segments=32, ring_count=16,
                                             location=(*xy, z0 + SPHERE_R))
    elif shape == "box":
        bpy.ops.mesh.primitive_cube_add(size=BOX, location=(*xy, z0 + 0.5 * BOX))
    elif shape == "suzanne":
        bpy.ops.mesh.primitive_monkey_add(size=SUZANNE, location=(*xy, z0 + 0.3),
                                          rotation=(0.0, 0.0, 1.0))
    else:
        raise ValueError(shape)
    obj = bpy.context.active_object
    obj.name = name
    obj.data.materials.append(grey_diffuse(bpy))
    bpy.context.view_layer.update()
    zmin = min((obj.matrix_world @ v.co).z for v in obj.data.vertices)
    obj.location.z += z0 - zmin + 0.002            # resting on the surface, 2 mm above it
    bpy.context.view_layer.update()
    return obj


def _build(bpy, room):
    """Build ``room`` in a factory-empty scene with its true albedo: (surface names, lamp
    powers, {surface: albedo image name})."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    if room == "office":
        from scenes.office import build_office
        info = build_office(seed=0, n_lamps=2, texture_size=OFFICE_TEXELS)
        return list(info.objects), dict(info.lamp_powers), dict(info.albedo_images)
    from scenes import family as fam
    spec = fam.room_spec(int(room.split()[1]), texel=FAMILY_TEXELS)
    for srf in spec.surfaces:         # a table's atlas of 22 faces: 3 texels a side of its top
        if srf.name.startswith("Table"):
            srf.albedo = np.repeat(np.repeat(srf.albedo, TABLE_SCALE, 0), TABLE_SCALE, 1)
    info = fam.build_room(spec, "visible")
    return list(info["objects"]), spec.lamp_powers, dict(info["albedo_images"])


def bake_and_read(room, state, log):
    """Bake the room's photo and each placement's truth (cached), read the photographed room
    and each placement; write them to ``state``."""
    import bpy

    from relight_addon.blender.read import read_scene
    from scenes.bake import LAST_BAKE, bake_lighting
    surfaces, power, albedo = _build(bpy, room)
    size = OFFICE_TEXELS if room == "office" else FAMILY_TEXELS
    bakes = []

    def bake(seed):
        t0 = time.perf_counter()
        out = bake_lighting(power, samples=SAMPLES, seed=seed, texture_size=size,
                            objects=surfaces)
        bakes.append((time.perf_counter() - t0, LAST_BAKE["cached"]))
        return out
    photo = bake(0)
    truths = []
    for label, _, shape, xy, z0 in PLACEMENTS[room]:
        obj = _add_object(bpy, shape, xy, z0)
        truths.append(bake(1))
        bpy.data.objects.remove(obj)
        log(f"{room}: {label}: truth baked in {bakes[-1][0]:.0f} s"
            + (" (cached)" if bakes[-1][1] else ""))
    for name in surfaces:                          # photographed: the photo is the texture
        img = bpy.data.images[albedo[name]]
        rgb = np.asarray(photo[name], np.float32)
        rgba = np.ones(rgb.shape[:2] + (4,), np.float32)
        rgba[..., :3] = rgb
        img.pixels.foreach_set(rgba.ravel())
        img.update()
    bpy.context.view_layer.update()
    data, report = read_scene(bpy.context)
    if report.errors:
        raise RuntimeError(f"{room}: {report.errors}")
    image_name = {v: k for k, v in albedo.items()}
    order = [image_name[im.name] for im in data.images]
    reads = []
    for (label, _, shape, xy, z0), truth in zip(PLACEMENTS[room], truths):
        obj = _add_object(bpy, shape, xy, z0)
        d, rep = read_scene(bpy.context, roles={obj.name: "virtual"})
        if rep.errors or not d.virtual.any():
            raise RuntimeError(f"{room}, {label}: {rep.errors} (virtual patches "
                               f"{int(d.virtual.sum())})")
        pts = np.array([obj.matrix_world @ v.co for v in obj.data.vertices])
        reads.append({"data": d, "centre": 0.5 * (pts.min(0) + pts.max(0)),
                      "truth": [np.asarray(truth[n], np.float32) for n in order]})
        bpy.data.objects.remove(obj)
    _save(_state_path(state, room), {"room": data, "photo": [np.asarray(photo[n], np.float32)
                                                         for n in order],
                                 "reads": reads, "order": order,
                                 "bake_seconds": [b[0] for b in bakes if not b[1]]})


def _state_path(state, room):
    return os.path.join(state, room.replace(" ", "_"))


def _save(path, obj):
    """``obj`` (core objects, arrays, builtins) to ``path``.{pkl,npy} by core/persist.py."""
    from relight_addon.core import persist
    header, blob = persist.pack(obj)
    np.save(path + ".npy", blob)
    with open(path + ".pkl", "wb") as f:
        pickle.dump(header, f)


def _load(path):
    from relight_addon.core import persist
    with open(path + ".pkl", "rb") as f:
        header = pickle.load(f)
    return persist.unpack(header, np.load(path + ".npy"))


# -- scoring (bpy-free) ---------------------------------------------------------------------------

def _core_key():
    """sha1 of the core's sources that a room's precompute depends on (not the insertion)."""
    h = hashlib.sha1()
    for p in sorted(glob.glob(os.path.join(ROOT, "relight_addon", "core", "**", "*.py"),
                              recursive=True)):
        if os.path.basename(p) in ("object_change.py", "virtual.py"):
            continue
        with open(p, "rb") as f:
            h.update(f.read())
    return h.hexdigest()[:12]


def _precompute(state, room, data, preset):
    from relight_addon.core.relight.shadowfree import ShadowFreeOptions, shadow_free
    path = _state_path(state, room) + f".{preset}.{_core_key()}"
    if os.path.exists(path + ".pkl"):
        return _load(path), None
    t0 = time.perf_counter()
    res = shadow_free(data, ShadowFreeOptions(preset=preset))
    seconds = time.perf_counter() - t0
    _save(path, res)
    return res, seconds


def score_room(state, room, presets, log):
    from relight_addon.core.relight.settled import texel_points
    from relight_addon.core.relight.virtual import add_objects
    from relight_addon.core.texture.colour import delta_e_2000, linear_rgb_to_lab
    st = _load(_state_path(state, room))
    rows = []
    for preset in presets:
        res, t_pre = _precompute(state, room, st["room"], preset)
        tm = res.texel_map
        photo = tm.gather(st["photo"]).astype(np.float64)
        ignored = res.relit()
        ignored = tm.gather([ignored[i] for i in range(len(st["order"]))]).astype(np.float64)
        x, _ = texel_points(res.solution.scene if res.scene is None else res.scene, tm)
        for (label, cat, shape, _, _), rd in zip(PLACEMENTS[room], st["reads"]):
            want = tm.gather(rd["truth"]).astype(np.float64)
            t0 = time.perf_counter()
            with_obj = add_objects(res, rd["data"])
            t_add = time.perf_counter() - t0
            got = with_obj.relit()
            got = tm.gather([got[i] for i in range(len(st["order"]))]).astype(np.float64)
            w_l, p_l = want @ LUM, photo @ LUM
            white = np.percentile(w_l, 99)
            visible = w_l > HIDDEN * p_l
            near = np.linalg.norm(x - rd["centre"], axis=1) < NEAR
            shadow = visible & near & (w_l < DARKER * p_l) & (p_l - w_l > NOISE * white)

            def de(a):
                return delta_e_2000(linear_rgb_to_lab(np.clip(a / white, 0, None)),
                                    linear_rgb_to_lab(np.clip(want / white, 0, None)))
            d_ex, d_ig = de(got), de(ignored)
            row = dict(room=room, preset=preset, label=label, category=cat, shape=shape,
                       shadow_texels=int(shadow.sum()), visible_texels=int(visible.sum()),
                       exact_shadow=float(d_ex[shadow].mean()) if shadow.any() else None,
                       ignored_shadow=float(d_ig[shadow].mean()) if shadow.any() else None,
                       exact_all=float(d_ex[visible].mean()),
                       ignored_all=float(d_ig[visible].mean()),
                       add_seconds=t_add, precompute_seconds=t_pre)
            rows.append(row)
            log(f"{room} {preset} {label}: shadow ({row['shadow_texels']} texels) exact "
                f"{_f(row['exact_shadow'])} ignored {_f(row['ignored_shadow'])}; overall "
                f"{row['exact_all']:.2f} / {row['ignored_all']:.2f}; add {t_add:.2f} s")
    return rows


def _f(x, fmt="{:.2f}"):
    return "-" if x is None else fmt.format(x)


# -- report ---------------------------------------------------------------------------------------

def verdict(r):
    if r["exact_shadow"] is None:
        return "no shadow"
    miss = []
    if r["exact_shadow"] > TARGET:
        miss.append("> 3.0")
    if r["ignored_shadow"] < BETTER * r["exact_shadow"]:
        miss.append("< 3x")
    return "met" if not miss else "missed: " + ", ".join(miss)


def write_report(rows, out, note, seconds):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    presets = sorted({r["preset"] for r in rows}, key=lambda p: PRESETS.index(p)
                     if p in PRESETS else 9)
    load = os.getloadavg()
    lines = [
        "# Exact virtual objects at many placements: their shadows against Cycles truth", "",
        f"Generated by `benchmarks/bench_object_placements.py` (see its docstring) in "
        f"{seconds / 60:.1f} min; load average at the end {load[0]:.1f} (2 cores).  Rooms: the "
        f"demo office ({OFFICE_TEXELS} texels per surface) and family rooms 20, 21, 12, 14, 8 "
        f"({FAMILY_TEXELS} texels per wall), photo and truth baked by Cycles ({SAMPLES} samples, "
        "seeds 0 and 1).  Grey objects (albedo 0.5): a sphere of radius 0.25 m, a 0.5 m box, "
        "Suzanne (0.4), inserted with `add_objects` (Update, shadows Exact) on the room's "
        "precompute.  Mean CIEDE2000 in the object's shadow (truth < 0.8 x photo, > 0.05 x photo, "
        f"within {NEAR:.0f} m of the object) and over the texels the truth shows lit; ignored = "
        "the room's maps without the object.  Target: Exact <= 3.0 in the shadow and >= 3x "
        "better than ignored.", ""]
    if note:
        lines += [note, ""]
    for preset in presets:
        sub = [r for r in rows if r["preset"] == preset]
        met = sum(verdict(r) == "met" for r in sub)
        lines += [f"## {preset}", "",
                  f"{met} of {len(sub)} placements meet the target.", "",
                  "| room | placement | category | shadow texels | Exact shadow | ignored "
                  "shadow | x better | Exact overall | ignored overall | add_objects | target |",
                  "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---|"]
        for r in sub:
            xb = (r["ignored_shadow"] / r["exact_shadow"]) if r["exact_shadow"] else None
            lines.append(f"| {r['room']} | {r['label']} | {r['category']} | "
                         f"{r['shadow_texels']} | {_f(r['exact_shadow'])} | "
                         f"{_f(r['ignored_shadow'])} | {_f(xb, '{:.1f}')} | "
                         f"{r['exact_all']:.2f} | {r['ignored_all']:.2f} | "
                         f"{r['add_seconds']:.2f} s | {verdict(r)} |")
        pre = {r["room"]: r["precompute_seconds"] for r in sub if r["precompute_seconds"]}
        if pre:
            lines += ["", "Precompute of the rooms (this run): " + ", ".join(
                f"{k} {v:.1f} s" for k, v in pre.items())]
        lines.append("")
    lines += ["![placements](object_placements.png)", "",
              "object_placements.png: mean CIEDE2000 in each object's shadow, Exact and "
              "ignored, per placement and preset; the dashed line is the 3.0 target."]
    with open(out, "w") as f:
        f.write("\n".join(lines) + "\n")
    fig, axes = plt.subplots(len(presets), 1, figsize=(12, 4.2 * len(presets)), squeeze=False)
    for ax, preset in zip(axes[:, 0], presets):
        sub = [r for r in rows if r["preset"] == preset and r["exact_shadow"] is not None]
        pos = np.arange(len(sub))
        ax.bar(pos - 0.2, [r["ignored_shadow"] for r in sub], 0.4, label="ignored",
               color="0.7")
        ax.bar(pos + 0.2, [r["exact_shadow"] for r in sub], 0.4, label="Exact",
               color="tab:blue")
        ax.axhline(TARGET, ls="--", color="tab:red", label="target 3.0")
        ax.set_xticks(pos)
        ax.set_xticklabels([f"{r['room']}: {r['label']}" for r in sub], rotation=70,
                           ha="right", fontsize=7)
        ax.set_ylabel("mean CIEDE2000 in the shadow")
        ax.set_title(f"Exact virtual objects' shadows vs Cycles truth ({preset})")
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.splitext(out)[0] + ".png", dpi=110)


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--rooms", default=",".join(PLACEMENTS))
    ap.add_argument("--presets", default=",".join(PRESETS))
    ap.add_argument("--state", default=STATE)
    ap.add_argument("--score-only", action="store_true")
    ap.add_argument("--bake-only", action="store_true")
    ap.add_argument("--out", default=os.path.join(HERE, "results", "object_placements.md"))
    ap.add_argument("--raw", default=None, help="JSON of the rows (default: next to --out)")
    ap.add_argument("--note", default="")
    args = ap.parse_args(argv)
    rooms = [r.strip() for r in args.rooms.split(",") if r.strip()]
    rooms = [r if r == "office" or r.startswith("room") else f"room {r}" for r in rooms]
    os.makedirs(args.state, exist_ok=True)
    t0 = time.perf_counter()

    def log(msg):
        print(f"[{time.perf_counter() - t0:6.0f} s] {msg}", flush=True)
    if not args.score_only:
        for room in rooms:
            bake_and_read(room, args.state, log)
    if args.bake_only:
        return
    rows = []
    for room in rooms:
        rows += score_room(args.state, room, args.presets.split(","), log)
    raw = args.raw or os.path.splitext(args.out)[0] + "_raw.json"
    with open(raw, "w") as f:
        json.dump(rows, f, indent=1)
    write_report(rows, args.out, args.note, time.perf_counter() - t0)


if __name__ == "__main__":
    main()
