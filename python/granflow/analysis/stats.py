"""Statistical error of time series: Flyvbjerg-Petersen blocking, means and ratios with
standard errors, the trend test and steady-state detection, SE against averaging time, and the
jackknife over blocks.

Everything here works on *samples* of a time series (one row per sample of a ``series`` table, or
one window of a ``bins`` table) and never on particles.

Conventions
-----------
* ``dt`` is the interval between samples (simulation time units).  For a series sampled every
  ``dt`` the integrated autocorrelation time is
  ``tau_int = dt * (1/2 + sum_{k>=1} rho_k)``, so that the variance of the mean of ``n`` samples is
  ``var(mean) = sigma^2 * (2 tau_int / dt) / n``.  The *statistical inefficiency* is
  ``g = 2 tau_int / dt = (SE / SE_naive)^2`` where ``SE_naive = sqrt(sigma^2 / (n - 1))`` is the
  standard error one would quote for uncorrelated samples.  Hence ``tau = g dt / 2``
  (uncorrelated samples: ``g = 1``, ``tau = dt / 2``).
* Standard errors come from Flyvbjerg & Petersen blocking (J. Chem. Phys. 91, 461 (1989)):
  at level ``k`` the series is replaced by means of pairs of the level ``k-1`` series, and
  ``SE_k^2 = c0_k / (n_k - 1)`` with ``c0_k`` the (biased) variance of the ``n_k`` block means;
  its own uncertainty is ``SE_k / sqrt(2 (n_k - 1))`` (FP eq. 28-29).
* The plateau of ``SE_k`` is located automatically with the hypothesis test of Jonsson
  (Phys. Rev. E 98, 043304 (2018)): level ``j`` is accepted when
  ``M_j = sum_{k>=j} n_k (gamma_k / c0_k)^2`` (``gamma_k`` the lag-1 autocovariance of the level-k
  block means) is below the ``1 - alpha`` quantile of chi-squared with (number of levels - j)
  degrees of freedom, i.e. when the remaining block means show no significant lag-1 correlation;
  in addition the level's own term ``n_j (gamma_j / c0_j)^2`` must be below the one-degree
  quantile.  The first accepted level is the plateau.  Since the test has little power with few
  blocks, the result is flagged ``converged=False`` (the series is too short for the blocking to
  *reach* a plateau and the SE is probably an underestimate) unless both

  1. the plateau level has at least ``min_blocks`` blocks (default 20, i.e. a 16 % uncertainty
     of the SE itself), and
  2. the plateau block length ``b = 2^k`` is at least ``4 (g - 1)`` samples.  For a block length
     ``b`` the variance of the mean estimated from the block means is short by about
     ``(g - 1) / (2 b)`` (AR(1) process), so this keeps the low bias of the SE below ~6 %.

  Because Jonsson's test at ``alpha = 0.01`` accepts levels whose blocks still carry a little
  correlation (SE ~5-10 % low for long series), the reported level is the first level at or
  above Jonsson's with ``b >= 8 (g_J - 1)`` (``g_J`` the inefficiency at Jonsson's level) and at
  least ``min_blocks`` blocks (bias ~3 %); if there is none, Jonsson's level is reported.
"""

from __future__ import annotations

import functools
import math
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, NamedTuple, ParamSpec, TypeVar

import numpy as np
import numpy.typing as npt
import polars as pl
from scipy import stats

from .tables import FloatArray, IntArray, sample_interval

_P = ParamSpec("_P")
_R = TypeVar("_R")


def quiet(fn: Callable[_P, _R]) -> Callable[_P, _R]:
    """Run ``fn`` under ``np.errstate(all="ignore")`` with numpy's RuntimeWarnings (empty
    slices, invalid values) silenced: analysis code lets NaN/inf propagate and must not trip a
    global ``np.seterr(all="raise")`` (e.g. on harmless underflow)."""

    @functools.wraps(fn)
    def wrapper(*args: _P.args, **kwargs: _P.kwargs) -> _R:
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            return fn(*args, **kwargs)

    return wrapper


