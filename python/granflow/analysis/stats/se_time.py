"""Standard error against averaging time: the SE of the first fractions of a run's steady part,
its fit ``SE = C / sqrt(T)`` and the time a target SE needs."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
import polars as pl

from .._numerics import quiet
from ..tables import FloatArray, sample_interval
from .fp_blocking import DEFAULT_MIN_BLOCKS, blocking
from .steady import steady_state_start

DEFAULT_FRACTIONS: tuple[float, ...] = (1 / 32, 1 / 16, 1 / 8, 1 / 4, 1 / 2, 1.0)


@dataclass
class SEvsTime:
    """Standard error against averaging time, with the fit ``SE = C / sqrt(T)``.

    Attributes
    ----------
    table
        Columns: fraction, n, T (simulated averaging time), wall_time (or null), mean, se,
        se_err, tau, converged.
    C, C_err
        Prefactor of ``SE = C / sqrt(T)``: ``se sqrt(T)`` of the full-length row when its
        blocking converged (the longest, most reliable estimate); else the fit on the converged
        rows (weighted geometric mean of ``se sqrt(T)``, weights ``(se / se_err)^2``), but not
        less than the full-length row implies (then a lower bound; ``too_short`` is set).
    exponent, exponent_err
        Free log-log slope of SE vs T over converged rows (should be close to -1/2).
    wall_time_per_unit_t
        Wall-clock seconds per unit of simulated time (if known).
    t_start
        Time at which the steady part (used here) starts.
    too_short
        True if the full-length estimate did not converge or fewer than two rows converged.
    """

    table: pl.DataFrame
    C: float
    C_err: float
    exponent: float
    exponent_err: float
    wall_time_per_unit_t: float | None
    t_start: float
    too_short: bool
    message: str = ""

    @quiet
    def predict_se(self, T: npt.ArrayLike) -> FloatArray:
        """``C / sqrt(T)``."""
        return self.C / np.sqrt(np.asarray(T, dtype=np.float64))

    @quiet
    def time_to_reach(self, target_se: float) -> dict[str, Any]:
        """Simulated (and wall-clock) averaging time needed for ``SE = target_se``.

        Returns a dict with ``T`` (total steady averaging time), ``T_more`` (beyond what was
        simulated), ``wall_time`` / ``wall_time_more`` (None if the wall rate is unknown) and
        ``reliable`` (False when the data were too short for a converged estimate).
        """
        T = (self.C / target_se) ** 2
        T_have = float(self.table["T"].to_numpy().max()) if self.table.height else 0.0
        more = max(0.0, T - T_have)
        w = self.wall_time_per_unit_t
        return {
            "T": T,
            "T_more": more,
            "wall_time": None if w is None else T * w,
            "wall_time_more": None if w is None else more * w,
            "reliable": not self.too_short and math.isfinite(T),
        }


def _fit_inverse_sqrt(
    T: FloatArray, se: FloatArray, se_err: FloatArray, ok: npt.NDArray[np.bool_]
) -> tuple[float, float, float, float]:
    """C, C_err (geometric weighted mean of se sqrt(T)) and the free log-log slope."""
    use = ok & np.isfinite(se) & (se > 0) & np.isfinite(T) & (T > 0)
    if not use.any():
        use = np.isfinite(se) & (se > 0) & (T > 0)
    if not use.any():
        return np.nan, np.nan, np.nan, np.nan
    logc = np.log(se[use]) + 0.5 * np.log(T[use])
    rel = np.where(se_err[use] > 0, se_err[use] / se[use], 1.0)
    w = 1.0 / rel**2
    lc = float(np.sum(w * logc) / np.sum(w))
    C = math.exp(lc)
    C_err = C * math.sqrt(1.0 / float(np.sum(w)))
    expo, expo_err = np.nan, np.nan
    if np.unique(T[use]).size >= 2:
        lt, ls = np.log(T[use]), np.log(se[use])
        A = np.vstack([np.ones_like(lt), lt]).T
        sw = np.sqrt(w)
        coef, *_ = np.linalg.lstsq(A * sw[:, None], ls * sw, rcond=None)
        cov = np.linalg.pinv((A * w[:, None]).T @ A)
        expo, expo_err = float(coef[1]), float(math.sqrt(max(cov[1, 1], 0.0)))
    return C, C_err, expo, expo_err


@quiet
def se_vs_time(
    t: npt.ArrayLike,
    series: npt.ArrayLike,
    wall_time_per_unit_t: float | None = None,
    fractions: Sequence[float] = DEFAULT_FRACTIONS,
    *,
    start: int | None = None,
    dt: float | None = None,
    min_blocks: int = DEFAULT_MIN_BLOCKS,
) -> SEvsTime:
    """SE of the mean computed from the first fraction ``f`` of the steady samples vs ``T``.

    ``T = n_f dt`` is the simulated averaging time of the first ``n_f`` steady samples; the
    wall time is ``T * wall_time_per_unit_t`` if given.  The steady part starts at ``start``
    (sample index) or, by default, at :func:`steady_state_start`.  Then ``SE ~ C / sqrt(T)`` is
    fitted and :meth:`SEvsTime.time_to_reach` extrapolates.

    Parameters
    ----------
    t, series
        Sample times and values.
    wall_time_per_unit_t
        Wall-clock seconds per unit simulated time (optional).
    fractions
        Fractions of the steady samples to use (values in (0, 1]).
    start
        First steady sample (default: automatic).
    dt
        Sample interval (default: median spacing of ``t``).
    min_blocks
        Convergence requirement passed to :func:`blocking`.
    """
    tt = np.asarray(t, dtype=np.float64)
    xx = np.asarray(series, dtype=np.float64)
    if start is None:
        start = steady_state_start(tt, xx).index
    dts = sample_interval(tt) if dt is None else float(dt)
    ts, xs = tt[start:], xx[start:]
    rows: list[dict[str, Any]] = []
    for f, n_f in prefix_lengths(fractions, xs.size):
        b = blocking(xs[:n_f], dts, min_blocks=min_blocks)
        rows.append(prefix_row(f, n_f, dts, wall_time_per_unit_t, b.mean, b.se, b.se_err, b.tau,
                               b.converged))
    return se_table_result(rows, wall_time_per_unit_t, float(ts[0]) if ts.size else np.nan)


def prefix_lengths(fractions: Sequence[float], n: int) -> list[tuple[float, int]]:
    """(fraction, number of samples) of every prefix of ``n`` samples with at least two."""
    out = []
    for f in sorted({float(v) for v in fractions}):
        n_f = int(round(f * n))
        if n_f >= 2:
            out.append((f, n_f))
    return out


def prefix_row(fraction: float, n: int, dt: float, wall_time_per_unit_t: float | None,
               mean: float, se: float, se_err: float, tau: float, converged: bool
               ) -> dict[str, Any]:
    """One row of an SE-against-averaging-time table (see :func:`se_table_result`) for the
    prefix of ``n`` samples ``dt`` apart."""
    T = n * dt
    return {
        "fraction": fraction,
        "n": n,
        "T": T,
        "wall_time": None if wall_time_per_unit_t is None else T * wall_time_per_unit_t,
        "mean": mean,
        "se": se,
        "se_err": se_err,
        "tau": tau,
        "converged": converged,
    }


@quiet
def se_table_result(rows: list[dict[str, Any]], wall: float | None, t_start: float) -> SEvsTime:
    schema = {
        "fraction": pl.Float64,
        "n": pl.Int64,
        "T": pl.Float64,
        "wall_time": pl.Float64,
        "mean": pl.Float64,
        "se": pl.Float64,
        "se_err": pl.Float64,
        "tau": pl.Float64,
        "converged": pl.Boolean,
    }
    table = pl.DataFrame(rows, schema=schema)
    if table.height == 0:
        return SEvsTime(
            table, np.nan, np.nan, np.nan, np.nan, wall, t_start, True, "no steady samples"
        )
    T = table["T"].to_numpy()
    se = table["se"].to_numpy()
    se_err = table["se_err"].to_numpy()
    conv = table["converged"].to_numpy()
    C, C_err, ex, ex_err = _fit_inverse_sqrt(T, se, se_err, conv)
    too_short = (not bool(conv[-1])) or int(conv.sum()) < 2
    if se[-1] > 0:
        # anchor C on the full-length estimate: shorter prefixes hold fewer blocks and can miss
        # the longer correlations (their tau grows with T), so a fit dominated by them
        # predicted less time than the measured SE already implies. Unconverged, the last SE
        # is itself an underestimate: C is then at least what it implies (a lower bound).
        c_last = float(se[-1] * math.sqrt(T[-1]))
        if not too_short:
            C, C_err = c_last, float(se_err[-1] * math.sqrt(T[-1]))
        elif not c_last <= C:
            C = c_last
    msg = ""
    if too_short:
        msg = (
            "data too short: blocking did not reach a plateau "
            f"({int(conv.sum())}/{conv.size} prefixes converged); C and times are rough"
        )
    return SEvsTime(table, C, C_err, ex, ex_err, wall, t_start, too_short, msg)

