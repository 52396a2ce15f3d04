"""Reproduce 002 (Srivastava, Silbert, Grest & Lechman): Table 1 and figures 3-8 from granflow's
own cell runs, as resumable pieces, and the report docs/reproduce_002.md.

    python -m granflow.studies.reproduce_002 --quick [--out DIR] [--report FILE]
    python -m granflow.studies.reproduce_002 --full | --paper [--out DIR] [--report FILE]
           [--workers N | --scheduler ADDRESS] [--reanalyse] [--only-report]

A *point* is one cell run, (mu_s, N, p_ext, tau/p, seed), from the compacted start
(:class:`granflow.scenes.cell.ShearCell`), run in stints until its steady part spans a shear
strain of ``min_strain`` and the blocking SEs of mu1 and phi are within ``se_target`` of their
means, that of I within 3x (SE_TARGETS), or ``max_shear_steps`` of shear have run, or it
arrested over ARREST_STINTS stints, or it ran away. Each finished point is appended at once to
``OUT/points.parquet`` (one row: the point, its state, steps, wall seconds, and mean / SE /
correlation time of every observable), and the SE of I, phi, mu1 over the first quarter, half
and all of its steady part to ``OUT/se_vs_time.parquet``: a run that is stopped loses only its
unfinished points, and those go on from their checkpoints under ``OUT/work/`` (not committed).
The report pools the seeds of a point (inverse-variance), fits (4.2), (4.4), (4.6), (4.7) per
mu_s, prints each Table 1 row beside the paper's and draws figures 3-8.
"""

from __future__ import annotations

import json
import math
import os
import time
from collections.abc import Iterable, Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import polars as pl
import pyarrow as pa
import pyarrow.parquet as pq

from granflow.errors import GranflowError

#: observables kept per point (docs/columns.md, cell series)
OBSERVABLES = ("mu1", "mu2", "mu3", "phi", "I", "p", "shear_rate", "beta", "N0_tau", "N1_tau",
               "Z2", "theta_c", "A_xx", "A_xy", "A_yy", "A_zz", "max_overlap")
#: the steady part's fractions at which the SE is recorded (error against run time)
SE_FRACTIONS = (0.25, 0.5, 1.0)
SE_COLUMNS = ("I", "phi", "mu1")


@dataclass(frozen=True)
class Point:
    """One cell run of the campaign."""

    mu_s: float
    tau_ratio: float
    seed: int
    N: int = 2000
    p_ext: float = 1e-4

    @property
    def key(self) -> str:
        return (f"mu{self.mu_s:g}_N{self.N}_p{self.p_ext:g}_tau{self.tau_ratio:g}"
                f"_s{self.seed}")


#: relative SE targets, as multiples of the plan's ``se_target``: mu1 and phi (the issue's
#: 1 %), and I (the fits' abscissa, whose SE is ~10x phi's: 3 %)
SE_TARGETS = {"mu1": 1.0, "phi": 1.0, "I": 3.0}


@dataclass(frozen=True)
class Plan:
    """A campaign: its points, in the order they are run, and when a point is done."""

    name: str
    points: tuple[Point, ...]
    se_target: float = 0.01
    #: steps of shear after which a point stops unconverged, by N
    max_shear_steps: Mapping[int, int] = field(default_factory=lambda: {2000: 1_500_000})
    stint: int = 50_000
    sample_every: int = 200
    #: shear strain (2 |D| T, engineering) the steady part must span: an SE target is easily
    #: met by a short stretch of a slow flow (p = 1e-5 met it after 0.3 of strain, dilating)
    min_strain: float = 2.0
    #: the cell's material beyond (mu_s, N, p_ext, tau/p): ShearCell keywords (e.g. the
    #: channel's size_mix, kt_ratio, e_n, dt_frac in granflow.studies.cross_scene)
    cell_options: Mapping[str, Any] = field(default_factory=dict)
    #: observables kept per point (OBSERVABLES, and rheology.GRADIENT_COLUMNS if wanted)
    observables: tuple[str, ...] = OBSERVABLES

    def max_steps(self, n: int) -> int:
        return int(self.max_shear_steps.get(n, max(self.max_shear_steps.values())))

    def targets(self) -> dict[str, float]:
        """Relative SE each observable must reach (SE_TARGETS x ``se_target``)."""
        return {k: f * self.se_target for k, f in SE_TARGETS.items()}


