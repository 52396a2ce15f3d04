"""Statistical error of a run's key steady-state figures against averaging and wall time,
computed from the run's own samples by block averaging.

For every figure the standard error (SE) of its steady-state value is computed from the first
fraction ``f`` of the steady samples (``f`` in 1/32 ... 1, as :func:`stats.se_vs_time`), giving
SE against the simulated averaging time ``T`` and the wall-clock time ``T * w`` spent on it,
where ``w = wall_seconds / (t_end - t_begin)`` is the run's wall time per unit simulated time
(``t_begin``: the start of the sampled run, one sample interval before the first ``series``
sample or the first window's ``t0``; ``t_end``: the last sample).  ``SE = C / sqrt(T)`` is fitted
and extrapolated to the averaging time (and wall time) needed for a requested relative SE.  A
figure is flagged ``too_short`` when the blocking of the full steady part (or of fewer than two
prefixes) did not reach its plateau (:mod:`granflow.analysis.stats`: Flyvbjerg-Petersen
blocking with Jonsson's plateau test; at least 20 plateau blocks required): its SE is then
probably an underestimate and the extrapolation rough.

Figures
-------
``channel`` (paper 000, ``bins`` and ``series`` tables of docs/columns.md):

* ``u_slip``, ``u_max``, ``delta_0.95`` and ``sigma_xx`` as defined by
  :func:`granflow.analysis.channel.summary` (wall-bin and centre velocity of the folded
  half profile, the 0.95 point of the scaled profile, the bin-mean sigma_xx).  Each is a
  function ``F`` of the window-averaged raw profiles; its SE is that of the mean of the
  linearised window series ``z_w = dF(m)[m_w - m]`` (delta method, directional derivative by
  central differences), blocked like any other series, so correlations between windows and
  bins are kept.
* ``phi-profile`` and ``u_y-profile``: the profile as a whole, the RMS over bins of the per-bin
  SE (:func:`binned.profile_se_vs_time`); its ``value`` is the RMS of the mean profile, so
  ``rel_se`` is the relative profile error.

The steady part starts where MSER puts it on ``|vcm_y|`` of the ``series`` table (or on the
per-window mean ``u_y`` without a series), as in
:func:`granflow.analysis.channel_profiles.channel_steady_start`.

``cell`` (paper 002, ``series`` table): ``mu1``, ``mu2``, ``mu3``, ``phi``, ``I``, each blocked
directly; the steady part starts at :func:`granflow.analysis.rheology.cell_steady_start`.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import polars as pl
import pyarrow as pa
import pyarrow.parquet as pq

from . import channel as ch
from . import channel_profiles as cp
from ._numerics import quiet
from .binned import bin_matrix, profile_se_vs_time
from .stats import (
    DEFAULT_FRACTIONS,
    DEFAULT_MIN_BLOCKS,
    SEvsTime,
    blocking,
    prefix_lengths,
    prefix_row,
    se_table_result,
    se_vs_time,
)
from .tables import FloatArray, column, column_names, sample_interval

CHANNEL_FIGURES: tuple[str, ...] = (
    "u_slip",
    "u_max",
    "delta_0.95",
    "sigma_xx",
    "phi-profile",
    "u_y-profile",
)
CELL_FIGURES: tuple[str, ...] = ("mu1", "mu2", "mu3", "phi", "I")

TABLE_SCHEMA = {
    "figure": pl.Utf8,
    "fraction": pl.Float64,
    "n": pl.Int64,
    "averaging_time": pl.Float64,
    "wall_seconds": pl.Float64,
    "value": pl.Float64,
    "se": pl.Float64,
    "se_err": pl.Float64,
    "rel_se": pl.Float64,
    "tau": pl.Float64,
    "converged": pl.Boolean,
}


@dataclass
class ErrorReport:
    """SE of a run's key figures against averaging time and wall time.

    Attributes
    ----------
    scene
        'channel' or 'cell'.
    table
        One row per figure and prefix: figure, fraction, n (samples or windows),
        averaging_time (simulated steady time T), wall_seconds (T times the wall rate),
        value (mean over the prefix; for profiles the RMS profile), se, se_err (uncertainty
        of the SE), rel_se (se / |value|), tau (integrated correlation time; profiles: the
        largest over bins), converged (blocking reached its plateau).
    estimates
        One row per figure: value, se, rel_se, averaging_time and wall_seconds of the whole
        steady part, C (SE sqrt(T)), exponent (fitted slope of log SE vs log T, ~ -1/2),
        target_rel_se, target_se, time_needed (steady averaging time for the target),
        time_more (beyond the present one), wall_needed / wall_more (the same in wall-clock
        seconds), reliable (False when too short), too_short.
    too_short
        Per figure: True when the data are too short for the block analysis to have reached
        its plateau (see the module docstring).
    results
        Per figure: the :class:`stats.SEvsTime` behind the rows.
    wall_seconds, wall_per_time, t_start, t_end
        Wall time of the run, wall seconds per unit simulated time, start of the steady part
        and end of the run.
    """

    scene: str
    table: pl.DataFrame
    estimates: pl.DataFrame
    too_short: dict[str, bool]
    results: dict[str, SEvsTime] = field(repr=False)
    wall_seconds: float
    wall_per_time: float | None
    t_start: float
    t_end: float
    target_rel_se: float | None = None
    notes: list[str] = field(default_factory=list)

    @property
    def any_too_short(self) -> bool:
        """True if any figure's blocking did not reach its plateau."""
        return any(self.too_short.values())

    def to_parquet(
        self,
        path: str | os.PathLike[str],
        params: Mapping[str, Any] | None = None,
        seed: int | None = None,
    ) -> tuple[Path, Path]:
        """Write :attr:`table` to ``path`` and :attr:`estimates` beside it
        (``<stem>_estimates.parquet``) with :func:`granflow.io.write_parquet` (atomic, run
        metadata); the report's own numbers go into the file metadata too."""
        from granflow.io import write_parquet

        p = Path(path)
        meta = {
            **dict(params or {}),
            "error_report": {
                "scene": self.scene,
                "wall_seconds": self.wall_seconds,
                "wall_per_time": self.wall_per_time,
                "t_start": self.t_start,
                "t_end": self.t_end,
                "target_rel_se": self.target_rel_se,
                "too_short": self.too_short,
            },
        }
        a = write_parquet(self.table.to_arrow(), p, params=meta, seed=seed)
        b = write_parquet(
            self.estimates.to_arrow(), p.with_name(p.stem + "_estimates.parquet"), params=meta,
            seed=seed,
        )
        return a, b

    def plot(self, path: str | os.PathLike[str]) -> Path:
        """Relative SE against averaging time (bottom axis) and wall time (top axis) for every
        figure, with the fitted ``C / sqrt(T)`` lines and the target (if any);
        :func:`granflow.analysis.plots.plot_se_vs_time`."""
        from .plots import plot_se_vs_time

        rel: dict[str, SEvsTime] = {}
        for fig, r in self.results.items():
            v = self._value(fig)
            if not (math.isfinite(v) and v != 0.0) or r.table.height == 0:
                continue
            s = abs(v)
            tab = r.table.with_columns(pl.col("se") / s, pl.col("se_err") / s)
            rel[fig] = SEvsTime(tab, r.C / s, r.C_err / s, r.exponent, r.exponent_err,
                                r.wall_time_per_unit_t, r.t_start, r.too_short, r.message)
        return plot_se_vs_time(rel, path, ylabel="relative standard error",
                               target=self.target_rel_se)

    def _value(self, fig: str) -> float:
        row = self.estimates.filter(pl.col("figure") == fig)
        return float(row["value"][0]) if row.height else math.nan

    def text(self) -> str:
        """Plain-text summary for the scenes' printed summaries."""
        w = self.wall_per_time
        head = (
            f"statistical error ({self.scene}, block averaging): steady from t = "
            f"{self.t_start:.4g} to {self.t_end:.4g}"
        )
        if w is not None:
            head += f"; wall {self.wall_seconds:.3g} s ({w:.3g} s per unit time)"
        lines = [head]
        tgt = self.target_rel_se
        hdr = f"  {'figure':<12} {'value':>11} {'SE':>10} {'rel SE':>8} {'T_avg':>9} plateau"
        if tgt is not None:
            hdr += f"  to reach rel SE {tgt:.3g}: T_avg, wall [s]"
        lines.append(hdr)
        for r in self.estimates.iter_rows(named=True):
            line = (
                f"  {r['figure']:<12} {_g(r['value'], '11.5g')} {_g(r['se'], '10.3g')} "
                f"{_g(r['rel_se'], '8.2%')} {_g(r['averaging_time'], '9.4g')} "
                f"{'no' if r['too_short'] else 'yes':>7}"
            )
            if tgt is not None:
                line += f"  {_g(r['time_needed'], '.4g')}, {_g(r['wall_needed'], '.3g')}"
                if not r["reliable"]:
                    line += " (rough)"
            lines.append(line)
        short = [f for f, v in self.too_short.items() if v]
        if short:
            lines.append(
                "  data too short for the block analysis to reach its plateau: "
                + ", ".join(short)
                + " (their SE is probably an underestimate; run longer)"
            )
        lines += [f"  note: {n}" for n in self.notes]
        return "\n".join(lines)


