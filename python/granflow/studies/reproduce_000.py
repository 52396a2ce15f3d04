"""Reproduce 000 (Debnath, Kesava Rao & Kumaran 2022): the vertical channel across widths W and
mean volume fractions phi_bar, and the stiffness test of its fig. 10, as resumable pieces, and
the report docs/reproduce_000.md.

    python -m granflow.studies.reproduce_000 --quick [--out DIR] [--report FILE]
    python -m granflow.studies.reproduce_000 --full | --paper [--out DIR] [--report FILE]
           [--workers N | --scheduler ADDRESS] [--reanalyse] [--only-report]

A *point* is one channel run, (W, phi_bar, k_n, seed) at depth B and periodic height H,
prepared by fill and release (:class:`granflow.scenes.channel.Channel`) and run in stints of
``stint`` time units. It stops when

* it is **steady**: the flow state of the last half of its centre-of-mass velocity is steady
  or fluctuating (:func:`granflow.analysis.channel_profiles.flow_state`), the steady part (from
  MSER on |vcm_y|) spans at least ``min_average`` time units, and the jackknife SEs of u_slip
  and u_max are within ``se_target`` of their values; or
* it is **arrested** (|vcm_y| < 1e-3 sqrt(g d) over the last half) at two stints running; or
* it reached ``t_max`` (its last state is recorded: accelerating, decelerating, ...).

The stiffness points (fig. 10) are *branches*: the state of a finished k_n = 1e5 point, run on
at k_n = 1e6 and 1e7 (dt = 1.2e-4 sqrt(1e6/k_n), ~t_c/11, as 000 §2 at 1e6) until steady by
the same rule; the developing flow, common to all three, is not paid for again (the branch
forgets the k_n = 1e5 contact springs; the MSER start drops the transient).

Each finished point is appended at once to ``OUT/points.parquet`` (one row: the point, its
state, times, preparation seconds, wall seconds, and every section 3 number with its SE), its
half profile to ``OUT/profiles.parquet``, its zone means (fig. 10) to ``OUT/zones.parquet``
and the SEs of u_slip and u_max over the first quarter, half and all of its steady part to
``OUT/se_vs_time.parquet``; unfinished points go on from their checkpoints under
``OUT/work/`` (not committed).
"""

from __future__ import annotations

import json
import math
import os
import time
from collections.abc import Iterable
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import polars as pl
import pyarrow as pa
import pyarrow.parquet as pq

from granflow.analysis.estimate import Estimate
from granflow.errors import GranflowError

#: the steady part's fractions at which the SE is recorded (error against run time)
SE_FRACTIONS = (0.25, 0.5, 1.0)
#: the section 3.1 numbers kept per point (granflow.analysis.channel.velocity_scaling)
SCALING = ("u_slip", "u_max", "u_max_over_u_slip", "delta_095", "residual_31", "delta_fit",
           "u_slip_fit", "u_max_fit", "residual_fit", "mean_velocity", "mean_velocity_32",
           "mean_velocity_ratio")
#: the half-profile columns kept per point (figs 4, 6-9; channel_profiles.ChannelProfiles)
PROFILE = ("xi", "xi_lo", "xi_hi", "u", "gamma_dot", "phi", "T", "sigma_xx", "sigma_xy", "w_z",
           "mu", "I", "omega_ratio", "production", "Gamma", "gamma_over_sqrtT", "p_phi",
           "mu_phi", "D_phi")
#: sample interval in time units (~100 steps at k_n = 1e5) and samples per window
SAMPLE_DT = 0.04
WINDOW = 50


@dataclass(frozen=True)
class Point:
    """One channel run of the campaign; ``parent`` (a key) for a branch (see the module
    docstring)."""

    W: float
    phi_bar: float
    seed: int = 1
    kn: float = 1e5
    B: float = 10.0
    H: float = 20.0
    parent: str = ""

    @property
    def key(self) -> str:
        return (f"W{self.W:g}_phi{self.phi_bar:g}_kn{self.kn:g}_B{self.B:g}_H{self.H:g}"
                f"_s{self.seed}")

    @property
    def dt(self) -> float:
        """1.2e-4 sqrt(1e6/k_n): 000's step at k_n = 1e6 (~t_c/11), scaled with t_c."""
        return 1.2e-4 * math.sqrt(1e6 / self.kn)

    def channel(self, threads: int | None = 1) -> Any:
        from granflow.scenes.channel import Channel

        return Channel(W=self.W, H=self.H, B=self.B, phi_bar=self.phi_bar, kn=self.kn,
                       dt=self.dt, seed=self.seed, threads=threads,
                       sample_every=max(1, round(SAMPLE_DT / self.dt)), window=WINDOW)


