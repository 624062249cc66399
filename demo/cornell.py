"""`make demo`: solve the embedded Cornell box and write out/cornell.png.

Until the Blender bridge lands this is the main job: it runs the whole core (refinement, form
factors, visibility, per-lamp basis) and draws the leaf radiosity from a pinhole camera inside
the box (painter's algorithm over the leaves, which are small enough for it).
"""
from __future__ import annotations

import argparse
import os
import time

import numpy as np


def render_leaves(corners, colours, eye, look_at, width=640, height=640, fov_deg=40.0):
    """Draw quads (n, 4, 3) with flat colours (n, 3) in [0, 1] from a pinhole camera (matplotlib)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection

    eye, look_at = np.asarray(eye, float), np.asarray(look_at, float)
    fwd = look_at - eye
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    rel = corners - eye
    depth = rel @ fwd
    # Back-face culling (patches are one-sided) keeps the painter's algorithm honest.
    normal = np.cross(corners[:, 2] - corners[:, 0], corners[:, 3] - corners[:, 1])
    facing = np.einsum("ij,ij->i", normal, rel.mean(axis=1)) < 0
    visible = np.all(depth > 1e-3, axis=1) & facing
    f = 1.0 / np.tan(np.radians(fov_deg) / 2)
    xy = np.stack([rel @ right, rel @ up], axis=-1) * (f / np.maximum(depth, 1e-3))[..., None]
    order = np.argsort(-depth.mean(axis=1)[visible])          # far to near
    polys = xy[visible][order]
    fig = plt.figure(figsize=(width / 100, height / 100), dpi=100)
    ax = fig.add_axes([0, 0, 1, 1])
    ax.add_collection(PolyCollection(polys, facecolors=colours[visible][order], edgecolors="none",
                                     antialiased=False))
    ax.set_xlim(-1, 1)
    ax.set_ylim(-1, 1)
    ax.set_axis_off()
    return fig


def to_srgb(linear):
    linear = np.clip(linear, 0.0, 1.0)
    return np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * linear ** (1 / 2.4) - 0.055)


def main(argv=None):
    from relight_addon.core.radiosity.precompute import solve_radiosity
    from scenes.testscenes import cornell_box

    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--preset", default="high")
    parser.add_argument("--out", default="out")
    parser.add_argument("--results", default="",
                        help="also copy the picture there (e.g. benchmarks/results/cornell.png)")
    args = parser.parse_args(argv)

    scene = cornell_box(front_wall=False)          # the classic open box, seen from the front
    t0 = time.perf_counter()
    sol = solve_radiosity(scene, args.preset)
    elapsed = time.perf_counter() - t0
    B = sol.radiosity()
    exposure = 1.0 / max(np.percentile(B[B.max(axis=1) < scene.emission.max()], 99), 1e-12)
    colours = to_srgb(B * exposure)
    h = sol.hierarchy
    leaves = sol.leaves
    size = float(scene.corners[..., 0].max())
    fig = render_leaves(h.corners[leaves], colours, eye=(size / 2, -1.4 * size, size / 2),
                        look_at=(size / 2, size, size / 2), fov_deg=38.0)
    os.makedirs(args.out, exist_ok=True)
    path = os.path.join(args.out, "cornell.png")
    fig.savefig(path)
    if args.results:
        import shutil
        shutil.copyfile(path, args.results)
    st = sol.stats()
    print(f"Cornell box, preset {args.preset}: {st['elements']} elements, {st['leaves']} leaves, "
          f"{st['links']} links, solved in {elapsed:.2f} s (residual {st['residual']:.1e}) -> {path}")
    return path


if __name__ == "__main__":
    main()