def _g(v: Any, fmt: str) -> str:
    """``format(v, fmt)``, or a right-aligned '-' of the same width for None/NaN."""
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        digits = ""
        for c in fmt:
            if not c.isdigit():
                break
            digits += c
        return "-".rjust(int(digits) if digits else 1)
    return format(v, fmt)


# --------------------------------------------------------------------------------------------
# time bookkeeping
# --------------------------------------------------------------------------------------------
def _time_span(tables: Mapping[str, Any]) -> tuple[float, float]:
    """(t_begin, t_end) of the sampled run (see the module docstring)."""
    begins, ends = [], []
    if "series" in tables and "t" in column_names(tables["series"]):
        t = column(tables["series"], "t")
        if t.size:
            begins.append(float(t[0] - sample_interval(t)) if t.size > 1 else float(t[0]))
            ends.append(float(t[-1]))
    if "bins" in tables:
        names = column_names(tables["bins"])
        if "t0" in names and "t1" in names:
            b = tables["bins"]
            begins.append(float(np.nanmin(column(b, "t0"))))
            ends.append(float(np.nanmax(column(b, "t1"))))
    if not begins:
        raise ValueError("no time column: need series.t or bins.t0/t1")
    return min(begins), max(ends)


# --------------------------------------------------------------------------------------------
# channel
# --------------------------------------------------------------------------------------------
def _channel_scalars(
    prof: cp.ChannelProfiles,
) -> tuple[list[str], Callable[[Mapping[str, FloatArray]], FloatArray]]:
    xi = prof.xi

    def fn(m: Mapping[str, FloatArray]) -> FloatArray:
        q = prof.derived(m)
        return np.array(
            [q["u"][0], q["u"][-1], ch.delta_095_profile(xi, q), float(np.mean(q["sigma_xx"]))]
        )

    return ["u_slip", "u_max", "delta_0.95", "sigma_xx"], fn


