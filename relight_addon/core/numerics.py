# SPDX-License-Identifier: GPL-3.0-or-later
"""One guard for the ratios of the core (DESIGN.md §4: guard every ratio, no NaN or Inf).

The denominators guarded here are non-negative quantities that are zero only where the ratio
has no meaning of its own: a degenerate face's area or normal length, the weight sum of an
empty set, the distance from a point to itself, the light on a texel that no lamp reaches.
There the numerator vanishes with them, and ``x / max(d, TINY)`` gives 0 instead of 0 / 0's
NaN, while anywhere ``d`` is a real value (far above TINY) it is exactly ``x / d``.

Floors that are thresholds rather than denominators (a fraction of the brightest value, a
solver's tolerance, the argument of a logarithm) keep their own names and values where they
are used.
"""
from __future__ import annotations

import numpy as np

# The smallest denominator: the least normal double above 0 by a margin (2.2e-308), so that
# its reciprocal (1e300) is finite and a numerator up to ~1e8 divided by it stays finite.
TINY = 1e-300


def nonzero(d):
    """``d`` (a scalar or an array) with every value below TINY raised to it: a denominator
    that can be divided by, in place or broadcast."""
    return np.maximum(d, TINY)


def safe_div(x, d):
    """``x / d`` with ``d`` floored at TINY (see the module docstring)."""
    return x / np.maximum(d, TINY)
