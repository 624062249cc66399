"""Outputs of the core, recorded before and compared after a refactor (issue 43: the layer
moves and the function splits must not change a result).

    python -m benchmarks.equivalence record /work/scratch/layers/before.npz
    python -m benchmarks.equivalence record /work/scratch/layers/after.npz
    python -m benchmarks.equivalence compare before.npz after.npz [--md out.md --label step]

What is recorded (every run is seeded, so two runs of the same code give the same bits):

* the Cornell box (``scenes.testscenes.cornell_box``) solved at draft and medium, and at draft
  with high's spread ray origins and partial-link rays: the leaf radiosities, the per-patch
  radiosities and the per-lamp basis;
* a texel-mode shadow-free precompute at draft of the bpy-free office (``scenes.office``,
  16 texels per surface, the true albedo as the photo): per image the texture T and the maps M,
  the coverage, the per-texel denominator and the relit result;
* the same result with one virtual point lamp added (``virtual.add_lamps``), and the office
  precomputed with a virtual box on the floor (``shadow_free`` -> ``virtual.add_objects``);
* the office in element mode (refinement, regather, reference elements) and DRB97 mode at
  draft, and split 6 x 6 in texel mode on a 150-triangle proxy (``radiosity.proxy``).

``compare`` prints, per array, whether the bits are equal and the largest absolute (and
relative to the array's largest magnitude) difference.
"""
from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TEXELS = 16


def _setup_path():
    if ROOT not in sys.path:
        sys.path.insert(0, ROOT)


def cornell(out: dict, preset: str, **changes):
    """``changes``: Quality fields on top of the preset (high's spread ray origins and
    partial-link rays, at draft's cost)."""
    from relight_addon.core.radiosity.precompute import solve_radiosity
    from relight_addon.core.radiosity.presets import get_preset
    from scenes.testscenes import cornell_box
    sol = solve_radiosity(cornell_box(), get_preset(preset).with_(**changes), seed=0)
    key = f"cornell_{preset}" + "".join(f"_{k}" for k in sorted(changes))
    out[f"{key}/leaf_B"] = np.asarray(sol.radiosity())
    out[f"{key}/patch_B"] = np.asarray(sol.patch_radiosity())
    out[f"{key}/basis"] = np.asarray(sol.basis)


def _office_scene(virtual_box: bool = False, split: int = 1):
    from relight_addon.core.scene import SceneData, quads_from_boxes
    from scenes.office import office_geometry, office_scene_data
    scene = office_scene_data(office_geometry(seed=0, n_lamps=2, texture_size=TEXELS))
    if split > 1:
        scene = _split(scene, split)
    if not virtual_box:
        return scene
    box = quads_from_boxes([2.2, 1.4, 0.25], [0.5, 0.5, 0.5])[1:]     # no bottom face
    n = len(box)
    return SceneData(
        np.concatenate([scene.corners, box]), np.r_[scene.rho, np.full((n, 3), 0.6)],
        np.r_[scene.emission, np.zeros((n, 3))], np.r_[scene.lamp, np.full(n, -1)],
        scene.lamp_names, occluder=np.r_[scene.occluder, np.ones(n, bool)],
        group=np.r_[scene.group, np.full(n, -1)], uv=np.r_[scene.uv, np.zeros((n, 4, 2))],
        image=np.r_[scene.image, np.full(n, -1)], images=scene.images,
        viewpoint=scene.viewpoint, virtual=np.r_[np.zeros(scene.n_patches, bool),
                                                 np.ones(n, bool)])


def _split(scene, n: int):
    """``scene`` with every non-lamp quad split n x n (corners and UVs bilinear): a dense mesh
    that the radiosity solves on a decimated proxy."""
    from relight_addon.core.scene import SceneData, bilinear_point
    g = np.arange(n + 1) / n
    u0, v0 = np.meshgrid(g[:-1], g[:-1])
    u0, v0 = u0.ravel(), v0.ravel()
    uv = np.stack([np.stack([u0, v0], -1), np.stack([u0 + 1 / n, v0], -1),
                   np.stack([u0 + 1 / n, v0 + 1 / n], -1), np.stack([u0, v0 + 1 / n], -1)], 1)
    keep = {}
    for name in ("corners", "uv"):
        c = getattr(scene, name)
        sub = bilinear_point(c[:, None, None], uv[None, ..., 0], uv[None, ..., 1])
        keep[name] = sub                                   # (p, n*n, 4, dim)
    surf = scene.lamp < 0
    rep = np.where(surf, n * n, 1)
    idx = np.repeat(np.arange(scene.n_patches), rep)
    first = np.r_[0, np.cumsum(rep)[:-1]]
    j = np.arange(len(idx)) - first[idx]
    corners = np.where(surf[idx, None, None], keep["corners"][idx, j], scene.corners[idx])
    uvs = np.where(surf[idx, None, None], keep["uv"][idx, j], scene.uv[idx])
    return SceneData(corners, scene.rho[idx], scene.emission[idx], scene.lamp[idx],
                     scene.lamp_names, occluder=scene.occluder[idx], group=scene.group[idx],
                     uv=uvs, image=scene.image[idx], images=scene.images,
                     viewpoint=scene.viewpoint)