@quiet
def _linearised(
    fn: Callable[[Mapping[str, FloatArray]], FloatArray],
    mats: Mapping[str, FloatArray],
    weights: FloatArray,
    eps: float = 1e-3,
) -> tuple[FloatArray, FloatArray]:
    """Value F(mean) and the linearised window series z (n_windows, n_figures) of ``fn``."""
    wsum = float(np.sum(weights))
    mean = {k: np.nansum(v * weights[:, None], axis=0) / wsum for k, v in mats.items()}
    val = np.asarray(fn(mean), dtype=float)
    nw = next(iter(mats.values())).shape[0]
    z = np.full((nw, val.size), np.nan)
    scale = weights / np.mean(weights)
    for w in range(nw):
        dev = {k: v[w] - mean[k] for k, v in mats.items()}
        fp = fn({k: mean[k] + eps * dev[k] for k in mats})
        fm = fn({k: mean[k] - eps * dev[k] for k in mats})
        z[w] = scale[w] * (np.asarray(fp) - np.asarray(fm)) / (2 * eps)
    return val, z


@quiet
def _channel_report(
    tables: Mapping[str, Any],
    wall_per_time: float | None,
    fractions: Sequence[float],
    min_blocks: int,
    start_time: float | None,
) -> tuple[dict[str, SEvsTime], dict[str, float], float, list[str]]:
    if "bins" not in tables:
        raise ValueError("channel error report needs the 'bins' table")
    bins = tables["bins"]
    series = tables.get("series")
    notes: list[str] = []
    raw = [c for c in ("u_y", "sigma_xx") if c in column_names(bins)]
    bm = bin_matrix(bins, raw)
    if "u_y" not in bm.data:
        raise ValueError("bins table needs a u_y column")
    tw = bm.t0 if np.all(np.isfinite(bm.t0)) else bm.t_mid
    if start_time is None:
        ss = cp.channel_steady_start(bm, series)
        start_time = ss.t_start
        if not ss.settled:
            notes.append("steady start at the edge of the MSER search range: the transient "
                         "may not be over")
    keep = tw >= start_time - 1e-9 * max(1.0, abs(start_time))
    if keep.sum() < 2:
        keep = np.ones_like(keep)
    sw = int(np.argmax(keep))
    t_start = float(tw[sw])
    results: dict[str, SEvsTime] = {}
    values: dict[str, float] = {}
    # scalar figures by the delta method on the window series
    prof = cp.profiles(bins, series, start_time=t_start)
    names, fn = _channel_scalars(prof)
    sel = bm.select(keep)
    dts = sel.dt
    nw = sel.window.size
    rows: dict[str, list[dict[str, Any]]] = {k: [] for k in names}
    for f, n_f in prefix_lengths(fractions, nw):
        mats = {k: v[:n_f] for k, v in sel.data.items()}
        val, z = _linearised(fn, mats, sel.n_samples[:n_f])
        for j, k in enumerate(names):
            b = blocking(z[:, j], dts, min_blocks=min_blocks)
            rows[k].append(prefix_row(f, n_f, dts, wall_per_time, float(val[j]), b.se,
                                      b.se_err, b.tau, b.converged))
    for k in names:
        results[k] = se_table_result(rows[k], wall_per_time, t_start)
        values[k] = float(results[k].table["mean"][-1]) if results[k].table.height else math.nan
    # profiles as a whole
    for col, fig in (("phi", "phi-profile"), ("u_y", "u_y-profile")):
        if col not in column_names(bins):
            notes.append(f"no {col} column: {fig} left out")
            continue
        r = profile_se_vs_time(bins, col, wall_per_time, fractions, start_window=sw,
                               min_blocks=min_blocks)
        results[fig] = r
        values[fig] = float(r.table["mean"][-1]) if r.table.height else math.nan
    return results, values, t_start, notes


