"""A value with its standard error: the one type analysis returns for an estimate.

Tables (polars frames, Parquet files) keep the flat convention instead: a column ``x`` and
its standard error ``x_se`` beside it.
"""

from __future__ import annotations

from typing import NamedTuple

__all__ = ["Estimate"]


class Estimate(NamedTuple):
    """A value and its standard error (``nan`` where it has none).

    Attributes
    ----------
    value
        The estimate.
    se
        Its standard error (blocking, jackknife or a fit's, as the function returning it says).
    """

    value: float
    se: float
