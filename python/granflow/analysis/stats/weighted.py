"""The inverse-variance weighted mean of independent estimates, each with its SE."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike


def weighted_mean(values: ArrayLike, ses: ArrayLike) -> tuple[float, float]:
    """(mean, SE) of independent ``values`` with standard errors ``ses``, weighted by
    1/SE^2: the mean is sum(x/se^2)/sum(1/se^2) and its SE sum(1/se^2)^-1/2. Every SE must
    be finite and positive (the caller drops the others)."""
    x = np.asarray(values, dtype=np.float64)
    w = 1.0 / np.asarray(ses, dtype=np.float64) ** 2
    return float(np.sum(w * x) / np.sum(w)), float(np.sum(w) ** -0.5)
