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
    lights = [(lt.direction, lt.half_angle, lt.radiance) for lt in lighting.lights
              if lt.solid_angle > 0]
    floor = E_FLOOR * max(float(np.abs(lighting.sh[0]).max()) * np.pi / np.sqrt(4 * np.pi),
                          1e-300)
    return pack_uniforms(centres, radii, hull, lights, floor)


def pack_uniforms(centres, radii, hull, lights, e_floor):
    """:func:`shadow_uniforms` from plain values: ``lights`` [(direction (3,), half-angle,
    radiance (3,))] (those with a solid angle), ``e_floor`` the residual's floor (what a
    set-up scene stores: blender/ar_draw.py)."""
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
    lights = list(lights)[:MAX_LIGHTS]
    ld = np.zeros((MAX_LIGHTS, 4), np.float32)
    lr = np.zeros((MAX_LIGHTS, 4), np.float32)
    for j, (direction, half_angle, radiance) in enumerate(lights):
        ld[j, :3], ld[j, 3] = direction, half_angle
        lr[j, :3] = radiance
    return {"spheres": sph, "n_spheres": int(len(c)), "hull": h, "light_dir": ld,
            "light_rad": lr, "n_lights": len(lights), "e_floor": np.float32(e_floor),
            "cap_angles": np.asarray(CAP_ANGLES, np.float32)}


def shadow_textures(lighting):
    """{sampler name: float32 array} for ar_shadow_frag.glsl, rows bottom first (bpy's
    Image.pixels order, as GL textures take them): ``irradiance_map`` (h, w, 3) and
    ``cap_tables`` (layers, h, w, 3), one layer per CAP_ANGLES entry."""
    return {"irradiance_map": np.ascontiguousarray(lighting.irradiance[::-1], np.float32),
            "cap_tables": np.ascontiguousarray(lighting.caps[:, ::-1], np.float32)}


def textures_from_tables(pixels, bands, rows):
    """:func:`shadow_textures` from the stored tables image's pixels (k rows x w, >= 3
    channels, bottom row first: blender/ar_nodes.tables_pixels, band 0 the irradiance table,
    bands 1.. the cap tables, each band's rows from its nadir up)."""
    px = np.asarray(pixels, np.float32)[..., :3].reshape(bands, rows, -1, 3)
    return {"irradiance_map": np.ascontiguousarray(px[0]),
            "cap_tables": np.ascontiguousarray(px[1:])}