# --------------------------------------------------------------------------------------------
# cell
# --------------------------------------------------------------------------------------------
@quiet
def _cell_report(
    tables: Mapping[str, Any],
    wall_per_time: float | None,
    fractions: Sequence[float],
    min_blocks: int,
    start_time: float | None,
) -> tuple[dict[str, SEvsTime], dict[str, float], float, list[str]]:
    from .rheology import cell_steady_start, classify_run

    if "series" not in tables:
        raise ValueError("cell error report needs the 'series' table")
    series = tables["series"]
    t = column(series, "t")
    notes: list[str] = []
    if start_time is None:
        ss = cell_steady_start(series)
        start = ss.index
        if not ss.settled:
            notes.append("steady start at the edge of the MSER search range: the transient "
                         "may not be over")
    else:
        start = int(np.searchsorted(t, start_time - 1e-9 * max(1.0, abs(start_time))))
    st = classify_run(series, start=start)
    if not st.averaged:
        notes.append(f"run classified '{st.state}': not a steady state, errors are formal")
    results: dict[str, SEvsTime] = {}
    values: dict[str, float] = {}
    names = column_names(series)
    for fig in CELL_FIGURES:
        if fig not in names:
            notes.append(f"no {fig} column: left out")
            continue
        r = se_vs_time(t, column(series, fig), wall_per_time, fractions, start=start,
                       min_blocks=min_blocks)
        results[fig] = r
        values[fig] = float(r.table["mean"][-1]) if r.table.height else math.nan
    return results, values, float(t[start]) if t.size > start else math.nan, notes


