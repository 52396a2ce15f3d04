"""The delete-one-block jackknife over contiguous blocks of samples.

A jackknife SE from ``nb`` blocks has ``nb - 1`` degrees of freedom: from 2 blocks it is one
difference, and the 000 campaign's 2-block SEs came out 200-500x smaller than their
neighbours'. No SE is given from fewer than MIN_SE_BLOCKS blocks (NaN: not enough data).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from .._numerics import quiet
from ..tables import FloatArray

#: fewest blocks an SE may rest on (fewer: NaN, not enough data): the jackknife's blocks and
#: the cell campaign's blocks of 2 tau; 10 blocks give the SE a ~25 % uncertainty of its own
MIN_SE_BLOCKS = 10


def choose_blocks(n: int, g: float = 1.0, max_blocks: int = 32) -> tuple[int, int]:
    """Block length ``L >= ceil(g)`` (g = statistical inefficiency, in samples) and number of
    blocks ``n // L`` (at most ``max_blocks``) for a jackknife over contiguous blocks."""
    g = g if np.isfinite(g) else 1.0
    L = max(1, int(math.ceil(g)), int(math.ceil(n / max_blocks)))
    return L, n // L


@quiet
def jackknife_se(full: Any, replicates: Sequence[Any],
                 min_blocks: int = MIN_SE_BLOCKS) -> Any:
    """Delete-one-block jackknife SE: ``sqrt((nb-1)/nb * sum_i (theta_i - mean theta)^2)``.

    ``full`` is the estimate from all data (returned unchanged by the caller); works for
    scalars and arrays (element-wise, NaN replicates ignored). NaN where fewer than
    ``min_blocks`` (at least 2) replicates are finite: not enough data for an SE.
    """
    need = max(2, int(min_blocks))
    reps = np.asarray([np.asarray(r, dtype=np.float64) for r in replicates])
    if reps.shape[0] < need:
        return np.full(np.shape(full), np.nan) if np.ndim(full) else np.nan
    fin = np.isfinite(reps)
    nb = fin.sum(axis=0).astype(np.float64)
    mean = np.where(fin, reps, 0.0).sum(axis=0) / np.maximum(nb, 1.0)
    ssq = np.where(fin, (reps - mean) ** 2, 0.0).sum(axis=0)
    se = np.sqrt(np.where(nb >= need, (nb - 1.0) / np.maximum(nb, 1.0) * ssq, np.nan))
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
    ``(value, jackknife SE)`` (NaN SE from fewer than MIN_SE_BLOCKS blocks)."""
    value = fn(full_input)
    reps = [fn(loo_inputs[i]) for i in range(loo_inputs.shape[0])]
    return value, jackknife_se(value, reps)
