"""Cycles ground truth for the shadow-free benchmark: per-lamp bakes of the office, several seeds.

Light transport is linear in the lamp powers (Cycles without clamping), so one bake per lamp
alone gives every target lighting: bake(I) = sum_k I_k bake_k.  Independent seeds are averaged
into two disjoint halves: the "photo" (input texture) and the "truth" (reference), so that the
input's noise and the reference's noise are independent, and their difference at the original
lighting is the noise floor.  Bakes are cached on disk (scenes.bake).
"""
from __future__ import annotations

import sys

import numpy as np

SCENE = dict(seed=0, n_lamps=2, texture_size=48, variant="small")


def build_scene():
    import bpy  # noqa: PLC0415

    from scenes.office import build_office  # noqa: PLC0415
    bpy.ops.wm.read_factory_settings(use_empty=True)
    return build_office(**SCENE)


def lamp_bakes(info, samples=2048, seeds=range(2)):
    """{lamp name: [bake dict per seed]} with only that lamp on at its original power."""
    from scenes.bake import bake_lighting  # noqa: PLC0415
    powers = dict(info.lamp_powers)
    out = {}
    for lamp in powers:
        only = {k: (v if k == lamp else 0.0) for k, v in powers.items()}
        out[lamp] = [bake_lighting(only, samples=samples, seed=int(s),
                                   texture_size=SCENE["texture_size"]) for s in seeds]
    return out


def halves(per_lamp):
    """(photo_basis, truth_basis): {lamp: {object: mean bake}} over the first / second half of
    the seeds."""
    photo, truth = {}, {}
    for lamp, bakes in per_lamp.items():
        n = len(bakes) // 2
        for dst, part in ((photo, bakes[:n]), (truth, bakes[n:2 * n])):
            dst[lamp] = {o: np.mean([b[o] for b in part], axis=0) for o in part[0]}
    return photo, truth


def combine(basis, intensities):
    """sum_k I_k bake_k as {object: image}."""
    lamps = list(basis)
    objs = basis[lamps[0]]
    return {o: sum(float(intensities.get(k, 1.0)) * basis[k][o] for k in lamps) for o in objs}


if __name__ == "__main__":  # warm the cache: python benchmarks/shadowfree_data.py [samples] [n]
    import os
    import time
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    samples = int(sys.argv[1]) if len(sys.argv) > 1 else 2048
    n = int(sys.argv[2]) if len(sys.argv) > 2 else 2
    t0 = time.time()
    info = build_scene()
    lamp_bakes(info, samples, range(n))
    print(f"{2 * n} bakes at {samples} samples in {time.time() - t0:.0f} s")
