# SPDX-License-Identifier: GPL-3.0-or-later
"""What the viewport's sphere-shadow shader (blender/shaders/ar_shadow_frag.glsl) reads: its
uniform arrays and textures, packed from the numpy side.  Changing the spheres (a drag, an
animation) or the lights changes these values only: nothing recompiles."""
from __future__ import annotations

import numpy as np

from .cap_filter import CAP_ANGLES
from .env_shadow import E_FLOOR
from .main_light import MAX_LIGHTS

MAX_SPHERES = 128          # uniform array size in the shader (the sets are 8-128 spheres)


def shadow_uniforms(lighting, centres, radii, hull=None):
    """{uniform name: float32 / int value} for ar_shadow_frag.glsl: ``spheres`` (MAX_SPHERES,
    4) world centres + radii (the first ``n_spheres`` used), ``hull`` (4,) (w = 0: none),
    ``light_dir`` / ``light_rad`` (MAX_LIGHTS, 4), ``n_lights``, ``e_floor``, ``cap_angles``.
    Raises ValueError past MAX_SPHERES spheres."""
    c = np.asarray(centres, float).reshape(-1, 3)
    r = np.asarray(radii, float).ravel()
    if len(c) > MAX_SPHERES:
        raise ValueError(f"The sphere set has {len(c)} spheres; the viewport shader takes at "
                         f"most {MAX_SPHERES}.")
    sph = np.zeros((MAX_SPHERES, 4), np.float32)
    sph[:len(c), :3], sph[:len(c), 3] = c, r
    h = np.zeros(4, np.float32)
    if hull is not None:
        h[:3], h[3] = hull[0], hull[1]
    lights = [lt for lt in lighting.lights if lt.solid_angle > 0][:MAX_LIGHTS]
    ld = np.zeros((MAX_LIGHTS, 4), np.float32)
    lr = np.zeros((MAX_LIGHTS, 4), np.float32)
    for j, lt in enumerate(lights):
        ld[j, :3], ld[j, 3] = lt.direction, lt.half_angle
        lr[j, :3] = lt.radiance
    floor = E_FLOOR * max(float(np.abs(lighting.sh[0]).max()) * np.pi / np.sqrt(4 * np.pi),
                          1e-300)
    return {"spheres": sph, "n_spheres": int(len(c)), "hull": h, "light_dir": ld,
            "light_rad": lr, "n_lights": len(lights), "e_floor": np.float32(floor),
            "cap_angles": np.asarray(CAP_ANGLES, np.float32)}


def shadow_textures(lighting):
    """{sampler name: float32 array} for ar_shadow_frag.glsl, rows bottom first (bpy's
    Image.pixels order, as GL textures take them): ``irradiance_map`` (h, w, 3) and
    ``cap_tables`` (layers, h, w, 3), one layer per CAP_ANGLES entry."""
    return {"irradiance_map": np.ascontiguousarray(lighting.irradiance[::-1], np.float32),
            "cap_tables": np.ascontiguousarray(lighting.caps[:, ::-1], np.float32)}
