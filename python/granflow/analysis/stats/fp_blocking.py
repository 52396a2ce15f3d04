"""Flyvbjerg-Petersen blocking of time series: the standard error of a mean, of many means at
once, and of a ratio of means.

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

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
import polars as pl
from scipy import stats

from .._numerics import quiet
from ..estimate import Estimate
from ..tables import FloatArray, IntArray

DEFAULT_MIN_BLOCKS = 20
DEFAULT_ALPHA = 0.01


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


@quiet
def mean_se(
    series: npt.ArrayLike,
    dt: float = 1.0,
    *,
    alpha: float = DEFAULT_ALPHA,
    min_blocks: int = DEFAULT_MIN_BLOCKS,
) -> Estimate:
    """Mean of a series and its blocking standard error (:func:`blocking` has the correlation
    time, the convergence flag and the rest)."""
    b = blocking(series, dt, alpha=alpha, min_blocks=min_blocks)
    return Estimate(b.mean, b.se)


@quiet
def ratio_se(
    a: npt.ArrayLike,
    b: npt.ArrayLike,
    dt: float = 1.0,
    *,
    min_blocks: int = DEFAULT_MIN_BLOCKS,
) -> Estimate:
    """Ratio of means ``r = <a>/<b>`` with its SE from blocking the linearised series
    ``z_i = (a_i - r b_i) / <b>`` (delta method; keeps the a-b cross-correlation)."""
    aa = np.asarray(a, dtype=np.float64)
    bb = np.asarray(b, dtype=np.float64)
    ok = np.isfinite(aa) & np.isfinite(bb)
    aa, bb = aa[ok], bb[ok]
    mb = float(np.mean(bb)) if len(bb) else 0.0
    if mb == 0.0:
        # the ratio is undefined (e.g. no wall contact yet): say so instead of dividing by 0
        return Estimate(float("nan"), float("nan"))
    r = float(np.mean(aa)) / mb
    z = (aa - r * bb) / mb
    blk = blocking(z, dt, min_blocks=min_blocks)
    return Estimate(r, blk.se)