@dataclass(frozen=True)
class Plan:
    """A campaign: its points, then its branches, then its later points (the order they are
    run in), and when a point is done."""

    name: str
    points: tuple[Point, ...]
    branches: tuple[Point, ...] = ()
    #: points run after the branches (the widest channels)
    later: tuple[Point, ...] = ()
    #: relative SE of u_slip and u_max to reach
    se_target: float = 0.01
    #: time units per stint, and at most per point
    stint: float = 50.0
    t_max: float = 1500.0
    #: steady averaging time a point needs at least (000 averages 600)
    min_average: float = 200.0
    #: branches: the same, counted from the branch
    branch_t_max: float = 250.0
    branch_min_average: float = 100.0

    def limits(self, point: Point) -> tuple[float, float]:
        """(t_max, min_average) of ``point``."""
        if point.parent:
            return self.branch_t_max, self.branch_min_average
        return self.t_max, self.min_average


WIDTHS = (20.0, 40.0, 60.0)
PHIS = (0.59, 0.60, 0.61)
#: the stiffness test (fig. 10): branches of this (W, phi_bar) at these k_n
STIFF_AT = (20.0, 0.59)
STIFF_KN = (1e6, 1e7)


def _branches(parent: Point, kns: Iterable[float]) -> tuple[Point, ...]:
    return tuple(replace(parent, kn=k, parent=parent.key) for k in kns)


def full_plan() -> Plan:
    """W = 20, 40, 60 x phi_bar = 0.59, 0.60, 0.61 at B = 10, H = 20, k_n = 1e5; the
    stiffness branches at W = 20, phi_bar = 0.59 (k_n = 1e7 costs 10x the steps); then
    W = 100 at the three phi_bar."""
    pts = tuple(Point(w, p) for w in WIDTHS for p in PHIS)
    return Plan("full", pts, _branches(Point(*STIFF_AT), STIFF_KN),
                later=tuple(Point(100.0, p) for p in PHIS))


def paper_plan() -> Plan:
    """000's own scale: W = 60, 80, 100, 125, 150 x phi_bar = 0.59-0.62 at B = 40, H = 60,
    k_n = 1e6, to t = 2600 (steady after 2000, 600 averaged), 3 seeds."""
    pts = tuple(Point(w, p, seed=s, kn=1e6, B=40.0, H=60.0)
                for s in (1, 2, 3) for w in (60.0, 80.0, 100.0, 125.0, 150.0)
                for p in (0.59, 0.60, 0.61, 0.62))
    return Plan("paper", pts, t_max=2600.0, min_average=600.0)


def quick_plan() -> Plan:
    """Minutes on two cores: W = 12 at phi_bar = 0.58 and 0.59, B = 5, H = 8, a short average
    at 3 % SE, and one k_n = 1e6 branch."""
    pts = (Point(12.0, 0.58, B=5.0, H=8.0), Point(12.0, 0.59, B=5.0, H=8.0))
    return Plan("quick", pts, _branches(pts[0], (1e6,)), se_target=0.03, stint=25.0,
                t_max=150.0, min_average=40.0, branch_t_max=60.0, branch_min_average=20.0)


# --------------------------------------------------------------------------------------------
# one point
# --------------------------------------------------------------------------------------------
def _est(e: Estimate) -> tuple[float, float]:
    """(value, SE) of a summary entry."""
    return float(e.value), float(e.se)


def _se_rows(point: Point, bins: pa.Table, t_start: float, t_end: float) -> list[dict[str, Any]]:
    """SE of u_slip and u_max from the first fractions of the steady part (error against
    averaging time): the profiles of the windows ending by t_start + f (t_end - t_start)."""
    from granflow.analysis.channel_profiles import profiles

    t1 = np.asarray(bins.column("t1").to_numpy(), dtype=float)
    rows = []
    for f in SE_FRACTIONS:
        cut = t_start + f * (t_end - t_start)
        part = bins.filter(pa.array(t1 <= cut + 1e-9))
        try:
            prof = profiles(part, start_time=t_start)
        except ValueError:  # fewer than two windows in the part
            continue
        (us, um), (us_se, um_se) = prof.estimate(
            lambda q: np.array([q["u"][0], q["u"][-1]]))
        rows.append({**asdict(point), "fraction": f, "T_avg": cut - t_start,
                     "u_slip": float(us), "u_slip_se": float(us_se), "u_max": float(um),
                     "u_max_se": float(um_se), "n_blocks": prof.n_blocks})
    return rows


