"""The SE of a mean that shares a slow mode with a reference series.

Why: in the stress-controlled cell the volume (phi) relaxes under the barostat with a slow
mode (hundreds of t_c) that every rate follows: I = |D| a / sqrt(p / rho) is a function of phi
along the flow law, and at the longest blocks I's block means correlate with phi's at -0.9.
In I itself that mode carries a small share of the variance beside fast collisional noise, so
its blocking curve is still rising at the last levels with enough blocks and the curve's fit
misses it; in phi it dominates and the fit sees it (docs: 002's pairs of seeds differed by
-4.8 combined SEs in I and +3.6 in phi at once). Splitting ``x = beta ref + r`` at a block
length long enough for the fast noise to have averaged out (``beta`` by least squares on block
means), the mean of x is ``beta mean(ref) + mean(r)``, and its variance
``beta^2 SE(ref)^2 + SE(r)^2``: the slow share measured where it is clean, the rest by
blocking the residual. (The cross term is dropped: r's block means are uncorrelated with
ref's at the regression's block length by construction.)
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from .._numerics import quiet
from ..tables import FloatArray
from .fp_blocking import blocking_many

#: fewest blocks of the regression of block means (the slope's error ~ 1/sqrt of it)
REGRESSION_BLOCKS = 64


@quiet
def shared_mode_se(x: npt.ArrayLike, ref: npt.ArrayLike, dt: float = 1.0,
                   *, blocks: int = REGRESSION_BLOCKS) -> tuple[FloatArray, FloatArray]:
    """The SE of the mean of every column of ``x`` (samples x series) through the slow mode it
    shares with ``ref`` (module docstring), and the slopes ``beta``; NaN where the series is
    too short for ``blocks`` blocks of at least one sample, or ``ref`` is constant."""
    xx = np.asarray(x, dtype=np.float64)
    if xx.ndim == 1:
        xx = xx[:, None]
    y = np.asarray(ref, dtype=np.float64).ravel()
    n, m = xx.shape
    nan = np.full(m, np.nan)
    if y.size != n:
        raise ValueError("x and ref must have the same number of samples")
    if n < blocks or not (np.isfinite(xx).all() and np.isfinite(y).all()):
        return nan, nan
    b = 1
    while n // (2 * b) >= blocks:
        b *= 2
    k = n // b
    xb = xx[: k * b].reshape(k, b, m).mean(axis=1)
    yb = y[: k * b].reshape(k, b).mean(axis=1)
    yc = yb - yb.mean()
    ss = float(yc @ yc)
    if ss <= 0.0:
        return nan, nan
    beta = (yc[:, None] * (xb - xb.mean(axis=0))).sum(axis=0) / ss
    resid = xx - np.outer(y, beta)
    se_r = blocking_many(resid, dt).se
    se_ref = float(blocking_many(y[:, None], dt).se[0])
    return np.sqrt(beta**2 * se_ref**2 + se_r**2), beta
