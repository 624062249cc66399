"""Shadow-free textures against Cycles ground truth (issue 3): writes results/shadowfree.md and
results/shadowfree_<lighting>.png.

Scene: the office of scenes.office (seed 0, 2 lamps of 40 W, 48^2 texels per surface).
Input photo and truth are Cycles DIFFUSE bakes (adaptive sampling off) from independent seeds:
per lamp alone, seed 0 for the photo, seed 1 for the truth, combined linearly for every target
lighting (shadowfree_data.py).  The noise floor is the difference of the two at the original
lighting.

Methods: "element" (the seed's pipeline), "texel" (per-texel shadow removal), "DRB97" (no texture
correction), "global scale" (photo x total power ratio, with the true lamp powers).

Metrics: CIEDE2000 per texel between relit and truth, linear RGB divided by a fixed white (the
99th percentile luminance of the truth at the original lighting, so that L = 100 there) then
LAB; mean and 95th percentile over every covered texel and over the former shadow of the lamp
switched off (texels where that lamp gives at least 10 % of the unoccluded direct light and at
least half of it is blocked, by ray casting on the geometry).

Usage: python benchmarks/bench_shadowfree.py [--presets draft,medium,high] [--samples 2048]
"""
from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))
sys.path.insert(0, HERE)

import shadowfree_data as sd  # noqa: E402

RESULTS = os.path.join(HERE, "results")
LUM = np.array([0.2126, 0.7152, 0.0722])


def lightings(lamps):
    out = {"original": {}}
    for k in lamps:
        out[f"{k[-1]} off"] = {k: 0.0}
    for k in lamps:
        out[f"{k[-1]} doubled"] = {k: 2.0}
    return out


def shadow_masks(scene, tm, lamps):
    """{lamp: (T,) bool}: texels in the lamp's shadow (see the module docstring)."""
    from relight_addon.core.geometry.raycast import make_occluder
    from relight_addon.core.relight.direct import lamp_irradiance
    from relight_addon.core.scene import bilinear_point
    occ = make_occluder(scene.occluder_triangles())
    pts = bilinear_point(scene.corners[tm.patch][:, None], tm.u[:, None], tm.v[:, None])[:, 0]
    nrm = scene.area_normal()[1][tm.patch]
    U, O = lamp_irradiance(scene, pts, nrm, occ, rays=64, seed=5)
    u, o = U @ LUM, O @ LUM                                    # (T, k)
    share = u / np.maximum(u.sum(axis=1, keepdims=True), 1e-300)
    return {name: (share[:, j] >= 0.1) & (o[:, j] <= 0.5 * u[:, j]) for j, name in enumerate(lamps)}


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--presets", default="draft,medium,high")
    ap.add_argument("--samples", type=int, default=2048)
    ap.add_argument("--out", default=RESULTS)
    ap.add_argument("--methods", default="DRB97=none,element=element,"
                    "element + references=element:reference=True,texel=texel,"
                    "texel 8 rays=texel:texel_rays=8:texel_samples=1,"
                    "texel 128 rays=texel:texel_rays=128:texel_samples=3",
                    help="label=mode[:option=value...] comma-separated")
    args = ap.parse_args(argv)
    presets = args.presets.split(",")

    from relight_addon.core.relight.shadowfree import ShadowFreeOptions, shadow_free
    from relight_addon.core.texture.colour import delta_e_2000, linear_rgb_to_lab
    from relight_addon.core.texture.mapping import rasterize_patches
    from scenes.office import office_scene_data

    t0 = time.perf_counter()
    info = sd.build_scene()
    per = sd.lamp_bakes(info, args.samples, range(2))
    photo_b, truth_b = sd.halves(per)
    t_bakes = time.perf_counter() - t0
    data = info.data
    names = [s.name for s in data.surfaces]
    lamps = [lp.name for lp in data.lamps]
    powers = {lp.name: lp.power for lp in data.lamps}
    photo = sd.combine(photo_b, {})
    scene = office_scene_data(data, photo)
    shapes = [im.texels.shape[:2] for im in scene.images]
    tm = rasterize_patches(scene.uv, scene.image, shapes)
    masks = shadow_masks(scene, tm, lamps)

    def texels(imgs):                   # {name: image} -> (T, 3) in tm order
        return tm.gather([imgs[n] for n in names]).astype(np.float64)

    truth = {lab: texels(sd.combine(truth_b, I)) for lab, I in lightings(lamps).items()}
    photo_t = texels(photo)
    white = float(np.percentile(truth["original"] @ LUM, 99))

    def de(x, y):
        return delta_e_2000(linear_rgb_to_lab(np.clip(x / white, 0, None)),
                            linear_rgb_to_lab(np.clip(y / white, 0, None)))

    def score(relit_t, lab):
        d = de(relit_t, truth[lab])
        row = {"all": (float(d.mean()), float(np.percentile(d, 95)))}
        off = [k for k in lamps if lab == f"{k[-1]} off"]
        if off:
            m = masks[off[0]]
            row["shadow"] = (float(d[m].mean()), float(np.percentile(d[m], 95)))
        return row, d

    L = lightings(lamps)
    rows = []
    floor = {lab: score(photo_t, "original")[0] for lab in ["original"]}["original"]
    floor_shadow = {k: (float(de(photo_t, truth["original"])[masks[k]].mean())) for k in lamps}
    # Global exposure scale with the true lamp powers.
    rel = {}
    for lab, I in L.items():
        ratio = sum(powers[k] * I.get(k, 1.0) for k in lamps) / sum(powers.values())
        rel[lab] = score(photo_t * ratio, lab)[0]
    rows.append(("global scale", "-", 0.0, rel, {}))
    pictures = {}
    for preset in presets:
        for label, mode, extra in parse_methods(args.methods):
            t1 = time.perf_counter()
            res = shadow_free(scene, ShadowFreeOptions(mode=mode, preset=preset, **extra))
            dt = time.perf_counter() - t1
            rel = {}
            for lab, I in L.items():
                out = res.relit([I.get(k, 1.0) for k in lamps])
                relit_t = tm.gather([out[i] for i in range(len(names))]).astype(np.float64)
                rel[lab], d = score(relit_t, lab)
                if preset == "medium":
                    pictures.setdefault(lab, {})[label] = (relit_t, d)
            def rel_(x):
                x = np.asarray(x, float)
                return {k: round(float(v), 3) for k, v in zip(lamps, x / max(x.mean(), 1e-300))}
            rows.append((label, preset, dt, rel, {
                "stats": {k: (round(v, 4) if isinstance(v, float) else v)
                          for k, v in res.stats.items()},
                "exitance": rel_(res.exitance_scale), "eq 4.2": rel_(res.lamps.equal),
                "NNLS": rel_(res.lamps.nnls)}))
            print(label, preset, f"{dt:.1f}s", {k: v["all"][0] for k, v in rel.items()}, flush=True)

    os.makedirs(args.out, exist_ok=True)
    write_table(os.path.join(args.out, "shadowfree.md"), rows, floor, floor_shadow, L, lamps,
                args.samples, t_bakes, masks)
    if pictures:
        write_grids(args.out, tm, names, shapes, photo_t, truth, pictures, white)
    write_curve(os.path.join(args.out, "shadowfree_speed_accuracy.png"), rows, floor_shadow, lamps)


