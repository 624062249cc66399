# SPDX-License-Identifier: GPL-3.0-or-later
"""The main light of an environment map, as ARCore's Environmental HDR hands it over.

ARCore gives a renderer one main directional light (direction, intensity) beside ambient
spherical harmonics and a reflection cube map.  Here the main light is the brightest connected
region of the map: the pixels connected to the brightest one (8-connected, wrapping around in
longitude) whose luminance is above the geometric mean of that peak and the map's median
luminance (a sun, 10^4 x the sky, keeps its disk and inner halo; a softbox or a window in an
interior map keeps its outline).  The light is what that region adds to its surroundings: the
region's radiance minus the mean radiance of the ring of pixels around it, so that

    map = residual + light,      residual = the map with the region set to the ring's radiance

and the ambient SH is projected from the residual (SH9 of a map with a sun rings: its
irradiance is far from the truth near the sun's horizon, see benchmarks/results/ar.md).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..texture.colour import LUMINANCE
from .cap import cap_cosine_integral, cone_sin2
from .envmap import equirect_directions, equirect_solid_angles


@dataclass
class MainLight:
    """direction   (3,) unit world direction *towards* the light (a Blender sun's -Z axis
                   points the other way: ``-direction``)
    solid_angle  steradians of the light's region
    half_angle   radians: the cone of that solid angle, acos(1 - solid_angle / 2 pi)
    radiance     (3,) mean linear RGB radiance the light adds over its region
    irradiance   (3,) radiance x solid_angle: its irradiance at normal incidence (W/m^2; the
                 "intensity" of ARCore's main light, and a Blender sun's strength)
    share        the light's part of the map's luminous power (integral of L dw), in [0, 1]
    pixels       number of map pixels in the region"""

    direction: np.ndarray
    solid_angle: float
    half_angle: float
    radiance: np.ndarray
    irradiance: np.ndarray
    share: float
    pixels: int


def _component(mask, seed):
    """Mask of the 8-connected component of ``mask`` holding pixel ``seed``, wrapping in
    longitude (columns 0 and W-1 are neighbours)."""
    from scipy import ndimage
    h, w = mask.shape
    tiled = np.concatenate([mask, mask], axis=1)          # a component crossing the seam
    lab, _ = ndimage.label(tiled, structure=np.ones((3, 3), bool))
    r, c = seed
    ids = {lab[r, c], lab[r, c + w]}
    comp = np.isin(lab, list(ids))
    return comp[:, :w] | comp[:, w:]


def _ring(region):
    from scipy import ndimage
    h, w = region.shape
    tiled = np.concatenate([region[:, -2:], region, region[:, :2]], axis=1)
    grown = ndimage.binary_dilation(tiled, structure=np.ones((3, 3), bool), iterations=2)
    return grown[:, 2:-2] & ~region


def extract_main_light(env):
    """(MainLight, residual (H, W, 3)) of the validated equirectangular map ``env``
    (envmap.validate_environment).  A map without any contrast (uniform) gives a light of
    share 0 and the map itself as residual."""
    h, w = env.shape[:2]
    lum = env @ LUMINANCE
    om = np.broadcast_to(equirect_solid_angles(h, w)[:, None], (h, w))
    total = float((lum * om).sum())
    peak_at = np.unravel_index(np.argmax(lum), lum.shape)
    peak = float(lum[peak_at])
    median = float(np.median(lum))
    threshold = np.sqrt(max(peak, 0.0) * max(median, 0.0))
    region = _component(lum >= threshold, peak_at) if peak > median else np.zeros((h, w), bool)
    ring = _ring(region) if region.any() else np.zeros((h, w), bool)
    if ring.any():
        background = (env[ring] * om[ring, None]).sum(0) / om[ring].sum()
    else:
        background = np.zeros(3)
    added = np.where(region[..., None], np.maximum(env - background, 0.0), 0.0)
    power = (added * om[..., None]).sum(axis=(0, 1))          # (3,) integral of L dw
    dirs = equirect_directions(h, w)
    weight = (added @ LUMINANCE) * om
    vec = (dirs * weight[..., None]).sum(axis=(0, 1))
    norm = np.linalg.norm(vec)
    if not region.any() or norm <= 0 or total <= 0:
        zero = np.zeros(3)
        light = MainLight(np.array([0.0, 0.0, 1.0]), 0.0, 0.0, zero, zero, 0.0, 0)
        return light, env.copy()
    solid = float(om[region].sum())
    residual = env - added
    light = MainLight(direction=vec / norm, solid_angle=solid,
                      half_angle=float(np.arccos(np.clip(1.0 - solid / (2 * np.pi), -1, 1))),
                      radiance=power / solid, irradiance=power,
                      share=float(np.clip(power @ LUMINANCE / total, 0.0, 1.0)),
                      pixels=int(region.sum()))
    return light, residual


MAX_LIGHTS = 4              # ARCore hands over one; studio maps have three softboxes
MIN_SHARE = 0.05            # a further light must carry this part of the map's power
MAX_HALF_ANGLE = np.radians(20.0)   # a wider region is sky, not a light: the residual keeps it


def extract_lights(env, max_lights=MAX_LIGHTS, min_share=MIN_SHARE):
    """([MainLight, ...], residual): the main light (as :func:`extract_main_light`) then up to
    ``max_lights`` - 1 further compact lights taken from the residual in turn, each carrying at
    least ``min_share`` of the *original* map's luminous power and no wider than
    MAX_HALF_ANGLE.  lights[0] is ARCore's main light; the residual is what SH9 represents."""
    total = float(((env @ LUMINANCE) * equirect_solid_angles(*env.shape[:2])[:, None]).sum())
    lights, residual = [], env
    for k in range(max(1, int(max_lights))):
        light, rest = extract_main_light(residual)
        if light.pixels == 0:
            break
        share = float(light.irradiance @ LUMINANCE) / max(total, 1e-300)
        if k > 0 and (share < min_share or light.half_angle > MAX_HALF_ANGLE):
            break
        light.share = share
        lights.append(light)
        residual = rest
    if not lights:
        light, residual = extract_main_light(env)
        lights = [light]
    return lights, residual


def light_irradiance(light, normals):
    """Irradiance (n, 3) of ``light`` (a cone of its solid angle) on receivers with unit
    ``normals`` (n, 3): its radiance times the cone's clamped-cosine integral, exact across the
    horizon (cap.py)."""
    return light.radiance[None, :] * cap_cosine_integral(
        np.asarray(normals, float) @ light.direction, cone_sin2(light.half_angle))[:, None]