#: tau/p per mu_s: from just above yield to the largest ratio with steady flow (measured from
#: the compacted start, docs/cell.md), then one ratio above it that records the runaway
RATIOS: dict[float, tuple[float, ...]] = {
    0.0: (0.15, 0.2, 0.25, 0.3, 0.35, 0.4),
    0.01: (0.15, 0.2, 0.25, 0.3, 0.35, 0.4),
    0.1: (0.25, 0.3, 0.35, 0.4, 0.45, 0.5),
    0.3: (0.4, 0.45, 0.5, 0.55, 0.6, 0.65),
}
#: lower pressures at mu_s = 0.3 (one seed)
LOWER_P: dict[float, tuple[float, ...]] = {1e-5: (0.45, 0.5, 0.55), 1e-6: (0.5, 0.55)}
#: ratios added after the first pass: nearer yield at mu_s = 0.3, to pin mu1_0 (run last)
NEAR_YIELD: dict[float, tuple[float, ...]] = {0.3: (0.36, 0.38)}
RUNAWAY: dict[float, float] = {0.0: 0.5, 0.01: 0.5, 0.1: 0.6, 0.3: 0.7}
#: further mu_s, run after the others
MORE_RATIOS: dict[float, tuple[float, ...]] = {
    0.03: (0.15, 0.2, 0.25, 0.3, 0.35, 0.4),
    0.2: (0.35, 0.4, 0.45, 0.5, 0.55, 0.6),
}


def full_plan() -> Plan:
    """mu_s in {0, 0.01, 0.1, 0.3} at N = 2000 (seed 1, then seed 2), a runaway probe per mu_s,
    N = 10,000 at mu_s = 0.3 (the size effect), mu_s in {0.03, 0.2} (two seeds), two ratios
    nearer yield at mu_s = 0.3, then p_ext = 1e-5 and 1e-6 at mu_s = 0.3 (one seed)."""
    pts: list[Point] = []
    for seed in (1, 2):
        pts += [Point(mu, r, seed) for mu, rs in RATIOS.items() for r in rs]
    pts += [Point(mu, r, 1) for mu, r in RUNAWAY.items()]
    pts += [Point(0.3, r, 1, N=10_000) for r in (0.45, 0.5, 0.55, 0.6)]
    for seed in (1, 2):
        pts += [Point(mu, r, seed) for mu, rs in MORE_RATIOS.items() for r in rs]
    for seed in (1, 2):
        pts += [Point(mu, r, seed) for mu, rs in NEAR_YIELD.items() for r in rs]
    # is the offset from 002's curves the pressure? (its fits pool 1e-4, 1e-5, 1e-6)
    pts += [Point(0.3, r, 1, p_ext=p) for p, rs in LOWER_P.items() for r in rs]
    return Plan("full", tuple(pts), max_shear_steps={2000: 4_000_000, 10_000: 400_000})


def ratio_range(mu_s: float, n: int = 8) -> tuple[float, ...]:
    """``n`` ratios from just above yield to the largest steady one at ``mu_s``, interpolated
    between the measured ends of :data:`RATIOS`."""
    mus = sorted(RATIOS)
    lo = float(np.interp(mu_s, mus, [RATIOS[m][0] for m in mus]))
    hi = float(np.interp(mu_s, mus, [RATIOS[m][-1] for m in mus]))
    return tuple(round(float(r), 3) for r in np.linspace(lo, hi, n))


def paper_plan() -> Plan:
    """002's own scale: N = 1e4, p_ext in {1e-4, 1e-5, 1e-6}, Table 1's 14 mu_s, 8 ratios each
    (over the range with steady flow here), 3 realisations."""
    from granflow.analysis.rheology import TABLE1

    pts = tuple(Point(row[0], r, seed, N=10_000, p_ext=p)
                for p in (1e-4, 1e-5, 1e-6) for seed in (1, 2, 3)
                for row in TABLE1 for r in ratio_range(row[0]))
    # (steps per strain grow as p^-1/2: the cap with them)
    return Plan("paper", pts, max_shear_steps={10_000: 4_000_000})


def quick_plan() -> Plan:
    """Minutes on two cores: N = 500, mu_s = 0.3, four ratios, one seed, SE target 2 %."""
    pts = tuple(Point(0.3, r, 1, N=500) for r in (0.45, 0.5, 0.55, 0.6))
    return Plan("quick", pts, se_target=0.02, max_shear_steps={500: 200_000}, stint=25_000)


# --------------------------------------------------------------------------------------------
# one point
# --------------------------------------------------------------------------------------------
def _steady_series(series: pa.Table, t0: float, observables: Iterable[str]) -> pl.DataFrame:
    """The series after ``t0``, with the gradient-frame columns when ``observables`` ask for
    them (rheology.gradient_frame)."""
    from granflow.analysis.rheology import GRADIENT_COLUMNS, gradient_frame
    from granflow.analysis.tables import to_polars

    wanted = set(GRADIENT_COLUMNS) & set(observables)
    s = gradient_frame(series) if wanted else to_polars(series)
    return s.filter(pl.col("t") > t0)


