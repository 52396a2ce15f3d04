"""Is the steady part of a run stationary? The means of its first and last thirds against
their blocking SEs, for every reported quantity at once.

Why thirds and not the MSER start alone: MSER (:mod:`.steady`) picks the truncation that
minimises the SE of what is left, and on a run shorter than its transient (or drifting slowly
towards a runaway) it accepts a start inside the drift; the 002 campaign's pairs of seeds then
differed by up to 9 combined SEs in I. A drift that changes a quantity by Delta across the part
moves the thirds' means apart by 2 Delta / 3; their difference over its SE (each third's SE
from its own blocking, the thirds ~independent when a third spans many correlation times) is
standard normal for a stationary series.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from .._numerics import quiet
from .fp_blocking import blocking_many

#: |z| above which a quantity counts as drifting (two-sided p ~ 0.003 per quantity: ~1 %
#: false alarms over the four quantities a campaign point reports)
DRIFT_Z = 3.0
#: fewest samples in a third for the test to be made (fewer: not tested, ``tested`` False)
MIN_THIRD_SAMPLES = 16


@dataclass(frozen=True)
class Stationarity:
    """The thirds test of one or more quantities (:func:`stationarity`).

    Attributes
    ----------
    z
        Per quantity: (mean of the last third - mean of the first) / its SE.
    worst
        The quantity with the largest ``|z|`` ("" when none was tested).
    max_abs_z
        That ``|z|`` (NaN when none was tested).
    stationary
        ``max_abs_z <= z_max`` (False when the series is too short to test).
    tested
        Whether every third had enough samples.
    """

    z: Mapping[str, float]
    worst: str
    max_abs_z: float
    stationary: bool
    tested: bool


@quiet
def stationarity(series: Mapping[str, npt.ArrayLike], *, z_max: float = DRIFT_Z) -> Stationarity:
    """The thirds test of each quantity of ``series`` (name -> samples of the steady part,
    equally spaced): z = (mean of the last third - mean of the first third) / sqrt(SE1^2 +
    SE3^2), SEs by blocking each third (:func:`~.fp_blocking.blocking_many`). Stationary when
    every ``|z| <= z_max``; a series with fewer than 3 x MIN_THIRD_SAMPLES samples is not
    tested (``stationary`` False)."""
    names = list(series)
    if not names:
        raise ValueError("no quantities given")
    cols = [np.asarray(series[k], dtype=np.float64) for k in names]
    n = min(c.size for c in cols)
    k = n // 3
    if k < MIN_THIRD_SAMPLES:
        return Stationarity({c: math.nan for c in names}, "", math.nan, False, False)
    mat = np.column_stack([c[:n] for c in cols])
    first, last = blocking_many(mat[:k]), blocking_many(mat[n - k:])
    with np.errstate(divide="ignore", invalid="ignore"):
        se = np.sqrt(first.se**2 + last.se**2)
        diff = last.mean - first.mean
        z = np.where(se > 0, diff / se, np.where(diff != 0, np.inf, 0.0))
    z = np.where(np.isfinite(first.se) & np.isfinite(last.se), z, np.nan)
    zs = {c: float(v) for c, v in zip(names, z, strict=True)}
    finite = {c: abs(v) for c, v in zs.items() if not math.isnan(v)}
    if not finite:
        return Stationarity(zs, "", math.nan, False, False)
    worst = max(finite, key=lambda c: finite[c])
    return Stationarity(zs, worst, finite[worst], finite[worst] <= z_max, True)
