"""One rule for "agrees": a measured value against a reference, in standard errors.

Every comparison the studies and benchmarks print (granflow against a paper's printed
interval, against LAMMPS, a rate cell against a stress cell) reduces to a z: the distance in
SEs, and agreement is ``|z| <= AGREE_SIGMA``.
"""

from __future__ import annotations

import math

__all__ = ["AGREE_SIGMA", "agrees", "difference_z", "interval_z"]

#: two values agree where they are within this many (combined) SEs
AGREE_SIGMA = 2.0


def interval_z(value: float, se: float, lo: float, hi: float | None = None) -> float:
    """How many ``se`` ``value`` lies outside ``[lo, hi]`` (0 inside; ``hi`` defaults to
    ``lo``, a point). A printed number is known to half a unit of its last digit, so a paper's
    value is an interval. NaN where ``value`` or ``se`` is not finite or ``se <= 0``."""
    hi = lo if hi is None else hi
    if not (math.isfinite(value) and math.isfinite(se) and se > 0):
        return math.nan
    return max(lo - value, value - hi, 0.0) / se


def difference_z(a: float, a_se: float, b: float, b_se: float) -> tuple[float, float, float]:
    """``(a - b, its combined SE sqrt(a_se^2 + b_se^2), the difference over that SE)``; z is
    NaN where the combined SE is not positive."""
    se = math.hypot(a_se, b_se)
    diff = a - b
    return diff, se, (diff / se if se > 0 else math.nan)


def agrees(z: float, sigma: float = AGREE_SIGMA) -> bool:
    """``|z| <= sigma`` (False for a NaN z: no SE, no agreement)."""
    return bool(abs(z) <= sigma)