def write_curve(path, rows, floor_shadow, lamps):
    """Precompute time vs error in the former shadows (mean over the lamps), per method."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7, 4.5))
    series = {}
    for label, preset, dt, rel, _ in rows:
        y = np.mean([rel[f"{k[-1]} off"]["shadow"][0] for k in lamps])
        series.setdefault(label, []).append((dt, y, preset))
    for label, pts in series.items():
        if label == "global scale":
            ax.axhline(pts[0][1], color="grey", ls="--", label=f"global scale ({pts[0][1]:.1f})")
            continue
        xs, ys, ps = zip(*pts)
        ax.plot(xs, ys, "o-", label=label)
        for x, y, p in pts:
            ax.annotate(p, (x, y), fontsize=7, xytext=(3, 3), textcoords="offset points")
    ax.axhline(np.mean(list(floor_shadow.values())), color="k", ls=":", label="noise floor")
    ax.set_xscale("log")
    ax.set_xlabel("precompute time (s, 2 cores)")
    ax.set_ylabel("CIEDE2000 mean in the switched-off lamp's former shadow")
    ax.set_title("Shadow removal: speed / accuracy (office, lamp A or B off)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)


def parse_methods(spec):
    out = []
    for item in spec.split(","):
        label, rest = item.split("=", 1)
        mode, *opts = rest.split(":")
        extra = {}
        for o in opts:
            k, v = o.split("=")
            extra[k] = {"True": True, "False": False}.get(v, v)
            try:
                extra[k] = float(v) if "." in v else int(v)
            except ValueError:
                pass
        out.append((label, mode, extra))
    return out


def _fmt(v):
    return f"{v[0]:.2f} / {v[1]:.2f}"


def write_table(path, rows, floor, floor_shadow, L, lamps, samples, t_bakes, masks):
    load = os.getloadavg()
    lines = ["# Shadow-free textures vs Cycles ground truth", "",
             "Generated by `benchmarks/bench_shadowfree.py` (office, 2 lamps, 48^2 texels per surface, "
             f"{samples}-sample Cycles DIFFUSE bakes without adaptive sampling, photo and truth from "
             f"independent seeds; bakes {t_bakes:.0f} s incl. cache).  Load average "
             f"{load[0]:.2f} / {load[1]:.2f} / {load[2]:.2f} on 2 cores.", "",
             "CIEDE2000 between the relit texture and the Cycles truth, `mean / p95`; *all* = every "
             "covered texel, *shadow* = the former shadow of the lamp switched off "
             + ", ".join(f"({k}: {int(m.sum())} texels)" for k, m in masks.items()) + ".", "",
             f"Noise floor (photo vs truth bakes, original lighting): all {_fmt(floor['all'])}; "
             "in the shadows of " + ", ".join(f"{k} {v:.2f}" for k, v in floor_shadow.items())
             + " (mean).", ""]
    head = ["method", "preset", "precompute s"]
    for lab in L:
        head.append(f"{lab} all")
        if lab.endswith(" off"):
            head.append(f"{lab} shadow")
    lines.append("| " + " | ".join(head) + " |")
    lines.append("|" + "---|" * len(head))
    for label, preset, dt, rel, _ in rows:
        cells = [label, preset, f"{dt:.1f}"]
        for lab in L:
            cells.append(_fmt(rel[lab]["all"]))
            if lab.endswith(" off"):
                cells.append(_fmt(rel[lab]["shadow"]))
        lines.append("| " + " | ".join(cells) + " |")
    lines += ["", "Targets of the issue (medium preset, texel mode, means):", ""]
    get = {(lab, pre): rel for lab, pre, _, rel, _ in rows}
    tex, drb, glob = get.get(("texel", "medium")), get.get(("DRB97", "medium")), get.get(("global scale", "-"))
    if tex and drb and glob:
        offs = [f"{k[-1]} off" for k in lamps]
        sh = {m: np.mean([r[o]["shadow"][0] for o in offs]) for m, r in
              (("texel", tex), ("DRB97", drb), ("global", glob))}
        fl = float(np.mean(list(floor_shadow.values())))
        lines += [f"- original reproduced: {tex['original']['all'][0]:.2f} (target <= 1; the noise "
                  f"floor is {floor['all'][0]:.2f})",
                  "- lamp off, in its former shadow: " + ", ".join(
                      f"{o} {tex[o]['shadow'][0]:.2f}" for o in offs) + " (target <= 3)",
                  "- lamp off, overall: " + ", ".join(f"{o} {tex[o]['all'][0]:.2f}" for o in offs)
                  + " (target <= 2)",
                  f"- vs DRB97 in the shadows: {sh['DRB97'] / sh['texel']:.1f}x lower (target 3x); "
                  f"above the noise floor ({fl:.2f}): {(sh['DRB97'] - fl) / max(sh['texel'] - fl, 1e-9):.1f}x",
                  f"- vs the global exposure scale in the shadows: {sh['global'] / sh['texel']:.1f}x "
                  "lower (target 2x)"]
    lines += ["", "Details per run: elements, links, photo misfit; relative lamp exitances (truth: "
              "equal) used (shadow-edge fit), by eq 4.2 (equal lamps) and by NNLS on the eq 4.1 "
              "reflectances:", ""]
    for label, preset, dt, rel, extra in rows:
        if extra:
            lines.append(f"- {label} / {preset}: {extra['stats']}; exitance used "
                         f"{extra['exitance']}, eq 4.2 {extra['eq 4.2']}, NNLS {extra['NNLS']}")
    open(path, "w").write("\n".join(lines) + "\n")
    print(open(path).read())


def write_grids(out, tm, names, shapes, photo_t, truth, pictures, white):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    def mosaic(values):
        imgs = tm.scatter(values)
        tiles = [np.flipud(im) for im in imgs]
        rows = [np.concatenate(tiles[i:i + 3], axis=1) for i in range(0, 9, 3)]
        return np.concatenate(rows, axis=0)

    def srgb(x):
        x = np.clip(x / white, 0, 1)
        return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)

    for lab, methods in pictures.items():
        cols = [("input photo", srgb(mosaic(photo_t)))]
        shown = [m for m in ("DRB97", "element", "texel") if m in methods]
        for m in shown:
            cols.append((f"{m} relit", srgb(mosaic(methods[m][0]))))
        cols.append(("Cycles truth", srgb(mosaic(truth[lab]))))
        for m in shown:
            cols.append((f"{m} dE2000 (0-10)", mosaic(methods[m][1][:, None])[..., 0]))
        fig, axes = plt.subplots(2, 4, figsize=(16, 8.6))
        for ax, (title, img) in zip(axes.ravel(), cols):
            if img.ndim == 2:
                ax.imshow(img, cmap="magma", vmin=0, vmax=10, interpolation="nearest")
            else:
                ax.imshow(img, interpolation="nearest")
            ax.set_title(title, fontsize=10)
            ax.set_axis_off()
        fig.suptitle(f"Office textures (3 x 3 surfaces), lighting: {lab}, medium preset")
        fig.tight_layout()
        fig.savefig(os.path.join(out, f"shadowfree_{lab.replace(' ', '_')}.png"), dpi=70)
        plt.close(fig)


if __name__ == "__main__":
    main()