def _result(out: dict, key: str, res):
    for i in sorted(res.texture):
        out[f"{key}/T{i}"] = np.asarray(res.texture[i])
        out[f"{key}/M{i}"] = np.asarray(res.maps[i])
        out[f"{key}/cov{i}"] = np.asarray(res.coverage[i])
    for i, r in sorted(res.relit().items()):
        out[f"{key}/relit{i}"] = r
    if res.denominator is not None:
        out[f"{key}/denominator"] = np.asarray(res.denominator)
    if res.direct is not None:
        for i in sorted(res.direct):
            out[f"{key}/direct{i}"] = np.asarray(res.direct[i])
    out[f"{key}/lamp_scale"] = np.asarray(res.lamps.scale)
    out[f"{key}/solution_basis"] = np.asarray(res.solution.basis)


def office(out: dict):
    from relight_addon.core.lights import POINT, Lights
    from relight_addon.core.relight.shadowfree import ShadowFreeOptions, shadow_free
    from relight_addon.core.relight.virtual import add_lamps
    opt = ShadowFreeOptions(mode="texel", preset="draft")
    res = shadow_free(_office_scene(), opt)
    _result(out, "office", res)
    lamp = Lights.make(POINT, 0, np.array([[1, 0, 0, 1.0], [0, 1, 0, 1.5], [0, 0, 1, 2.0],
                                           [0, 0, 0, 1]]), np.full(3, 30.0 / (4 * np.pi)),
                       radius=0.05)
    _result(out, "office+lamp", add_lamps(res, lamp, ["virtual lamp"], seed=0))
    _result(out, "office+box", shadow_free(_office_scene(virtual_box=True), opt))
    _result(out, "office_element", shadow_free(
        _office_scene(), ShadowFreeOptions(mode="element", preset="draft", reference=True)))
    _result(out, "office_none", shadow_free(_office_scene(), ShadowFreeOptions(mode="none",
                                                                               preset="draft")))
    # the office split 6 x 6 (about 1,100 faces) solved on a proxy of 150 triangles
    _result(out, "office_proxy", shadow_free(
        _office_scene(split=6), ShadowFreeOptions(mode="texel", preset="draft", proxy_faces=150)))


def record(path: str):
    _setup_path()
    out = {}
    for name, job in (("cornell draft", lambda: cornell(out, "draft")),
                      ("cornell medium", lambda: cornell(out, "medium")),
                      ("cornell draft + jitter, partial rays",
                       lambda: cornell(out, "draft", jitter_origins=True, partial_rays=32)),
                      ("office (texel + lamp + box, element, none, proxy)", lambda: office(out))):
        t0 = time.perf_counter()
        job()
        print(f"{name}: {time.perf_counter() - t0:.1f} s", flush=True)
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    np.savez_compressed(path, **out)
    print(f"{len(out)} arrays -> {path}")


def compare(before: str, after: str, md: str | None = None, label: str = ""):
    a, b = np.load(before), np.load(after)
    rows, equal_all, worst = [], True, 0.0
    for key in sorted(set(a.files) | set(b.files)):
        if key not in a.files or key not in b.files:
            rows.append((key, "missing", "", ""))
            equal_all = False
            continue
        x, y = a[key], b[key]
        if x.shape != y.shape:
            rows.append((key, f"shape {x.shape} vs {y.shape}", "", ""))
            equal_all = False
            continue
        same = x.tobytes() == y.tobytes()
        equal_all &= same
        if x.dtype == bool:
            d, rel = float(np.count_nonzero(x != y)), 0.0
        else:
            d = float(np.max(np.abs(x.astype(np.float64) - y.astype(np.float64)), initial=0.0))
            scale = float(np.max(np.abs(x.astype(np.float64)), initial=0.0))
            rel = d / scale if scale > 0 else 0.0
        worst = max(worst, rel)
        rows.append((key, "equal" if same else "differs", f"{d:.3g}", f"{rel:.3g}"))
    lines = ["| array | bits | max abs diff | max diff / max abs |", "|---|---|---:|---:|"]
    lines += [f"| {k} | {s} | {d} | {r} |" for k, s, d, r in rows]
    summary = (f"{label}: {len(rows)} arrays, " +
               ("all bit-for-bit equal" if equal_all else
                f"not all equal, worst relative difference {worst:.3g}"))
    print("\n".join(lines))
    print(summary)
    if md:
        with open(md, "a") as f:
            f.write(f"\n## {label}\n\n{summary}.\n\n" + "\n".join(lines) + "\n")
    return equal_all, worst


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    sub = p.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("record")
    r.add_argument("path")
    c = sub.add_parser("compare")
    c.add_argument("before")
    c.add_argument("after")
    c.add_argument("--md")
    c.add_argument("--label", default="comparison")
    args = p.parse_args(argv)
    if args.cmd == "record":
        record(args.path)
    else:
        equal, _ = compare(args.before, args.after, args.md, args.label)
        return 0 if equal else 1


if __name__ == "__main__":
    sys.exit(main())
