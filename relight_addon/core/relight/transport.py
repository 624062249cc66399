"""Leaf irradiances of a radiosity solution, with and without visibility, per lamp.

The solution's leaf gather holds, for every (leaf, source) entry, the unoccluded form factor F
and the form factor with visibility F V.  Gathering a per-lamp basis through each gives the
occluded and unoccluded irradiance of every leaf, and restricted to lamp sources their direct
parts: the four quantities the shadow-free pipeline divides (seed 000 eq 4.5-4.6).  Lamps that
are not patches (``scene.lights``) add their direct irradiance per leaf, stored with the
solution, at the exitance factors the basis was solved with.
"""
from __future__ import annotations

import numpy as np

from ..radiosity.solver import LeafSystem
from ..texture.mapping import texel_element_means


class Transport:
    """Leaf irradiances of a solution, unoccluded (F) and occluded (F V), all sources and lamps only."""

    def __init__(self, sol):
        h, g = sol.hierarchy, sol.gather
        rho = sol.scene.rho
        self.occ = sol.system
        self.unocc = LeafSystem.from_rows(h, g, rho, g.F)
        self.unocc.U, self.unocc.W = sol.system.U, sol.system.W
        lamps = g.restrict(sol.scene.lamp[h.patch[g.source]] >= 0)
        self.dir_occ = LeafSystem.from_rows(h, lamps, rho)
        self.dir_unocc = LeafSystem.from_rows(h, lamps, rho, lamps.F)
        # every system reads its sources as the solution's does (exposed parts: exposure.py)
        for system in (self.unocc, self.dir_occ, self.dir_unocc):
            system.P_up, system.exposure = sol.system.P_up, sol.system.exposure
        self.light_occ = self.light_unocc = 0.0
        if sol.light_occ is not None:
            s = np.ones(sol.scene.n_lamps) if sol.emission_scale is None else sol.emission_scale
            self.light_occ = sol.light_occ * s[:, None, None]          # (k, L, 3)
            self.light_unocc = sol.light_unocc * s[:, None, None]

    @staticmethod
    def per_lamp(system, basis):
        """Gather of a per-lamp leaf radiosity (k, L, 3) through ``system``: (k, L, 3)."""
        k, L, _ = basis.shape
        flat = np.moveaxis(basis, 0, 2).reshape(L, 3 * k)
        return np.moveaxis(system.gather(flat).reshape(L, 3, k), 2, 0)   # (k, L, 3)

    def irradiance(self, basis):
        """Per lamp (k, L, 3): occluded, unoccluded, direct occluded, direct unoccluded."""
        lo, lu = self.light_occ, self.light_unocc
        return (self.per_lamp(self.occ, basis) + lo, self.per_lamp(self.unocc, basis) + lu,
                self.per_lamp(self.dir_occ, basis) + lo,
                self.per_lamp(self.dir_unocc, basis) + lu)

    def total(self, radiosity, intensities, unoccluded=False):
        """Leaf irradiance (L, 3) of a leaf radiosity (L, 3) lit by lamps at ``intensities``."""
        system, light = (self.unocc, self.light_unocc) if unoccluded else \
            (self.occ, self.light_occ)
        return self._with_lights(system.gather(radiosity), light, intensities)

    def direct(self, radiosity, intensities, unoccluded=False):
        """The part of :meth:`total` that comes straight from the lamps (lamp patches at their
        radiosity, and the lights)."""
        system, light = (self.dir_unocc, self.light_unocc) if unoccluded else \
            (self.dir_occ, self.light_occ)
        return self._with_lights(system.gather(radiosity), light, intensities)

    @staticmethod
    def _with_lights(H, light, intensities):
        if not np.isscalar(light):
            H = H + np.tensordot(np.asarray(intensities, float), light, axes=1)
        return H


def as_given(per_lamp, scene):
    """The sum over lamps of per-lamp values (k, ...) at the scene's own lamp intensities (the
    lighting of the photo: a lamp that is off in it counts 0)."""
    return np.tensordot(np.asarray(scene.lamp_intensity, float), per_lamp, axes=1)


def leaf_means(sol, tm, values):
    """Mean of per-texel ``values`` (T, 3) over each leaf of the solution, and the texel counts
    (leaves without texels take their ancestors' means)."""
    h = sol.hierarchy
    means, counts = texel_element_means(h, tm, values)
    return means[sol.leaves], counts[sol.leaves]