def point_row(point: Point, plan: Plan, bins: pa.Table, series: pa.Table) -> dict[str, Any]:
    """The row of a point from its tables: state, steady start and averaging time, the
    section 3 numbers with SEs, whether it met the plan's criterion; its half profile, zone
    means and SE rows under ``"profile_rows"``, ``"zone_rows"``, ``"se_rows"``."""
    from granflow.analysis import channel as ach
    from granflow.analysis.channel_profiles import flow_state, profiles

    row: dict[str, Any] = {**asdict(point), "state": "short", "converged": False,
                           "profile_rows": [], "zone_rows": [], "se_rows": []}
    t = np.asarray(series.column("t").to_numpy(), dtype=float)
    if t.size < 100:
        return row
    fs = flow_state(series)
    row.update(state=fs.state, t_end=float(t[-1]), vcm_tail=fs.v_mean,
               rel_amplitude=fs.rel_amplitude, rel_drift=fs.rel_drift)
    if not fs.is_steady:
        return row
    prof = profiles(bins, series)
    s = ach.summary(bins, series, start_time=prof.t_start)
    row.update(t_start=prof.t_start, T_avg=float(t[-1] - prof.t_start),
               n_blocks=prof.n_blocks)
    for k in (*SCALING, "wall_friction", "sigma_xx_mean", "vcm", "omega_ratio_shearing"):
        row[k], row[f"{k}_se"] = _est(s[k])
    zn = s["zones"]
    row["xi_ad"], row["xi_ad_se"] = _est(zn["xi_ad"])
    row["phi_plug"], row["phi_plug_se"] = _est(zn["phi_plug"])
    row["xi_plug"], row["xi_wall"] = zn["xi_plug"], zn["xi_wall"]
    cond = s["conduction"]
    row["l_c"], row["l_c_se"] = _est(cond["l_c"])
    row["l_c_bins"], row["l_c_at_bound"] = cond["n_bins"], cond["at_bound"]
    row["sigma_xx_rel_spread"] = s["sigma_xx_rel_spread"]
    prof_tab = s["profile"].select([*PROFILE, *(f"{c}_se" for c in PROFILE[3:]), "zone"])
    row["profile_rows"] = [{**asdict(point), **r} for r in prof_tab.iter_rows(named=True)]
    zones = ach.zones(prof)
    for zone, est in ach.zone_means(prof, zones).items():
        z: dict[str, Any] = {**asdict(point), "zone": zone,
                             "n_bins": zones.labels.count(zone)}
        for k, e in est.items():
            z[k], z[f"{k}_se"] = e.value, e.se
        row["zone_rows"].append(z)
    row["se_rows"] = _se_rows(point, bins, prof.t_start, float(t[-1]))
    t_max, min_average = plan.limits(point)
    row["converged"] = bool(
        row["T_avg"] >= min_average
        and all(math.isfinite(row[f"{k}_se"]) and row[f"{k}_se"] <= plan.se_target * abs(row[k])
                for k in ("u_slip", "u_max")))
    return row


def _tables(ch: Any) -> tuple[pa.Table, pa.Table]:
    t = ch.tables()
    return t["bins"], t["series"]


def run_point(point: Point, plan: Plan, work: str, threads: int = 1) -> dict[str, Any]:
    """Run (or go on with) one point in ``work/<key>`` in stints until :func:`point_row`
    says it is steady and converged, or arrested for two stints, or ``t_max``; returns its
    row (with ``prep_seconds``, the preparation's wall time, and ``wall_seconds``, all of
    it). An instability is a row with ``state`` "failed" and the error."""
    from granflow import io

    d = Path(work) / point.key
    d.mkdir(parents=True, exist_ok=True)
    ck, meta = d / "checkpoint.gfck", d / "meta.json"
    fb, fs = d / "bins.parquet", d / "series.parquet"
    ch = point.channel(threads)
    info: dict[str, Any] = {"wall_seconds": 0.0, "prep_seconds": math.nan}
    if ck.exists() and meta.exists():
        ch.restore(ck)
        ch.load_tables({"bins": pq.read_table(fb), "series": pq.read_table(fs)})
        info = json.loads(meta.read_text())
    t0 = time.perf_counter()
    if ch.sim is None:
        if point.parent:
            ch.branch_from(Path(work) / point.parent / "checkpoint.gfck")
        else:
            ch.prepare(progress=False)
        info["prep_seconds"] = time.perf_counter() - t0
    t_max, _ = plan.limits(point)
    steps = max(1, round(plan.stint / point.dt))

    def save() -> None:
        b, s = _tables(ch)
        io.write_parquet(b, fb)
        io.write_parquet(s, fs)
        ch.save_checkpoint(ck)
        meta.write_text(json.dumps({**info, "wall_seconds": info["wall_seconds"]
                                    + time.perf_counter() - t0}))

    error = None
    row: dict[str, Any] = {}
    arrested = 0
    try:
        while ch.core.time < t_max - 1e-9:
            ch.run(min(steps, max(1, round((t_max - ch.core.time) / point.dt))), progress=False)
            save()
            row = point_row(point, plan, *_tables(ch))
            arrested = arrested + 1 if row["state"] == "arrested" else 0
            if row["converged"] or arrested >= 2:
                break
    except GranflowError as exc:
        error = f"{type(exc).__name__}: {exc}"
    if not row:
        row = point_row(point, plan, *_tables(ch))
    if error is not None:
        row.update(state="failed", error=error, converged=False)
    row.update(n=ch.prep_info.get("n"), phi_bar_achieved=ch.prep_info.get("phi_bar_achieved"),
               settle_time=ch.prep_info.get("settle_time"), t_run=float(ch.core.time),
               steps=int(ch.core.step), prep_seconds=info["prep_seconds"],
               wall_seconds=info["wall_seconds"] + time.perf_counter() - t0)
    return row


