"""Statistical error of time series, one module per job.

* :mod:`.fp_blocking` — Flyvbjerg-Petersen blocking: the SE of a mean (its conventions and the
  plateau rule are in that module's docstring), of many means at once, of a ratio of means.
* :mod:`.steady` — the end of the start-up transient (MSER) and the trend test.
* :mod:`.stationarity` — the thirds test: is a steady part stationary (no slow drift)?
* :mod:`.shared_mode` — the SE of a mean through a slow mode shared with a reference series.
* :mod:`.se_time` — SE against averaging time and its extrapolation.
* :mod:`.block_jackknife` — the delete-one-block jackknife (no SE from fewer than
  MIN_SE_BLOCKS blocks).
* :mod:`.weighted` — the inverse-variance mean of independent estimates.

Everything here works on *samples* of a time series (one row per sample of a ``series`` table, or
one window of a ``bins`` table) and never on particles. A value with its error is an
:class:`granflow.analysis.estimate.Estimate`.
"""

from .block_jackknife import (
    MIN_SE_BLOCKS,
    block_means,
    choose_blocks,
    jackknife,
    jackknife_se,
)
from .fp_blocking import (
    DEFAULT_ALPHA,
    DEFAULT_MIN_BLOCKS,
    FIT_MIN_BLOCKS,
    FIT_TAUS,
    SECOND_MODE_PENALTY,
    BlockingArrays,
    BlockingResult,
    blocking,
    blocking_many,
    mean_se,
    ratio_se,
)
from .se_time import (
    DEFAULT_FRACTIONS,
    SEvsTime,
    prefix_lengths,
    prefix_row,
    se_table_result,
    se_vs_time,
)
from .shared_mode import REGRESSION_BLOCKS, shared_mode_se
from .stationarity import DRIFT_Z, Stationarity, stationarity
from .steady import SteadyStart, Trend, steady_state_start, trend
from .weighted import weighted_mean

__all__ = [
    "DEFAULT_ALPHA",
    "DEFAULT_FRACTIONS",
    "DEFAULT_MIN_BLOCKS",
    "DRIFT_Z",
    "FIT_MIN_BLOCKS",
    "FIT_TAUS",
    "MIN_SE_BLOCKS",
    "REGRESSION_BLOCKS",
    "SECOND_MODE_PENALTY",
    "BlockingArrays",
    "BlockingResult",
    "SEvsTime",
    "Stationarity",
    "SteadyStart",
    "Trend",
    "block_means",
    "blocking",
    "blocking_many",
    "choose_blocks",
    "jackknife",
    "jackknife_se",
    "mean_se",
    "prefix_lengths",
    "prefix_row",
    "ratio_se",
    "se_table_result",
    "se_vs_time",
    "shared_mode_se",
    "stationarity",
    "steady_state_start",
    "trend",
    "weighted_mean",
]
