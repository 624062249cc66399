# SPDX-License-Identifier: GPL-3.0-or-later
"""Glossy reflection of the environment from its cube mip chain (seed 002 §4.4).

Seed 002 reads the map in the reflected direction at a mip level standing for the lobe's width,
after McGuire et al. 2013 ("Plausible Blinn-Phong reflection of standard cube MIP-maps"):

    level = log2(size sqrt 3) - 0.5 log2(n_s + 1)

(size = the level-0 face width, n_s the Blinn-Phong exponent; clamped to the chain).  A Cycles
Glossy BSDF of roughness r (GGX, alpha = r^2) has about the Blinn-Phong exponent
n_s = 2 / alpha^2 - 2 (Walter et al. 2007).  The lookups are seamless and trilinear
(envmap.sample_cube_mips), as a GL cube map with GL_TEXTURE_CUBE_MAP_SEAMLESS reads them.
"""
from __future__ import annotations

import numpy as np

from .envmap import sample_cube_mips

ALPHA_FLOOR = 1e-3          # a mirror: the exponent stays finite


def mcguire_mip_level(n_s, size):
    """Fractional mip level (0 = finest) for Blinn-Phong exponent ``n_s`` on a chain whose
    level 0 is ``size`` texels wide."""
    level = np.log2(size * np.sqrt(3.0)) - 0.5 * np.log2(np.maximum(np.asarray(n_s, float), 0) + 1)
    return np.clip(level, 0.0, np.log2(size))


def phong_exponent(roughness):
    """Blinn-Phong exponent of a GGX lobe of Blender roughness r (alpha = r^2): 2/alpha^2 - 2."""
    alpha = np.maximum(np.asarray(roughness, float) ** 2, ALPHA_FLOOR)
    return np.maximum(2.0 / alpha ** 2 - 2.0, 0.0)


def reflect(incident, normals):
    """Mirror directions (n, 3) of the unit ``incident`` directions (towards the surface) about
    unit ``normals``: i - 2 (i.n) n."""
    i = np.asarray(incident, float)
    n = np.asarray(normals, float)
    return i - 2.0 * np.sum(i * n, axis=-1, keepdims=True) * n


def glossy_radiance(mips, directions, n_s, padded=None):
    """Radiance (n, 3) reflected towards the viewer by a white Blinn-Phong lobe of exponent
    ``n_s`` (scalar or (n,)) around the mirror ``directions`` (n, 3): the mip chain ``mips``
    (lighting.EnvironmentLighting.mips) at McGuire's level."""
    level = mcguire_mip_level(n_s, mips[0].shape[1])
    return sample_cube_mips(mips, directions, level, padded)