DEFAULT_MIN_BLOCKS = 20
DEFAULT_ALPHA = 0.01
DEFAULT_FRACTIONS: tuple[float, ...] = (1 / 32, 1 / 16, 1 / 8, 1 / 4, 1 / 2, 1.0)


# --------------------------------------------------------------------------------------------
# Flyvbjerg-Petersen blocking
# --------------------------------------------------------------------------------------------
@dataclass
class BlockingResult:
    """Blocking analysis of one series (see module docstring for the definitions).

    Attributes
    ----------
    mean, se, se_err
        Sample mean, plateau standard error of the mean and the uncertainty of that SE.
    se_naive
        SE assuming uncorrelated samples (level 0).
    g
        Statistical inefficiency ``(se / se_naive)^2``.
    tau
        Integrated autocorrelation time ``g dt / 2`` in the units of ``dt``.
    level, block_size, n_blocks
        Plateau level, its block length (samples) and number of blocks.
    n
        Number of (finite) samples.
    converged
        False if the series is too short for the blocking to reach a plateau.
    levels
        Per-level table: level, block_size, n_blocks, se, se_err, lag1 (lag-1 autocorrelation of
        the block means), M (Jonsson statistic), threshold (chi-squared quantile), accepted.
    """

    mean: float
    se: float
    se_err: float
    se_naive: float
    g: float
    tau: float
    level: int
    block_size: int
    n_blocks: int
    n: int
    converged: bool
    levels: pl.DataFrame = field(repr=False)


@dataclass
class BlockingArrays:
    """Vectorised blocking result for ``m`` series of equal length (one entry per series)."""

    mean: FloatArray
    se: FloatArray
    se_err: FloatArray
    se_naive: FloatArray
    g: FloatArray
    tau: FloatArray
    level: IntArray
    n_blocks: IntArray
    n: IntArray
    converged: npt.NDArray[np.bool_]


def _levels_2d(x: FloatArray) -> tuple[list[int], FloatArray, FloatArray, FloatArray]:
    """Blocking transformation of the columns of ``x`` (n, m), all finite.

    Returns the block counts n_k and arrays (K, m) of mean, c0 (biased variance) and gamma
    (biased lag-1 autocovariance, Jonsson's definition) of the level-k block means.
    """
    nks: list[int] = []
    means: list[FloatArray] = []
    c0s: list[FloatArray] = []
    c1s: list[FloatArray] = []
    while x.shape[0] >= 2:
        n = x.shape[0]
        mu = x.mean(axis=0)
        dev = x - mu
        nks.append(n)
        means.append(mu)
        c0s.append(np.mean(dev * dev, axis=0))
        c1s.append(np.sum(dev[:-1] * dev[1:], axis=0) / n)
        half = n // 2
        x = 0.5 * (x[0 : 2 * half : 2] + x[1 : 2 * half : 2])
    return nks, np.array(means), np.array(c0s), np.array(c1s)


#: levels with at least this many blocks enter the fit of the blocking curve
FIT_MIN_BLOCKS = 16
#: correlation times (in samples) tried by the fit: log-spaced from 0.05 to n/2
FIT_TAUS = 40
#: chi^2 a second correlation time must gain to be kept (two more parameters)
SECOND_MODE_PENALTY = 6.0


def _block_inflation(b: FloatArray, r: FloatArray) -> FloatArray:
    """h(b, r) = b Var(mean of b samples) / sigma^2 for correlations rho_j = r^j:
    1 + 2 [r/(1-r) - r (1 - r^b) / (b (1-r)^2)]; shape (len(r), len(b))."""
    r = r[:, None]
    return 1.0 + 2.0 * (r / (1.0 - r) - r * (1.0 - r ** b[None, :]) / (b[None, :] * (1.0 - r) ** 2))


