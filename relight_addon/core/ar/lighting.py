# SPDX-License-Identifier: GPL-3.0-or-later
"""Everything AR mode derives from one environment map, in one call (the pipeline, top to
bottom): validation, main light and residual, SH9 (whole map and residual), irradiance map,
cube faces and their mip chain.  The lead's ar_setup reads the World's Environment Texture
pixels, calls :func:`prepare_environment` once, and writes what the materials need."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .cap_filter import CAP_ANGLES, cap_filtered_maps
from .envmap import cube_mips, equirect_to_cube, padded_mips, validate_environment
from .irradiance import irradiance_map, irradiance_polynomial, sh9_project
from .main_light import MAX_LIGHTS, MainLight, extract_lights

CUBE_SIZE = 128        # cube face texels at level 0 (the bundled maps are 1024 wide: 256 / face)


@dataclass
class EnvironmentLighting:
    """env           (H, W, 3) validated equirectangular map, top row first
    lights         [MainLight, ...] (main_light.py): direction, solid angle, radiance, share;
                   lights[0] is the main light (ARCore's), the others further compact lights
    residual       (H, W, 3) the map without the lights
    sh             (9, 3) radiance SH9 of the whole map (irradiance.py order)
    sh_ambient     (9, 3) radiance SH9 of the residual
    poly           (9, 3) irradiance polynomial of the whole map (irradiance.SH_POLYNOMIAL_TERMS)
    poly_ambient   (9, 3) the same for the residual (add main_light.light_irradiance of each
                   light)
    irradiance     (h, w, 3) irradiance table E(n), latitude nodes (irradiance.irradiance_map)
    mips           [(6, S, S, 3), ...] cube mip chain of the map, level 0 = CUBE_SIZE
    caps           (k, h, w, 3) cap-filtered tables (latitude nodes) of the residual, one
                   per cap half-angle of cap_filter.CAP_ANGLES (cap_filter.py)"""

    env: np.ndarray
    lights: list
    residual: np.ndarray
    sh: np.ndarray
    sh_ambient: np.ndarray
    poly: np.ndarray
    poly_ambient: np.ndarray
    irradiance: np.ndarray
    mips: list
    caps: np.ndarray = None
    _padded: list = None

    @property
    def light(self) -> MainLight:
        """The main light (ARCore's single directional light)."""
        return self.lights[0]

    @property
    def padded(self):
        """The mip chain with one-texel borders, for repeated seamless lookups."""
        if self._padded is None:
            self._padded = padded_mips(self.mips)
        return self._padded


def prepare_environment(pixels, bottom_row_first=False, cube_size=CUBE_SIZE,
                        max_lights=MAX_LIGHTS) -> EnvironmentLighting:
    """The :class:`EnvironmentLighting` of the environment ``pixels`` ((H, W, 3|4) linear RGB,
    equirectangular; ``bottom_row_first`` for bpy's ``Image.pixels`` order).  Raises ValueError
    (one sentence) on a map too small, with NaN/Inf or negative radiance; never modifies its
    input."""
    env = validate_environment(pixels, bottom_row_first)
    lights, residual = extract_lights(env, max_lights)
    sh, sh_amb = sh9_project(env), sh9_project(residual)
    mips = cube_mips(equirect_to_cube(env, cube_size))
    return EnvironmentLighting(env=env, lights=lights, residual=residual, sh=sh, sh_ambient=sh_amb,
                               poly=irradiance_polynomial(sh),
                               poly_ambient=irradiance_polynomial(sh_amb),
                               irradiance=irradiance_map(residual, sparse=env - residual),
                               mips=mips,
                               caps=cap_filtered_maps(residual, CAP_ANGLES))