def _analyse(s: pl.DataFrame, observables: Iterable[str] = OBSERVABLES) -> dict[str, Any]:
    from granflow.analysis import rheology as rh

    cols = [c for c in observables if c in s.columns]
    res = rh.analyse_run(s, columns=cols)
    out: dict[str, Any] = {"state": res.state.state, "t_start": res.state.t_start,
                           "T_avg": float(s["t"][-1] - res.state.t_start)}
    for r in res.stats.iter_rows(named=True):
        o = r["observable"]
        out[o], out[f"{o}_se"], out[f"{o}_tau"] = r["mean"], r["se"], r["tau"]
    return out


#: stints of shear before a point may stop as arrested
ARREST_STINTS = 4

def _converged(row: Mapping[str, Any], plan: Plan) -> bool:
    return (row["state"] == "flowing"
            and 2.0 * row.get("shear_rate", 0.0) * row.get("T_avg", 0.0) >= plan.min_strain
            and all(math.isfinite(row.get(f"{k}_se", math.nan))
                    and row[f"{k}_se"] <= t * abs(row[k]) for k, t in plan.targets().items()))


def _se_rows(point: Point, s: pl.DataFrame, t_start: float) -> list[dict[str, Any]]:
    """SE of I, phi, mu1 over the first fractions of the steady part (error against time;
    stats.se_vs_time per observable, each row with its averaging time T)."""
    from granflow.analysis.stats import se_vs_time

    t = s["t"].to_numpy()
    start = int(np.searchsorted(t, t_start))
    rows: dict[float, dict[str, Any]] = {}
    for col in SE_COLUMNS:
        tab = se_vs_time(t, s[col].to_numpy(), fractions=SE_FRACTIONS, start=start).table
        for r in tab.iter_rows(named=True):
            row = rows.setdefault(r["fraction"], {**asdict(point), "fraction": r["fraction"],
                                                  "T_avg": r["T"]})
            row[f"{col}_se"] = r["se"]
    return list(rows.values())


def point_row(point: Point, plan: Plan, series: pa.Table, shear0: float) -> dict[str, Any]:
    """The row of a point from its series (the steady part after the shear switch at
    ``shear0``): state, mean / SE / correlation time of every observable, whether it met the
    plan's SE targets, and its SE rows under ``"se_rows"``."""
    s = _steady_series(series, shear0, plan.observables)
    row: dict[str, Any] = {**asdict(point), "state": "short", "converged": False}
    if s.height >= 200:
        row.update(_analyse(s, plan.observables))
        row["converged"] = _converged(row, plan)
    row["se_rows"] = (_se_rows(point, s, float(row["t_start"])) if row["state"] == "flowing"
                      else [])
    return row


def run_point(point: Point, plan: Plan, work: str, threads: int = 1) -> dict[str, Any]:
    """Run (or go on with) one point in ``work/<key>`` in stints until :func:`point_row` says
    it met the SE targets or arrested (or ``max_shear_steps``); returns its row. A runaway or
    another instability is a row with ``state`` "runaway" or "failed", the error, and phi at the
    switch and at the last sample (the measurement that there is no steady state)."""
    from granflow import io
    from granflow.scenes.cell import ShearCell

    d = Path(work) / point.key
    d.mkdir(parents=True, exist_ok=True)
    ck, tab, meta = d / "checkpoint.gfck", d / "series.parquet", d / "meta.json"
    cell = ShearCell(N=point.N, mu_s=point.mu_s, p_ext=point.p_ext, tau_ratio=point.tau_ratio,
                     seed=point.seed, sample_every=plan.sample_every, threads=threads,
                     **plan.cell_options)
    wall = 0.0
    if ck.exists() and meta.exists():
        cell.restore(ck)
        cell.load_tables({"series": pq.read_table(tab)})
        wall = float(json.loads(meta.read_text())["wall_seconds"])
    t0 = time.perf_counter()
    cell.prepare(progress=False)
    shear0 = float(cell.shear_start_time or 0.0)
    max_steps = plan.max_steps(point.N)

    def shear_steps() -> int:
        return round((cell.core.time - shear0) / cell.core.dt)

    def save() -> None:
        io.write_parquet(cell.tables()["series"], tab)
        cell.save_checkpoint(ck)
        meta.write_text(json.dumps({"wall_seconds": wall + time.perf_counter() - t0}))

    error = None
    row: dict[str, Any] = {}
    try:
        while shear_steps() < max_steps:
            cell.run(min(plan.stint, max_steps - shear_steps()), progress=False)
            save()
            row = point_row(point, plan, cell.tables()["series"], shear0)
            # (arrest is final once it held over 4 stints: a creeping packing can restart)
            if row["converged"] or (row["state"] == "arrested"
                                    and shear_steps() >= ARREST_STINTS * plan.stint):
                break
    except GranflowError as exc:
        error = f"{type(exc).__name__}: {exc}"
    if error is not None or not row:
        row = point_row(point, plan, cell.tables()["series"], shear0)
    if error is not None:
        s = pl.from_arrow(cell.tables()["series"])
        assert isinstance(s, pl.DataFrame)
        before, after = s.filter(pl.col("t") <= shear0), s.filter(pl.col("t") > shear0)
        row.update(state="runaway" if "dilat" in error else "failed", error=error,
                   phi_start=float(before["phi"][-1]) if before.height else math.nan,
                   phi_end=float(after["phi"][-1]) if after.height else math.nan,
                   t_end=float(cell.core.time - shear0), se_rows=[])
    row.update(t_c=cell.t_c, shear_steps=shear_steps(), T_shear=float(cell.core.time - shear0),
               wall_seconds=wall + time.perf_counter() - t0)
    return row