_ReportFn = Callable[..., tuple[dict[str, SEvsTime], dict[str, float], float, list[str]]]

#: The one table of error reports: per scene name (the TOML ``scene``; a scene that has one
#: says so as ``error_report``, analysis does not import the scenes), its figures and the
#: function that computes them.
REPORTS: dict[str, tuple[tuple[str, ...], _ReportFn]] = {
    "channel": (CHANNEL_FIGURES, _channel_report),
    "cell": (CELL_FIGURES, _cell_report),
    "rate_cell": (CELL_FIGURES, _cell_report),  # the cell's series, the cell's report
}
FIGURES: dict[str, tuple[str, ...]] = {name: figs for name, (figs, _) in REPORTS.items()}


# --------------------------------------------------------------------------------------------
# entry points
# --------------------------------------------------------------------------------------------
def error_vs_time(
    scene: str,
    tables: Mapping[str, pa.Table | Any],
    wall_seconds: float,
    target_rel_se: float | None = None,
    *,
    fractions: Sequence[float] = DEFAULT_FRACTIONS,
    min_blocks: int = DEFAULT_MIN_BLOCKS,
    start_time: float | None = None,
) -> ErrorReport:
    """SE of the key steady-state figures of a run against averaging time and wall time.

    Parameters
    ----------
    scene
        'channel' (figures: u_slip, u_max, delta_0.95, sigma_xx, phi-profile, u_y-profile) or
        'cell' (mu1, mu2, mu3, phi, I).
    tables
        The run's tables by name (``scene.tables()`` or the run directory's Parquet files):
        'bins' (and 'series') for the channel, 'series' for the cell; any table type of
        :func:`tables.as_columns`.
    wall_seconds
        Wall-clock time of the run; the wall rate is ``wall_seconds / (t_end - t_begin)``.
    target_rel_se
        Relative SE wanted (e.g. 0.01): the averaging and wall time needed are estimated.
    fractions, min_blocks, start_time
        Prefix fractions, plateau requirement, and an explicit start of the steady part.
    """
    if scene not in FIGURES:
        raise ValueError(f"invalid scene = {scene!r}: allowed one of {sorted(FIGURES)}")
    if target_rel_se is not None and not (math.isfinite(target_rel_se) and target_rel_se > 0):
        raise ValueError(f"invalid target_rel_se = {target_rel_se}: allowed > 0")
    t_begin, t_end = _time_span(tables)
    span = t_end - t_begin
    w = float(wall_seconds) / span if span > 0 and wall_seconds is not None else None
    fn = REPORTS[scene][1]
    results, values, t_start, notes = fn(tables, w, fractions, min_blocks, start_time)
    rows: list[pl.DataFrame] = []
    est: list[dict[str, Any]] = []
    for fig, r in results.items():
        tab = r.table
        if tab.height:
            rows.append(pl.DataFrame({
                "figure": [fig] * tab.height,
                "fraction": tab["fraction"],
                "n": tab["n"],
                "averaging_time": tab["T"],
                "wall_seconds": tab["wall_time"],
                "value": tab["mean"],
                "se": tab["se"],
                "se_err": tab["se_err"],
                "rel_se": (tab["se"] / tab["mean"].abs()),
                "tau": tab["tau"],
                "converged": tab["converged"],
            }, schema=TABLE_SCHEMA))
        v = values.get(fig, math.nan)
        se = float(tab["se"][-1]) if tab.height else math.nan
        T_have = float(tab["T"][-1]) if tab.height else math.nan
        e: dict[str, Any] = {
            "figure": fig,
            "value": v,
            "se": se,
            "rel_se": se / abs(v) if v else math.nan,
            "averaging_time": T_have,
            "wall_seconds": None if w is None else T_have * w,
            "C": r.C,
            "exponent": r.exponent,
            "target_rel_se": target_rel_se,
            "target_se": None,
            "time_needed": None,
            "time_more": None,
            "wall_needed": None,
            "wall_more": None,
            "reliable": not r.too_short,
            "too_short": r.too_short,
        }
        if target_rel_se is not None and math.isfinite(v) and v != 0 and math.isfinite(r.C):
            tse = target_rel_se * abs(v)
            need = r.time_to_reach(tse)
            e.update(target_se=tse, time_needed=need["T"], time_more=need["T_more"],
                     wall_needed=need["wall_time"], wall_more=need["wall_time_more"],
                     reliable=need["reliable"])
        est.append(e)
    table = pl.concat(rows) if rows else pl.DataFrame(schema=TABLE_SCHEMA)
    estimates = pl.from_dicts(est, schema={
        "figure": pl.Utf8, "value": pl.Float64, "se": pl.Float64, "rel_se": pl.Float64,
        "averaging_time": pl.Float64, "wall_seconds": pl.Float64, "C": pl.Float64,
        "exponent": pl.Float64, "target_rel_se": pl.Float64, "target_se": pl.Float64,
        "time_needed": pl.Float64, "time_more": pl.Float64, "wall_needed": pl.Float64,
        "wall_more": pl.Float64, "reliable": pl.Boolean, "too_short": pl.Boolean,
    })
    too_short = {fig: bool(r.too_short) for fig, r in results.items()}
    return ErrorReport(scene, table, estimates, too_short, results, float(wall_seconds), w,
                       t_start, t_end, target_rel_se, notes)


def error_report_for_run(
    directory: str | os.PathLike[str],
    target_rel_se: float | None = None,
    write: bool = True,
    **kwargs: Any,
) -> ErrorReport:
    """:func:`error_vs_time` for a run directory written by :func:`granflow.runner.execute`
    (scene and wall time from ``manifest.json``, tables from ``*.parquet``); with ``write`` the
    report goes beside the results as ``errors.parquet`` / ``errors_estimates.parquet``."""
    d = Path(directory)
    man = json.loads((d / "manifest.json").read_text())
    scene = man["spec"]["scene"]
    skip = {"errors", "errors_estimates"}
    tables = {f.stem: pq.read_table(f) for f in d.glob("*.parquet") if f.stem not in skip}
    rep = error_vs_time(scene, tables, float(man.get("wall_seconds", 0.0)), target_rel_se,
                        **kwargs)
    if write:
        rep.to_parquet(d / "errors.parquet", params=man.get("parameters"), seed=man.get("seed"))
    return rep


__all__ = [
    "CELL_FIGURES",
    "CHANNEL_FIGURES",
    "ErrorReport",
    "error_report_for_run",
    "error_vs_time",
]
