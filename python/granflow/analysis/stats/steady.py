"""The end of a run's start-up transient (MSER) and the linear trend test of a time series."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from .._numerics import quiet
from ..tables import FloatArray
from .fp_blocking import blocking


@dataclass
class Trend:
    """Least-squares straight line ``x = a + slope t`` with a correlation-corrected slope SE.

    ``slope_se`` is the OLS slope error inflated by ``sqrt(g)`` of the residuals (their
    statistical inefficiency from blocking), ``t_stat = slope / slope_se`` and ``rel_drift`` is
    ``slope * (t_end - t_start) / |mean|`` (relative change across the fitted interval).
    """

    slope: float
    slope_se: float
    t_stat: float
    mean: float
    std: float
    rel_drift: float
    duration: float


@quiet
def trend(t: npt.ArrayLike, x: npt.ArrayLike) -> Trend:
    """Linear trend of ``x(t)`` with a slope SE that accounts for serial correlation."""
    tt = np.asarray(t, dtype=np.float64)
    xx = np.asarray(x, dtype=np.float64)
    ok = np.isfinite(tt) & np.isfinite(xx)
    tt, xx = tt[ok], xx[ok]
    n = tt.size
    if n < 3:
        return Trend(
            np.nan, np.nan, np.nan, float(np.mean(xx)) if n else np.nan, np.nan, np.nan, 0.0
        )
    tc = tt - tt.mean()
    sxx = float(np.sum(tc * tc))
    mean = float(xx.mean())
    slope = float(np.sum(tc * (xx - mean)) / sxx)
    resid = xx - mean - slope * tc
    s2 = float(np.sum(resid**2) / (n - 2))
    # (the plateau's g: the residual of a drift that is not linear is not stationary, and the
    # curve fit would read that very drift as a slow mode and hide it)
    g = blocking(resid, curve_fit=False).g if n >= 8 else 1.0
    g = max(g, 1.0) if np.isfinite(g) else 1.0
    slope_se = math.sqrt(s2 / sxx * g)
    duration = float(tt[-1] - tt[0])
    with np.errstate(divide="ignore", invalid="ignore"):
        t_stat = slope / slope_se if slope_se > 0 else (np.inf if slope else 0.0)
        rel = slope * duration / abs(mean) if mean != 0 else np.inf
    return Trend(slope, slope_se, float(t_stat), mean, float(xx.std()), float(rel), duration)


@dataclass
class SteadyStart:
    """End of the initial transient.

    Attributes
    ----------
    index, t_start
        First steady sample and its time.
    settled
        False when the MSER minimum sits on the edge of the search range (the transient may
        not be over; also the case for a drifting, e.g. accelerating, series).
    criterion
        Text description of the rule used.
    mser
        MSER statistic per candidate truncation (in batches).
    """

    index: int
    t_start: float
    settled: bool
    criterion: str
    mser: FloatArray = field(repr=False)


@quiet
def steady_state_start(
    t: npt.ArrayLike,
    series: npt.ArrayLike | Mapping[str, npt.ArrayLike],
    *,
    batch: int = 5,
    max_fraction: float = 0.5,
) -> SteadyStart:
    """The end of the start-up transient by the MSER-m rule: the one home of a run's steady
    start (the scenes choose what to pass: the channel ``|vcm_y|`` or its windows' mean
    velocity, the cell its key observables).

    MSER (White 1997; MSER-5 of White, Cobb & Spratt 2000): form means ``z_j`` of ``batch``
    consecutive samples; for every truncation ``d`` (in batches) up to ``max_fraction`` of the
    series compute ``MSER(d) = sum_{j>=d} (z_j - zbar_d)^2 / (N_b - d)^2`` (squared standard
    error of the truncated mean, uncorrelated estimate) and choose the ``d`` minimising it:
    dropping more data only pays while the removed samples bias the mean more than the loss of
    samples inflates its error.  If the minimum is at the largest allowed ``d`` the series is
    flagged ``settled=False``.

    Several observables (a mapping name -> samples): the latest of their starts, ``settled``
    only if every observable settled.

    Parameters
    ----------
    t
        Sample times.
    series
        Sample values (same length as ``t``), or a mapping of observable name -> values.
    batch
        Batch size m of MSER-m.
    max_fraction
        Largest fraction of the series that may be discarded.
    """
    if not isinstance(series, Mapping):
        return _mser_start(t, series, batch, max_fraction)
    starts = {k: _mser_start(t, v, batch, max_fraction) for k, v in series.items()}
    if not starts:
        raise ValueError("no columns given")
    last = max(starts.values(), key=lambda s: s.index)
    settled = all(s.settled for s in starts.values())
    crit = last.criterion + "; latest over " + ", ".join(starts)
    return SteadyStart(last.index, last.t_start, settled, crit, last.mser)


def _mser_start(t: npt.ArrayLike, series: npt.ArrayLike, batch: int,
                max_fraction: float) -> SteadyStart:
    """MSER-``batch`` start of one series (:func:`steady_state_start`)."""
    tt = np.asarray(t, dtype=np.float64)
    xx = np.asarray(series, dtype=np.float64)
    if tt.shape != xx.shape:
        raise ValueError("t and series must have the same shape")
    ok = np.isfinite(xx)
    idx_ok = np.flatnonzero(ok)
    crit = f"MSER-{batch}, truncation <= {max_fraction:g} of the series"
    if idx_ok.size == 0:
        return SteadyStart(0, float(tt[0]) if tt.size else np.nan, False, crit, np.zeros(0))
    x = xx[ok]
    nb = x.size // batch
    if nb < 4:
        return SteadyStart(int(idx_ok[0]), float(tt[idx_ok[0]]), False, crit, np.zeros(0))
    z = x[: nb * batch].reshape(nb, batch).mean(axis=1)
    z = z - z.mean()
    s1 = np.cumsum(z[::-1])[::-1]
    s2 = np.cumsum((z * z)[::-1])[::-1]
    cnt = nb - np.arange(nb, dtype=np.float64)
    ss = np.clip(s2 - s1 * s1 / cnt, 0.0, None)
    mser = ss / cnt**2
    dmax = max(1, int(math.floor(max_fraction * nb)))
    d = int(np.argmin(mser[: dmax + 1]))
    settled = d < dmax
    first = int(idx_ok[d * batch])
    return SteadyStart(first, float(tt[first]), bool(settled), crit, mser[: dmax + 1])
