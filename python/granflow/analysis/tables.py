"""Column access for analysis: any table (pyarrow, polars, a mapping of arrays, pandas-like)
as float arrays or a polars frame, and the array types the analysis modules share."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt
import polars as pl

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
#: Anything :func:`as_columns` understands: ``pyarrow.Table`` / ``RecordBatch``,
#: ``polars.DataFrame``, a mapping of column name -> 1-D array, or a pandas-like frame.
TableLike = Any


def column_names(data: TableLike) -> list[str]:
    """Column names of a pyarrow table, polars frame, mapping or pandas-like frame."""
    if hasattr(data, "column_names"):  # pyarrow Table / RecordBatch
        return list(data.column_names)
    if isinstance(data, pl.DataFrame):
        return list(data.columns)
    if isinstance(data, Mapping):
        return [str(k) for k in data.keys()]
    if hasattr(data, "columns"):
        return [str(c) for c in data.columns]
    raise TypeError(f"unsupported table type {type(data)!r}")


def column(data: TableLike, name: str) -> FloatArray:
    """One column as a float64 numpy array (nulls become NaN)."""
    if hasattr(data, "column_names"):
        arr = data.column(name).to_numpy()
    elif isinstance(data, pl.DataFrame):
        arr = data.get_column(name).to_numpy()
    elif isinstance(data, Mapping):
        arr = data[name]
    elif hasattr(data, "columns"):
        arr = data[name]
    else:
        raise TypeError(f"unsupported table type {type(data)!r}")
    return np.asarray(arr, dtype=np.float64)


def as_columns(data: TableLike, columns: Sequence[str] | None = None) -> dict[str, FloatArray]:
    """Convert a table (pyarrow / polars / dict of arrays / pandas-like) to a dict of float arrays.

    Parameters
    ----------
    data
        The table.
    columns
        Columns to extract (default: all).
    """
    names = list(columns) if columns is not None else column_names(data)
    return {c: column(data, c) for c in names}


def to_polars(data: TableLike) -> pl.DataFrame:
    """Any supported table as a polars DataFrame (keeps text columns, unlike :func:`as_columns`)."""
    if isinstance(data, pl.DataFrame):
        return data
    if hasattr(data, "column_names"):
        out = pl.from_arrow(data)
        return out if isinstance(out, pl.DataFrame) else out.to_frame()
    if isinstance(data, Mapping):
        return pl.DataFrame({str(k): np.asarray(v) for k, v in data.items()})
    return pl.from_pandas(data)


def sample_interval(t: npt.ArrayLike) -> float:
    """Median spacing of a sample-time array (1.0 if fewer than two samples)."""
    tt = np.asarray(t, dtype=np.float64)
    if tt.size < 2:
        return 1.0
    return float(np.median(np.diff(tt)))
