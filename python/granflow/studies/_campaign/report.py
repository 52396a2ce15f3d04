"""What the campaigns' reports share: markdown helpers (:func:`md_table`, :func:`pm`, :func:`span`,
:func:`span_of`, :func:`dask_recipe`), the SE-against-averaging-time figure
(:func:`plot_campaign_se`), and the cost of a campaign and of a plan at the measured throughput
(:func:`core_seconds`, :func:`cost`, :func:`paper_scale_estimate`)."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import polars as pl


def md_table(df: pl.DataFrame, fmt: Mapping[str, str] | None = None) -> str:
    """``df`` as a markdown table; floats with ``fmt[column]`` (default .4g), NaN as -."""
    fmt = fmt or {}
    head = "| " + " | ".join(df.columns) + " |"
    sep = "|" + "---|" * len(df.columns)
    body = []
    for r in df.iter_rows(named=True):
        cells = []
        for c in df.columns:
            v = r[c]
            if isinstance(v, float):
                cells.append("-" if not math.isfinite(v) else format(v, fmt.get(c, ".4g")))
            else:
                cells.append(str(v))
        body.append("| " + " | ".join(cells) + " |")
    return "\n".join([head, sep, *body])


def pm(v: float, e: float, digits: int = 3, *, signed: bool = False) -> str:
    """``v ± e`` with ``digits`` decimals (``-`` for NaN; ``v`` alone without an error);
    ``signed``: ``v`` with its sign (a change)."""
    if not math.isfinite(v):
        return "-"
    val = f"{v:+.{digits}f}" if signed else f"{v:.{digits}f}"
    return f"{val} ± {e:.{digits}f}" if math.isfinite(e) else val


def span(lo: float, hi: float, spec: str = ".3g") -> str:
    """The range ``lo``-``hi`` formatted with ``spec``; one value where both format alike."""
    a, b = format(lo, spec), format(hi, spec)
    return a if a == b else f"{a}-{b}"


def span_of(values: pl.Series, spec: str = ".3g") -> str:
    """:func:`span` of ``values``' smallest and largest."""
    return span(float(values.min()), float(values.max()), spec)  # type: ignore[arg-type]


def pm_column(value: str, se: str, name: str, digits: int = 4) -> pl.Expr:
    """The column ``name``: ``value ± se`` as text (:func:`pm`, ``digits`` decimals)."""
    return pl.struct(value, se).map_elements(lambda r: pm(r[value], r[se], digits),
                                             return_dtype=pl.String).alias(name)


def sig(v: float | None, digits: int = 2) -> str:
    """``v`` to ``digits`` significant figures, ``-`` where it is None or NaN (as
    :func:`md_table` writes a float): the scalar form of :func:`sig_text`."""
    return "-" if v is None or not math.isfinite(v) else f"{v:.{digits}g}"


def sig_text(column: str, digits: int = 2) -> pl.Expr:
    """``column`` as text rounded to ``digits`` significant figures, ``-`` where it is NaN or
    null (as :func:`md_table` writes a float): for numbers formatted inside a text cell."""
    v = pl.col(column)
    return (pl.when(v.is_null() | v.is_nan()).then(pl.lit("-"))
            .otherwise(v.round_sig_figs(digits).cast(pl.String)))


def dask_recipe(module: str, out: str, walltime: str, mode: str = "paper") -> list[str]:
    """A report's lines on running a campaign (``--mode``, the paper-scale one by default)
    with Dask (markdown)."""
    return ["Run it with Dask (each point one task, one thread; resumable as here):", "",
            "```bash",
            "# local pool (default), or any Dask scheduler:",
            f"python -m {module} --{mode} --out {out} \\",
            "    --scheduler tcp://scheduler:8786",
            "# on a batch system, a dask-jobqueue cluster gives that address:",
            "python -c 'from dask_jobqueue import SLURMCluster; c = SLURMCluster(cores=32, "
            f"processes=32, memory=\"64GB\", walltime=\"{walltime}\"); c.scale(jobs=4); "
            "print(c.scheduler_address); input()'",
            "```", ""]


#: at most this many points get a line with a legend entry each in plot_campaign_se (more are
#: drawn as grey lines under one entry)
LABELLED_POINTS = 12


