"""Binned profiles (the ``bins`` table of docs/columns.md): one matrix per column with a row
per window and a column per bin, its steady start, and the standard error of a whole profile
(per bin, and against averaging time). The windows are the samples of the blocking."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
import polars as pl

from ._numerics import quiet
from .stats import (
    DEFAULT_FRACTIONS,
    DEFAULT_MIN_BLOCKS,
    BlockingArrays,
    SEvsTime,
    SteadyStart,
    blocking_many,
    prefix_lengths,
    prefix_row,
    se_table_result,
    steady_state_start,
)
from .tables import FloatArray, IntArray, TableLike, column, column_names, sample_interval


@dataclass
class BinMatrix:
    """A ``bins`` table pivoted to (window, bin) matrices.

    Attributes
    ----------
    window
        Window indices (sorted), length n_w.
    t_mid, t0, t1
        Window mid/start/end times.
    n_samples
        Samples per window (weights), float.
    bin, x, x_lo, x_hi
        Bin indices and geometry (length n_b).
    data
        Column name -> (n_w, n_b) array (NaN where a (window, bin) row is missing).
    """

    window: IntArray
    t_mid: FloatArray
    t0: FloatArray
    t1: FloatArray
    n_samples: FloatArray
    bin: IntArray
    x: FloatArray
    x_lo: FloatArray
    x_hi: FloatArray
    data: dict[str, FloatArray]

    @property
    def dt(self) -> float:
        """Window length (median), the sample interval of the window series."""
        if self.t1.size and np.all(np.isfinite(self.t1 - self.t0)):
            return float(np.median(self.t1 - self.t0))
        return sample_interval(self.t_mid)

    def select(self, keep: npt.NDArray[np.bool_]) -> BinMatrix:
        """Subset of windows."""
        return BinMatrix(
            self.window[keep],
            self.t_mid[keep],
            self.t0[keep],
            self.t1[keep],
            self.n_samples[keep],
            self.bin,
            self.x,
            self.x_lo,
            self.x_hi,
            {k: v[keep] for k, v in self.data.items()},
        )


@quiet
def bin_matrix(bins: TableLike, columns: Sequence[str] | None = None) -> BinMatrix:
    """Pivot a ``bins`` table (docs/columns.md, channel) into (window, bin) matrices.

    Only ``window`` and ``bin`` are required; ``t0``/``t1``, ``n_samples``, ``x``/``x_lo``/
    ``x_hi`` are used when present.  ``columns`` defaults to every other numeric column.
    """
    names = column_names(bins)
    w_raw = column(bins, "window").astype(np.int64)
    b_raw = column(bins, "bin").astype(np.int64)
    windows, wi = np.unique(w_raw, return_inverse=True)
    bidx, bi = np.unique(b_raw, return_inverse=True)
    nw, nb = windows.size, bidx.size
    meta = {"window", "bin", "t0", "t1", "n_samples", "x", "x_lo", "x_hi"}
    if columns is None:
        columns = [c for c in names if c not in meta]

    def per_window(name: str, default: float) -> FloatArray:
        out = np.full(nw, default)
        if name in names:
            out[wi] = column(bins, name)
        return out

    def per_bin(name: str) -> FloatArray:
        out = np.full(nb, np.nan)
        if name in names:
            out[bi] = column(bins, name)
        return out

    t0 = per_window("t0", np.nan)
    t1 = per_window("t1", np.nan)
    t_mid = 0.5 * (t0 + t1)
    if not np.all(np.isfinite(t_mid)):
        t_mid = windows.astype(np.float64)
    x_lo, x_hi, x = per_bin("x_lo"), per_bin("x_hi"), per_bin("x")
    if not np.all(np.isfinite(x)):
        x = 0.5 * (x_lo + x_hi) if np.all(np.isfinite(x_lo + x_hi)) else bidx.astype(float)
    data: dict[str, FloatArray] = {}
    for c in columns:
        if c not in names:
            continue
        mat = np.full((nw, nb), np.nan)
        mat[wi, bi] = column(bins, c)
        data[c] = mat
    return BinMatrix(
        windows, t_mid, t0, t1, per_window("n_samples", 1.0), bidx, x, x_lo, x_hi, data
    )


@quiet
def window_steady_start(bm: BinMatrix, col: str = "u_y") -> SteadyStart:
    """Steady start of a ``bins`` table from the per-window spatial mean of ``col``
    (default the velocity, whose development is the slowest), by :func:`steady_state_start`
    with batch size 1 (windows are already averages)."""
    key = col if col in bm.data else next(iter(bm.data))
    s = np.nanmean(bm.data[key], axis=1)
    return steady_state_start(bm.t0 if np.all(np.isfinite(bm.t0)) else bm.t_mid, s, batch=1)


@dataclass
class ProfileErrors:
    """Per-bin blocking errors of binned profiles.

    Attributes
    ----------
    table
        One row per bin: bin, x, and for each column c: c, c_se, c_se_err, c_tau, c_converged.
    whole
        Per column: ``rms_se`` (RMS over bins of the SE), ``scale`` (RMS of the mean profile),
        ``rel_error = rms_se / scale`` (the profile-as-a-whole relative error),
        ``frac_converged`` and ``max_rel_se``.
    t_start, n_windows, dt
        Steady start, number of windows used and window length.
    """

    table: pl.DataFrame
    whole: dict[str, dict[str, float]]
    t_start: float
    n_windows: int
    dt: float


def _rms_profile(b: BlockingArrays) -> tuple[float, float, float, float]:
    """Whole-profile numbers: rms SE, its error, profile scale, converged fraction."""
    se, err, mean = b.se, b.se_err, b.mean
    ok = np.isfinite(se)
    if not ok.any():
        return np.nan, np.nan, np.nan, 0.0
    rms = float(np.sqrt(np.mean(se[ok] ** 2)))
    rms_err = float(np.sqrt(np.sum((se[ok] * err[ok]) ** 2)) / (ok.sum() * rms)) if rms else 0.0
    scale = float(np.sqrt(np.nanmean(mean**2)))
    return rms, rms_err, scale, float(np.mean(b.converged))


@quiet
def profile_se(
    bins: TableLike,
    columns: Sequence[str] = ("u_y", "phi", "T"),
    *,
    start_window: int | None = None,
    min_blocks: int = DEFAULT_MIN_BLOCKS,
) -> ProfileErrors:
    """SE per bin of window-averaged profiles (windows are the samples of each bin's series).

    Parameters
    ----------
    bins
        Channel ``bins`` table.
    columns
        Columns to analyse.
    start_window
        Position (0-based, in the sorted window list) of the first steady window; default from
        :func:`window_steady_start`.
    min_blocks
        Convergence requirement of :func:`blocking_many`.
    """
    bm = bin_matrix(bins, columns)
    if start_window is None:
        start_window = window_steady_start(bm).index
    keep = np.arange(bm.window.size) >= start_window
    bm = bm.select(keep)
    out: dict[str, Any] = {"bin": bm.bin, "x": bm.x}
    whole: dict[str, dict[str, float]] = {}
    for c in columns:
        if c not in bm.data:
            continue
        b = blocking_many(bm.data[c], bm.dt, min_blocks=min_blocks)
        out[c] = b.mean
        out[f"{c}_se"] = b.se
        out[f"{c}_se_err"] = b.se_err
        out[f"{c}_tau"] = b.tau
        out[f"{c}_converged"] = b.converged
        rms, rms_err, scale, frac = _rms_profile(b)
        with np.errstate(divide="ignore", invalid="ignore"):
            rel = rms / scale if scale else np.nan
            max_rel = float(np.nanmax(np.abs(b.se / b.mean))) if np.any(b.mean != 0) else np.nan
        whole[c] = {
            "rms_se": rms,
            "rms_se_err": rms_err,
            "scale": scale,
            "rel_error": rel,
            "frac_converged": frac,
            "max_rel_se": max_rel,
        }
    t_start = float(bm.t0[0]) if bm.t0.size else np.nan
    return ProfileErrors(pl.DataFrame(out), whole, t_start, int(bm.window.size), bm.dt)


@quiet
def profile_se_vs_time(
    bins: TableLike,
    col: str = "u_y",
    wall_time_per_unit_t: float | None = None,
    fractions: Sequence[float] = DEFAULT_FRACTIONS,
    *,
    start_window: int | None = None,
    min_blocks: int = DEFAULT_MIN_BLOCKS,
    converged_fraction: float = 0.9,
) -> SEvsTime:
    """Profile-as-a-whole SE (RMS over bins of the per-bin SE of ``col``) vs averaging time.

    Same table and ``C / sqrt(T)`` fit as :func:`se_vs_time`; the ``mean`` column holds the
    profile scale (RMS of the mean profile), so ``se / mean`` is the relative profile error.  A
    prefix counts as converged when at least ``converged_fraction`` of the bins converged.
    """
    bm = bin_matrix(bins, [col])
    if start_window is None:
        start_window = window_steady_start(bm, col).index
    mat = bm.data[col][start_window:]
    dts = bm.dt
    rows: list[dict[str, Any]] = []
    for f, n_f in prefix_lengths(fractions, mat.shape[0]):
        b = blocking_many(mat[:n_f], dts, min_blocks=min_blocks)
        rms, rms_err, scale, frac = _rms_profile(b)
        rows.append(prefix_row(f, n_f, dts, wall_time_per_unit_t, scale, rms, rms_err,
                               float(np.nanmax(b.tau)), frac >= converged_fraction))
    t_start = float(bm.t0[start_window]) if bm.t0.size > start_window else np.nan
    return se_table_result(rows, wall_time_per_unit_t, t_start)