def _curve_inefficiency(nks: Sequence[int], se_k: FloatArray, se_err_k: FloatArray) -> FloatArray:
    """Statistical inefficiency g of every column from a fit of its blocking curve.

    With correlations a sum of one or two exponentials, rho_j = sum_i c_i r_i^j, the squared SE
    of level k (block length b) is SE_b^2 = sum_i A_i h(b, r_i) (:func:`_block_inflation`),
    which tends to sum_i A_i (1 + r_i)/(1 - r_i) as b grows. The A_i (>= 0, linear) and the
    r_i = exp(-1/tau_i) (tau_i on a log grid to n/2 samples) are fitted to SE_k^2 over the
    levels with >= FIT_MIN_BLOCKS blocks, weighted by their variance (2 SE_k SE_err_k)^2; the
    second time is kept when it lowers chi^2 by more than SECOND_MODE_PENALTY. g is the
    asymptote over SE_0^2; NaN where fewer than 3 levels qualify or a column is constant.

    Why: the cell's volume (phi) under the barostat has a slow mode beside the collisional one,
    and its blocking curve rises again at the longest blocks that still have enough of them; a
    plateau test accepts the shoulder between the two and gave SEs 1.5x too small
    (benchmarks/seed_coverage.py). One exponential fitted to the whole curve follows the
    precise short blocks and misses a slow mode too (2.4x on a two-time AR(1) sum)."""
    nk = np.asarray(nks, dtype=np.float64)
    m = se_k.shape[1] if se_k.ndim == 2 else 0
    sel = nk >= FIT_MIN_BLOCKS
    if m == 0 or sel.sum() < 3:
        return np.full(m, np.nan)
    y = se_k[sel] ** 2  # (L, m)
    with np.errstate(divide="ignore", invalid="ignore"):
        w = 1.0 / (2.0 * se_k[sel] * se_err_k[sel]) ** 2
    ok = np.isfinite(w).all(axis=0) & (y[0] > 0)
    w = np.where(np.isfinite(w), w, 0.0)
    r = np.exp(-1.0 / np.geomspace(0.05, max(nk[0] / 2.0, 0.1), FIT_TAUS))
    h = _block_inflation(np.exp2(np.arange(nk.size, dtype=np.float64))[sel], r)  # (T, L)
    gr = (1.0 + r) / (1.0 - r)
    # normal equations per (time, column): hh[t] = sum_l w h_t h_t, hy[t] = sum_l w h_t y
    hy = np.einsum("tl,lm->tm", h, w * y)
    hh = np.einsum("tl,sl,lm->tsm", h, h, w)
    yy = np.einsum("lm,lm->m", w, y * y)
    diag = np.einsum("ttm->tm", hh)
    a1 = hy / diag
    chi = yy[None, :] - a1 * hy  # one time: chi^2 = yy - A hy at the optimum
    best_chi = chi.min(axis=0)
    best_g = np.take_along_axis(a1 * gr[:, None], chi.argmin(axis=0)[None, :], 0)[0]
    for i in range(r.size - 1):  # two times tau_i < tau_j
        a11, a22, a12 = diag[i][None, :], diag[i + 1:], hh[i, i + 1:]
        b1, b2 = hy[i][None, :], hy[i + 1:]
        det = a11 * a22 - a12 * a12
        with np.errstate(divide="ignore", invalid="ignore"):
            x1 = (b1 * a22 - b2 * a12) / det
            x2 = (a11 * b2 - a12 * b1) / det
        c2 = yy[None, :] - x1 * b1 - x2 * b2 + SECOND_MODE_PENALTY
        c2 = np.where((x1 >= 0) & (x2 >= 0) & (det > 0), c2, np.inf)
        j = c2.argmin(axis=0)
        cj = np.take_along_axis(c2, j[None, :], 0)[0]
        gj = (np.take_along_axis(x1 * gr[i] + x2 * gr[i + 1:, None], j[None, :], 0)[0])
        better = cj < best_chi
        best_chi = np.where(better, cj, best_chi)
        best_g = np.where(better, gj, best_g)
    return np.where(ok, best_g / y[0], np.nan)