def plot_campaign_se(se: pl.DataFrame, path: Path, columns: Sequence[str],
                     by: Sequence[str], *, xlabel: str, relative: bool = False,
                     target: float | None = None,
                     label: Callable[[Mapping[str, Any]], str] | None = None) -> Path:
    """SE of each of ``columns`` against the averaging time ``T_avg`` (a ``se_vs_time``
    table: a row per point, ``by``, and ``fraction`` of its steady part), a line per point,
    with the median's T^-1/2 and, if given, the relative ``target``; ``relative`` plots
    SE/value. ``label`` names a point's line (up to LABELLED_POINTS points)."""
    from matplotlib.figure import Figure

    from granflow.analysis.plots import save_figure

    groups = list(se.group_by(list(by), maintain_order=True))
    labelled = label is not None and len(groups) <= LABELLED_POINTS
    fig = Figure(figsize=(3 * len(columns) + 3, 3.8))
    for k, col in enumerate(columns):
        ax = fig.add_subplot(1, len(columns), k + 1)
        for _, g in groups:
            g = g.sort("T_avg")
            y = g[f"{col}_se"] / g[col] if relative else g[f"{col}_se"]
            if labelled:
                assert label is not None
                ax.plot(g["T_avg"], y, "o-", ms=3, lw=0.8, label=label(g.row(0, named=True)))
            else:
                ax.plot(g["T_avg"], y, "-", color="0.6", lw=0.7)
        t = np.array([se["T_avg"].min(), se["T_avg"].max()], dtype=float)
        full = se.filter(pl.col("fraction") == 1.0)
        s = full[f"{col}_se"] / full[col] if relative else full[f"{col}_se"]
        # (a point's SE may be NaN: too little data for one)
        c = float(np.nanmedian(s.to_numpy() * np.sqrt(full["T_avg"].to_numpy())))
        ax.plot(t, c / np.sqrt(t), "k--", label="median SE ~ T^-1/2")
        if not labelled:
            ax.plot([], [], "-", color="0.6", label="one point (first 1/4, 1/2, all)")
        if target is not None:
            ax.axhline(target, color="r", lw=0.6, label=f"{100 * target:g} % target")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel(xlabel)
        ax.set_ylabel(f"SE({col}) / {col}" if relative else f"SE of {col}")
        ax.legend(fontsize=5 if labelled else 7)
    return save_figure(fig, path, dpi=100)


def core_seconds(points: pl.DataFrame) -> pl.Expr:
    """Each point's core-seconds: its process's CPU time (``cpu_seconds``, all its threads)
    where recorded, else its wall time. A point that shared its core with another process
    (tests, a build, a third run) waited: its wall time overstates what it would take on an
    otherwise idle core, its CPU time does not (on an idle core the two agree to ~1 %)."""
    wall = pl.col("wall_seconds")
    if "cpu_seconds" not in points.columns:
        return wall
    cpu = pl.col("cpu_seconds")
    return pl.when(cpu.is_not_null() & cpu.is_finite() & (cpu > 0)).then(cpu).otherwise(wall)


def run_seconds(points: pl.DataFrame, prep: str | None = None) -> pl.Expr:
    """Each point's core-seconds (:func:`core_seconds`) of its run only when ``prep`` names
    the preparation's (wall) seconds: less the preparation's share of its wall time."""
    cs = core_seconds(points)
    return cs * (1.0 - pl.col(prep).fill_nan(0.0) / pl.col("wall_seconds")) if prep else cs


def cost(points: pl.DataFrame, by: Sequence[str], particles: str, steps: str, *,
         columns: Sequence[pl.Expr] = (), sort: Sequence[str] | None = None,
         prep: str | None = None) -> tuple[pl.DataFrame, float]:
    """Per group of ``by``: points, the further ``columns`` (aggregations), core-hours (one
    core a point, :func:`core_seconds`) and the longest point's wall seconds, sorted by
    ``sort`` (default ``by``); and the throughput in particle-steps (``particles`` x ``steps``
    columns) per core-second, of the runs only when ``prep`` names the preparation's (wall)
    seconds: a point's core-seconds less the preparation's share of its wall time."""
    d = points.with_columns((pl.col(particles) * pl.col(steps)).alias("particle_steps"),
                            core_seconds(points).alias("core_seconds"))
    per = d.group_by(list(by), maintain_order=True).agg(
        pl.len().alias("points"), *columns,
        (pl.col("core_seconds").sum() / 3600).alias("core-hours"),
        pl.col("wall_seconds").max().alias("longest point (s)")).sort(list(sort or by))
    run = d.select(run_seconds(points, prep))[:, 0]
    rate = float(d["particle_steps"].sum()) / float(run.sum())
    return per, rate


def paper_scale_estimate(points: Iterable[Any], particle_steps: Callable[[Any], float],
                         rate: float) -> dict[str, float]:
    """Runs, particle-steps (the sum of ``particle_steps(point)``) and core-hours at ``rate``
    (particle-steps per core-second) of a plan's ``points``."""
    pts = list(points)
    total = sum(particle_steps(p) for p in pts)
    return {"runs": len(pts), "particle-steps": total, "core-hours": total / rate / 3600}