def reanalyse(out: str | os.PathLike[str], plan: Plan) -> int:
    """Recompute the rows of ``out/points.parquet`` (and their SE rows) from the series kept in
    ``out/work`` (after a change of the analysis); a flowing point that no longer meets the
    SE targets, and has steps left, is dropped so that the next run goes on with it from its
    checkpoint. Returns the number of points dropped."""
    from granflow import _core

    from ._campaign import write_rows

    outp = Path(out)
    pts = pl.read_parquet(outp / "points.parquet")
    keep, se_rows, dropped = [], [], 0
    for old in pts.iter_rows(named=True):
        point = Point(old["mu_s"], old["tau_ratio"], old["seed"], old["N"], old["p_ext"])
        d = outp / "work" / point.key
        if not (d / "meta.json").exists() or old["state"] in ("runaway", "failed"):
            keep.append(old)
            continue
        header = _core.read_checkpoint_header(os.fspath(d / "checkpoint.gfck"))[1]
        shear0 = float(json.loads(header)["shear_start_time"])
        row = point_row(point, plan, pq.read_table(d / "series.parquet"), shear0)
        short = (old["shear_steps"] < plan.max_steps(point.N)
                 and (row["state"] != "arrested"
                      or old["shear_steps"] < ARREST_STINTS * plan.stint))
        if short and not row["converged"]:
            dropped += 1
            continue
        se_rows += row.pop("se_rows")
        keep.append({**old, **row})
    write_rows(outp / "points.parquet", keep)
    write_rows(outp / "se_vs_time.parquet", se_rows)
    return dropped


# --------------------------------------------------------------------------------------------
# the campaign
# --------------------------------------------------------------------------------------------
def run_campaign(plan: Plan, out: str | os.PathLike[str], workers: int | None = None,
                 scheduler: str | None = None, log: Any = print) -> pl.DataFrame:
    """Run the points of ``plan`` not yet in ``out/points.parquet``; each finished point is
    appended there as it completes (local process pool by default, or a Dask scheduler)."""
    from ._campaign import fmt, run_points

    def describe(row: dict[str, Any]) -> str:
        return (f"{row.get('state')}, I = {fmt(row, 'I')}, phi = {fmt(row, 'phi', '.4f')}, "
                f"{row['shear_steps']} steps, {row['wall_seconds']:.0f} s")

    return run_points(plan.points, run_point, (plan,), out, tables={"se_rows": "se_vs_time"},
                      workers=workers, scheduler=scheduler, describe=describe, log=log,
                      name=plan.name)


def main(argv: Iterable[str] | None = None) -> None:
    from granflow.studies.reproduce_002_report import write_report

    from ._campaign import cli

    cli(argv, module="granflow.studies.reproduce_002", description=(__doc__ or "").splitlines()[0],
        plans={"quick": (quick_plan, "minutes-long subset (default)"),
               "full": (full_plan, "the Table 1 campaign"),
               "paper": (paper_plan, "002's own scale (a cluster's work: the report's "
                                     "recipe)")},
        reanalyse=reanalyse, run_campaign=run_campaign,
        write_report=lambda out, path, plan: write_report(out, path, plan, paper_plan().points))


if __name__ == "__main__":
    main()