def _blocking_finite(
    x: FloatArray, dt: float, alpha: float, min_blocks: int, curve_fit: bool = True
) -> tuple[BlockingArrays, list[int], FloatArray, FloatArray, FloatArray, FloatArray]:
    """Blocking of the finite (n, m) array ``x``; see :func:`blocking_many`."""
    n, m = x.shape
    if n < 2:
        nan = np.full(m, np.nan)
        mean = x.mean(axis=0) if n == 1 else nan
        res = BlockingArrays(
            mean=np.asarray(mean, dtype=np.float64),
            se=nan,
            se_err=nan,
            se_naive=nan,
            g=nan,
            tau=nan,
            level=np.zeros(m, np.int64),
            n_blocks=np.full(m, n, np.int64),
            n=np.full(m, n, np.int64),
            converged=np.zeros(m, bool),
        )
        empty = np.zeros((0, m))
        return res, [], empty, empty, empty, empty
    nks, _means, c0, c1 = _levels_2d(x)
    nk = np.asarray(nks, dtype=np.float64)[:, None]
    n_levels = len(nks)
    se_k = np.sqrt(c0 / (nk - 1.0))
    se_err_k = se_k / np.sqrt(2.0 * (nk - 1.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        rho = np.where(c0 > 0, c1 / c0, 0.0)
    terms = nk * rho**2
    big_m = np.cumsum(terms[::-1], axis=0)[::-1]  # M_j = sum_{k>=j} n_k rho_k^2
    dof = n_levels - np.arange(n_levels)
    thresh = stats.chi2.ppf(1.0 - alpha, dof)[:, None]
    # Jonsson's global test, plus the same test on the level's own lag-1 correlation (the sum
    # over many levels dilutes a single clearly correlated level when the series is short)
    accepted = (big_m < thresh) & (terms < stats.chi2.ppf(1.0 - alpha, 1))
    accepted[-1, :] = True  # the last level is always (trivially) acceptable
    k_jonsson = np.argmax(accepted, axis=0)
    se_naive = se_k[0]
    with np.errstate(divide="ignore", invalid="ignore"):
        g_k = np.where(se_naive > 0, (se_k / se_naive) ** 2, 1.0)
    blk = (2.0 ** np.arange(n_levels))[:, None]
    # refinement: first level >= Jonsson's whose blocks are long enough for a small bias, with
    # the block length required from g at Jonsson's level (re-evaluating g at every level would
    # chase upward noise of the SE)
    g_j = g_k[k_jonsson, np.arange(m)]
    good = (
        (np.arange(n_levels)[:, None] >= k_jonsson[None, :])
        & (blk >= 8.0 * (g_j[None, :] - 1.0))
        & (nk >= min_blocks)
    )
    level = np.where(good.any(axis=0), np.argmax(good, axis=0), k_jonsson).astype(np.int64)
    cols = np.arange(m)
    se = se_k[level, cols]
    se_err = se_err_k[level, cols]
    g = g_k[level, cols]
    n_blocks = np.asarray(nks, dtype=np.int64)[level]
    converged = (n_blocks >= min_blocks) & (2.0**level >= 4.0 * (g - 1.0))
    g_fit = _curve_inefficiency(nks, se_k, se_err_k) if curve_fit else np.full(m, np.nan)
    fit = np.isfinite(g_fit) & (se_naive > 0)
    if fit.any():
        # the curve's asymptote where it can be fitted (module docstring); the plateau level
        # stays the one reported, with the SE's own error scaled to the new SE
        g = np.where(fit, g_fit, g)
        se_err = np.where(fit, se_err * np.sqrt(g_fit) * se_naive / np.where(se > 0, se, 1.0),
                          se_err)
        se = np.where(fit, np.sqrt(g_fit) * se_naive, se)
        converged = np.where(fit, n / g >= min_blocks, converged)
    res = BlockingArrays(
        mean=x.mean(axis=0),
        se=se,
        se_err=se_err,
        se_naive=se_naive,
        g=g,
        tau=0.5 * g * dt,
        level=level,
        n_blocks=n_blocks,
        n=np.full(m, n, np.int64),
        converged=converged,
    )
    return res, nks, se_k, se_err_k, rho, np.concatenate([big_m, thresh], axis=1)


@quiet
def blocking_many(
    x: npt.ArrayLike,
    dt: float = 1.0,
    *,
    alpha: float = DEFAULT_ALPHA,
    min_blocks: int = DEFAULT_MIN_BLOCKS,
    curve_fit: bool = True,
) -> BlockingArrays:
    """Flyvbjerg-Petersen blocking of every column of a 2-D array (samples x series).

    Vectorised over the columns; columns containing NaN are analysed separately on their finite
    samples (NaN samples are dropped, which is only appropriate if they are rare).

    Parameters
    ----------
    x
        Array of shape (n_samples, n_series) (a 1-D array is treated as one series).
    dt
        Sample interval, used for ``tau = g dt / 2``.
    alpha
        Significance level of Jonsson's plateau test.
    min_blocks
        Minimum number of blocks at the plateau level for ``converged=True``.
    curve_fit
        Take the SE from the fit of the blocking curve (:func:`_curve_inefficiency`) where it
        can be made (the default); False: the plateau level's SE.
    """
    arr = np.asarray(x, dtype=np.float64)
    if arr.ndim == 1:
        arr = arr[:, None]
    finite = np.isfinite(arr)
    good = finite.all(axis=0)
    out, *_ = _blocking_finite(arr[:, good], dt, alpha, min_blocks, curve_fit)
    if good.all():
        return out
    m = arr.shape[1]
    res = BlockingArrays(
        mean=np.full(m, np.nan),
        se=np.full(m, np.nan),
        se_err=np.full(m, np.nan),
        se_naive=np.full(m, np.nan),
        g=np.full(m, np.nan),
        tau=np.full(m, np.nan),
        level=np.zeros(m, np.int64),
        n_blocks=np.zeros(m, np.int64),
        n=np.zeros(m, np.int64),
        converged=np.zeros(m, bool),
    )
    names = ("mean", "se", "se_err", "se_naive", "g", "tau", "level", "n_blocks", "n", "converged")
    for name in names:
        getattr(res, name)[good] = getattr(out, name)
    for j in np.flatnonzero(~good):  # loop over series (bins), never over particles
        col = arr[finite[:, j], j][:, None]
        one, *_ = _blocking_finite(col, dt, alpha, min_blocks, curve_fit)
        for name in names:
            getattr(res, name)[j] = getattr(one, name)[0]
    return res


@quiet
def blocking(
    series: npt.ArrayLike,
    dt: float = 1.0,
    *,
    alpha: float = DEFAULT_ALPHA,
    min_blocks: int = DEFAULT_MIN_BLOCKS,
    curve_fit: bool = True,
) -> BlockingResult:
    """Flyvbjerg-Petersen blocking analysis of one series with automatic plateau detection.

    Implements FP (1989) eqs. 20-29 (block transformation, SE per level and its uncertainty) and
    Jonsson's (2018) plateau criterion; see the module docstring.  NaN samples are dropped.

    Parameters
    ----------
    series
        1-D samples, equally spaced in time.
    dt
        Sample interval (for ``tau``).
    alpha, min_blocks, curve_fit
        Plateau-test level, the minimum number of plateau blocks for ``converged``, and
        whether the SE comes from the blocking curve's fit (see :func:`blocking_many`).
    """
    x = np.asarray(series, dtype=np.float64).ravel()
    x = x[np.isfinite(x)]
    res, nks, se_k, se_err_k, rho, mt = _blocking_finite(x[:, None], dt, alpha, min_blocks,
                                                         curve_fit)
    k = len(nks)
    levels = pl.DataFrame(
        {
            "level": np.arange(k, dtype=np.int64),
            "block_size": (2 ** np.arange(k)).astype(np.int64),
            "n_blocks": np.asarray(nks, dtype=np.int64),
            "se": se_k[:, 0] if k else np.zeros(0),
            "se_err": se_err_k[:, 0] if k else np.zeros(0),
            "lag1": rho[:, 0] if k else np.zeros(0),
            "M": mt[:, 0] if k else np.zeros(0),
            "threshold": mt[:, 1] if k else np.zeros(0),
        }
    ).with_columns((pl.col("M") < pl.col("threshold")).alias("accepted"))
    lev = int(res.level[0])
    return BlockingResult(
        mean=float(res.mean[0]),
        se=float(res.se[0]),
        se_err=float(res.se_err[0]),
        se_naive=float(res.se_naive[0]),
        g=float(res.g[0]),
        tau=float(res.tau[0]),
        level=lev,
        block_size=2**lev,
        n_blocks=int(res.n_blocks[0]),
        n=int(x.size),
        converged=bool(res.converged[0]),
        levels=levels,
    )


class MeanSE(NamedTuple):
    """``(mean, se, tau, converged, n)`` of a series (a tuple with names)."""

    mean: float
    se: float
    tau: float
    converged: bool
    n: int


@quiet
def mean_se(
    series: npt.ArrayLike,
    dt: float = 1.0,
    *,
    alpha: float = DEFAULT_ALPHA,
    min_blocks: int = DEFAULT_MIN_BLOCKS,
) -> MeanSE:
    """Mean, blocking standard error, integrated correlation time ``tau = g dt / 2``,
    convergence flag and sample count of a series (see :func:`blocking`)."""
    b = blocking(series, dt, alpha=alpha, min_blocks=min_blocks)
    return MeanSE(b.mean, b.se, b.tau, b.converged, b.n)


@quiet
def ratio_se(
    a: npt.ArrayLike,
    b: npt.ArrayLike,
    dt: float = 1.0,
    *,
    min_blocks: int = DEFAULT_MIN_BLOCKS,
) -> MeanSE:
    """Ratio of means ``r = <a>/<b>`` with its SE from blocking the linearised series
    ``z_i = (a_i - r b_i) / <b>`` (delta method; keeps the a-b cross-correlation)."""
    aa = np.asarray(a, dtype=np.float64)
    bb = np.asarray(b, dtype=np.float64)
    ok = np.isfinite(aa) & np.isfinite(bb)
    aa, bb = aa[ok], bb[ok]
    mb = float(np.mean(bb)) if len(bb) else 0.0
    if mb == 0.0:
        # the ratio is undefined (e.g. no wall contact yet): say so instead of dividing by 0
        return MeanSE(float("nan"), float("nan"), float("nan"), False, len(aa))
    r = float(np.mean(aa)) / mb
    z = (aa - r * bb) / mb
    blk = blocking(z, dt, min_blocks=min_blocks)
    return MeanSE(r, blk.se, blk.tau, blk.converged, blk.n)


# --------------------------------------------------------------------------------------------
# trend test and steady-state detection
# --------------------------------------------------------------------------------------------
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
    series: npt.ArrayLike,
    *,
    batch: int = 5,
    max_fraction: float = 0.5,
) -> SteadyStart:
    """Detect the end of the start-up transient with the MSER-m rule.

    MSER (White 1997; MSER-5 of White, Cobb & Spratt 2000): form means ``z_j`` of ``batch``
    consecutive samples; for every truncation ``d`` (in batches) up to ``max_fraction`` of the
    series compute ``MSER(d) = sum_{j>=d} (z_j - zbar_d)^2 / (N_b - d)^2`` (squared standard
    error of the truncated mean, uncorrelated estimate) and choose the ``d`` minimising it:
    dropping more data only pays while the removed samples bias the mean more than the loss of
    samples inflates its error.  If the minimum is at the largest allowed ``d`` the series is
    flagged ``settled=False``.

    Parameters
    ----------
    t, series
        Sample times and values (same length).
    batch
        Batch size m of MSER-m.
    max_fraction
        Largest fraction of the series that may be discarded.
    """
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


@quiet
def steady_state_start_multi(
    t: npt.ArrayLike, columns: Mapping[str, npt.ArrayLike], **kwargs: Any
) -> SteadyStart:
    """Steady start common to several observables: the latest of their MSER starts;
    ``settled`` only if every observable settled."""
    starts = {k: steady_state_start(t, v, **kwargs) for k, v in columns.items()}
    if not starts:
        raise ValueError("no columns given")
    last = max(starts.values(), key=lambda s: s.index)
    settled = all(s.settled for s in starts.values())
    crit = last.criterion + "; latest over " + ", ".join(starts)
    return SteadyStart(last.index, last.t_start, settled, crit, last.mser)


# --------------------------------------------------------------------------------------------
# SE against averaging time
# --------------------------------------------------------------------------------------------
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


# --------------------------------------------------------------------------------------------
# jackknife over blocks of samples
# --------------------------------------------------------------------------------------------
def choose_blocks(n: int, g: float = 1.0, max_blocks: int = 32) -> tuple[int, int]:
    """Block length ``L >= ceil(g)`` (g = statistical inefficiency, in samples) and number of
    blocks ``n // L`` (at most ``max_blocks``) for a jackknife over contiguous blocks."""
    g = g if np.isfinite(g) else 1.0
    L = max(1, int(math.ceil(g)), int(math.ceil(n / max_blocks)))
    return L, n // L


@quiet
def jackknife_se(full: Any, replicates: Sequence[Any]) -> Any:
    """Delete-one-block jackknife SE: ``sqrt((nb-1)/nb * sum_i (theta_i - mean theta)^2)``.

    ``full`` is the estimate from all data (returned unchanged by the caller); works for
    scalars and arrays (element-wise, NaN replicates ignored).
    """
    reps = np.asarray([np.asarray(r, dtype=np.float64) for r in replicates])
    if reps.shape[0] < 2:
        return np.full(np.shape(full), np.nan) if np.ndim(full) else np.nan
    fin = np.isfinite(reps)
    nb = fin.sum(axis=0).astype(np.float64)
    mean = np.where(fin, reps, 0.0).sum(axis=0) / np.maximum(nb, 1.0)
    ssq = np.where(fin, (reps - mean) ** 2, 0.0).sum(axis=0)
    se = np.sqrt(np.where(nb >= 2, (nb - 1.0) / np.maximum(nb, 1.0) * ssq, np.nan))
    return float(se) if np.ndim(se) == 0 else se


@quiet
def block_means(
    x: FloatArray, weights: FloatArray, block_len: int
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Weighted full mean and leave-one-block-out means of ``x`` (n, ...) over contiguous blocks.

    The first ``n mod block_len`` samples (the earliest) are discarded so that all blocks are
    equal.  Returns (full mean over the kept samples, loo means (nb, ...), kept mask).
    """
    n = x.shape[0]
    nb = n // block_len
    drop = n - nb * block_len
    keep = np.arange(n) >= drop
    xk = x[drop:].reshape((nb, block_len) + x.shape[1:])
    wk = weights[drop:].reshape(nb, block_len)
    wshape = (nb, block_len) + (1,) * (x.ndim - 1)
    s = np.sum(xk * wk.reshape(wshape), axis=1)
    w = np.sum(wk, axis=1).reshape((nb,) + (1,) * (x.ndim - 1))
    full = s.sum(axis=0) / w.sum(axis=0)
    loo = (s.sum(axis=0)[None] - s) / (w.sum(axis=0)[None] - w)
    return full, loo, keep


@quiet
def jackknife(
    fn: Callable[[FloatArray], Any], full_input: FloatArray, loo_inputs: FloatArray
) -> tuple[Any, Any]:
    """Evaluate ``fn`` on the full-sample mean and on each leave-one-block-out mean and return
    ``(value, jackknife SE)``."""
    value = fn(full_input)
    reps = [fn(loo_inputs[i]) for i in range(loo_inputs.shape[0])]
    return value, jackknife_se(value, reps)