ROW_TABLES = {"profile_rows": "profiles", "zone_rows": "zones", "se_rows": "se_vs_time"}


def reanalyse(out: str | os.PathLike[str], plan: Plan) -> int:
    """Recompute the rows of ``out/points.parquet`` (and its other tables) from the tables
    kept in ``out/work`` (after a change of the analysis); a point that no longer meets the
    criterion, and has time left, is dropped so that the next run goes on with it from its
    checkpoint. Returns the number of points dropped."""
    from ._campaign import point_of, write_rows

    outp = Path(out)
    pts = pl.read_parquet(outp / "points.parquet")
    keep: list[dict[str, Any]] = []
    extra: dict[str, list[dict[str, Any]]] = {k: [] for k in ROW_TABLES}
    dropped = 0
    for old in pts.iter_rows(named=True):
        point = point_of(Point, old)
        d = outp / "work" / point.key
        if not (d / "bins.parquet").exists() or old["state"] == "failed":
            keep.append(old)
            continue
        row = point_row(point, plan, pq.read_table(d / "bins.parquet"),
                        pq.read_table(d / "series.parquet"))
        if (not row["converged"] and row["state"] != "arrested"
                and old["t_run"] < plan.limits(point)[0] - 1e-6):
            dropped += 1
            continue
        for k in ROW_TABLES:
            extra[k] += row.pop(k)
        keep.append({**old, **row})
    write_rows(outp / "points.parquet", keep)
    for k, stem in ROW_TABLES.items():
        write_rows(outp / f"{stem}.parquet", extra[k])
    return dropped


# --------------------------------------------------------------------------------------------
# the campaign
# --------------------------------------------------------------------------------------------
def _describe(row: dict[str, Any]) -> str:
    from ._campaign import fmt

    return (f"{row.get('state')}{'' if row.get('converged') else ' (not converged)'}, "
            f"u_slip = {fmt(row, 'u_slip')}, u_max/u_slip = {fmt(row, 'u_max_over_u_slip')}, "
            f"t = {fmt(row, 't_run', '.0f')}, prep {fmt(row, 'prep_seconds', '.1f')} s, "
            f"{fmt(row, 'wall_seconds', '.0f')} s")


def run_campaign(plan: Plan, out: str | os.PathLike[str], workers: int | None = None,
                 scheduler: str | None = None, log: Any = print) -> pl.DataFrame:
    """Run the points of ``plan`` not yet in ``out/points.parquet`` (with the branches whose
    parents are done, first), then the other branches (their parents are done by then), then
    its later points; each finished point is appended there as it completes."""
    from ._campaign import done_keys, run_points

    kw: dict[str, Any] = {"tables": ROW_TABLES, "workers": workers, "scheduler": scheduler,
                          "describe": _describe, "log": log}
    done = done_keys(Path(out), Point)
    ready = tuple(b for b in plan.branches if b.parent in done)
    run_points((*ready, *plan.points), run_point, (plan,), out, name=plan.name, **kw)
    waiting = tuple(b for b in plan.branches if b not in ready)
    run_points(waiting, run_point, (plan,), out, name=f"{plan.name} branches", **kw)
    return run_points(plan.later, run_point, (plan,), out, name=f"{plan.name} later", **kw)


def main(argv: Iterable[str] | None = None) -> None:
    from granflow.studies.reproduce_000_report import write_report

    from ._campaign import cli

    cli(argv, module="granflow.studies.reproduce_000", description=(__doc__ or "").splitlines()[0],
        plans={"quick": (quick_plan, "minutes-long subset (default)"),
               "full": (full_plan, "the width and phi_bar campaign"),
               "paper": (paper_plan, "000's own scale (a cluster's work: the report's "
                                     "recipe)")},
        reanalyse=reanalyse, run_campaign=run_campaign,
        write_report=lambda out, path, plan: write_report(out, path, plan, paper_plan()))


if __name__ == "__main__":
    main()
