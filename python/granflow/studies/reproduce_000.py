"""Reproduce 000 (Debnath, Kesava Rao & Kumaran 2022): the vertical channel across widths W and
mean volume fractions phi_bar, and the stiffness test of its fig. 10, as resumable pieces, and
the report docs/reproduce_000.md.

    python -m granflow.studies.reproduce_000 --quick [--out DIR] [--report FILE]
    python -m granflow.studies.reproduce_000 --full | --widths | --paper [--out DIR]
           [--report FILE] [--workers N [--threads T] | --scheduler ADDRESS] [--reanalyse]
           [--only-report]

A *point* is one channel run, (W, phi_bar, k_n, seed) at depth B and periodic height H,
prepared by fill and release (:class:`granflow.scenes.channel.Channel`, ``preparation =
Point.prep``: "pour", the soft pour the committed full dataset was made with, or 000's "rain",
the widths plan's) and run in stints of ``stint`` time units. It stops when

* it is **steady** and long enough (:func:`long_enough`), and only then are the SE targets
  consulted (:func:`converged`): the flow state of the last half of its centre-of-mass velocity
  is steady or fluctuating (:func:`granflow.analysis.channel_profiles.flow_state`); its steady
  part (from MSER on |vcm_y|) is stationary (the thirds test of u_slip, u_max, the mean velocity
  and the mean sigma_xx per window, :func:`granflow.analysis.channel.steady_check`: a drifting
  run is ``drifting`` and goes on), spans at least ``min_average`` time units and ``min_taus``
  integrated correlation times of the slowest of those quantities; then the jackknife SEs of
  u_slip and u_max must be within ``se_target`` of their values (an SE from fewer than
  MIN_SE_BLOCKS blocks is NaN and meets no target). The minimum length keeps a run from
  stopping because its SE estimate happened to dip (optional stopping biases every SE small).
  A plan may give a development time ``t_dev`` (000 §2: 2000): the steady part then starts at
  it (not at MSER's start), and nothing is averaged before ``t_dev + min_average``. The widths
  and paper plans run 000's protocol, 2000 + 600 (the paper plan's ``t_max`` = 2600: every
  run that flows is that long; the widths plan's goes on where 600 holds fewer than
  ``min_taus`` correlation times); or
* it is **arrested** (|vcm_y| < 1e-3 sqrt(g d) over the last half) at two stints running; or
* it reached ``t_max`` (its last state is recorded: accelerating, decelerating, drifting, ...).

Every point of the full and paper plans runs with REPLICAS independent seeds; the report's
value of a point is their mean (:func:`granflow.analysis.replicas.replica_mean`).

The stiffness points (fig. 10) are *branches*: the state of a finished k_n = 1e5 point, run on
at k_n = 1e6 and 1e7 (dt = 1.2e-4 sqrt(1e6/k_n), ~t_c/11, as 000 §2 at 1e6) until steady by
the same rule; the developing flow, common to all three, is not paid for again (the branch
forgets the k_n = 1e5 contact springs; the MSER start drops the transient).

Each finished point is appended at once to ``OUT/points.parquet`` (one row: the point, its
state, times, preparation seconds, wall seconds, and every section 3 number with its SE), its
half profile to ``OUT/profiles.parquet``, its zone means (fig. 10) to ``OUT/zones.parquet``
and the SEs of u_slip and u_max over the first quarter, half and all of its steady part to
``OUT/se_vs_time.parquet``; unfinished points go on from their checkpoints under
``OUT/work/`` (not committed), or on another machine from the copy of them in
``OUT/progress/`` (committed with the dataset; the stiffness parents' final states stay
there until their branches are done).
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import polars as pl
import pyarrow as pa
import pyarrow.compute as pc

from granflow.analysis.estimate import Estimate
from granflow.material import MATERIAL_000
from granflow.states import FlowState

from ._campaign import Study, add_final_rows, done_keys, fmt, run_points
from ._campaign import reanalyse as engine_reanalyse

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
#: independent seeds of every point of the full and paper plans, and those seeds
REPLICAS = 3
SEEDS = tuple(range(1, REPLICAS + 1))
#: sample interval in time units (~100 steps at k_n = 1e5) and samples per window
SAMPLE_DT = 0.04
WINDOW = 50
#: a run's last sample comes up to a sample interval (SAMPLE_DT) before the time it ran to:
#: its length is compared with the plan's to within this (time units, under a window)
TIME_TOL = 0.5


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
    #: the channel's preparation: "pour" (the committed full and paper plans) or 000's "rain"
    prep: str = "pour"

    @property
    def key(self) -> str:
        return (f"W{self.W:g}_phi{self.phi_bar:g}_kn{self.kn:g}_B{self.B:g}_H{self.H:g}"
                f"{'' if self.prep == 'pour' else '_' + self.prep}_s{self.seed}")

    @property
    def dt(self) -> float:
        """000's step at this k_n (the material's rule: 1.2e-4 at k_n = 1e6, ~t_c/11, scaled
        with t_c)."""
        dt = MATERIAL_000.with_(kn=self.kn).dt()
        assert dt is not None
        return dt


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
    #: development time: the steady part starts there (000 §2: 2000 of development before
    #: its 600 of averaging; 0: at MSER's start). A flow still developing when MSER starts
    #: its steady part creeps through it (the W = 20 rain runs from t ~ 600: +4 % per 1000
    #: time units, benchmarks/NOTES.md "the W = 20 channel develops until t ~ 1800"), which
    #: the thirds test is too weak to see.
    t_dev: float = 0.0
    #: integrated correlation times of the slowest of granflow.analysis.channel's
    #: STEADY_QUANTITIES the steady part must span before the SE targets are consulted (~10
    #: jackknife blocks of 2 tau)
    min_taus: float = 20.0
    #: branches: the same, counted from the branch
    branch_t_max: float = 250.0
    branch_min_average: float = 100.0
    #: the campaign that carries this one's question on (its report names it), "" if none
    superseded_by: str = ""

    def limits(self, point: Point) -> tuple[float, float]:
        """(t_max, min_average) of ``point``."""
        if point.parent:
            return self.branch_t_max, self.branch_min_average
        return self.t_max, self.min_average

    def t_dev_of(self, point: Point) -> float:
        """The development time of ``point`` (branches: none, their parent developed)."""
        return 0.0 if point.parent else self.t_dev

    def t_least(self, point: Point) -> float:
        """The run time ``point`` needs at least before it may stop: its development and
        its minimum average."""
        return self.t_dev_of(point) + self.limits(point)[1]

    def reached_least(self, point: Point, t_end: float) -> bool:
        """Whether a run of ``point`` whose last sample is at ``t_end`` ran its least
        (:meth:`t_least`, to within TIME_TOL)."""
        return t_end + TIME_TOL >= self.t_least(point)


WIDTHS = (20.0, 40.0, 60.0)
PHIS = (0.59, 0.60, 0.61)
#: the stiffness test (fig. 10): branches of this (W, phi_bar) at these k_n
STIFF_AT = (20.0, 0.59)
STIFF_KN = (1e6, 1e7)


def _branches(parent: Point, kns: Iterable[float]) -> tuple[Point, ...]:
    return tuple(replace(parent, kn=k, parent=parent.key) for k in kns)


def full_plan() -> Plan:
    """W = 20, 40, 60 x phi_bar = 0.59, 0.60, 0.61 at B = 10, H = 20, k_n = 1e5; the
    stiffness branches at W = 20, phi_bar = 0.59 (k_n = 1e7 costs 10x the steps), each from
    its own seed's parent; then W = 100 at the three phi_bar. REPLICAS seeds of every point,
    one after another (a campaign stopped part way leaves complete replica sets)."""
    pts = tuple(Point(w, p, seed=s) for w in WIDTHS for p in PHIS for s in SEEDS)
    branches = tuple(b for s in SEEDS for b in _branches(Point(*STIFF_AT, seed=s), STIFF_KN))
    return Plan("full", pts, branches,
                later=tuple(Point(100.0, p, seed=s) for p in PHIS for s in SEEDS),
                superseded_by="widths (`--widths`, docs/reproduce_000_widths.md: 000's own "
                              "preparation, the rain, 2000 + 600 and W = 150)")


#: issue 36's campaign (:func:`widths_plan`): 000's rain, widths to 150, the depth check and
#: the stiffness branches at W = 60
WIDE = (150.0, 100.0)
NARROW = (60.0, 40.0, 20.0)
RAIN_PHIS = (0.59, 0.60, 0.61)
#: the jamming bound is looked for at W = 60 (000: phi_bar_max = 0.62)
JAM_AT = (60.0, 0.62)
#: the depth check at W = 60, phi_bar = 0.60 (000 runs B = 40)
DEPTHS = (20.0, 40.0)
DEPTH_AT = (60.0, 0.60)
#: the periodic height of the rained campaign (issue 36): the rain (rain_phi = 0.02) packs its
#: bed's core at ~0.622 and the seam closes over its rough top (docs/channel.md,
#: "Preparation"), so H = 20 holds phi_bar = 0.59-0.61
RAIN_H = 20.0


#: the widths plan's cap: 000's 2000 + 600, and room for 20 correlation times of 80 (the
#: slowest measured at W = 60 and 150, 79 and 66, need 1580 and 1320 of averaging; under the
#: first cap, 3200, both ended unconverged). Runs that ended at the first cap keep their rows
#: (the report names them): a finished copy keeps its checkpoint alone, so it cannot go on.
WIDTHS_T_MAX = 3600.0


def widths_plan() -> Plan:
    """Issue 36's campaign, phi_bar = 0.60 across every width first, the widest first (a
    partial campaign still answers the width question), then 0.59 and 0.61 the same way:
    W = 150 and 100, one seed; W = 60, 40, 20, REPLICAS seeds; then phi_bar = 0.62 at W = 60
    (the jamming bound), REPLICAS seeds; the depth check at
    W = 60, phi_bar = 0.60 (B = 20, 40; B = 10 is the main point); then the stiffness
    branches (k_n = 1e6, 1e7 from the W = 60, phi_bar = 0.60 point of each seed). All at
    H = RAIN_H, k_n = 1e5, prepared by 000's rain; each runs 000's protocol: 2000 of
    development, then at least 600 averaged, and longer where 600 is under the rule's 20
    correlation times (to WIDTHS_T_MAX)."""
    def rained(w: float, phi: float, seed: int, b: float = 10.0) -> Point:
        return Point(w, phi, seed=seed, B=b, H=RAIN_H, prep="rain")

    # (phi_bar = 0.60 across every width first: 2000 + 600 makes the plan ~250 core-hours,
    # and one phi_bar across all widths answers the width question; then 0.59 and 0.61)
    widths = tuple(rained(w, p, 1) if w in WIDE else rained(w, p, s)
                   for p in (0.60, 0.59, 0.61) for w in (*WIDE, *NARROW)
                   for s in ((1,) if w in WIDE else SEEDS))
    jam = tuple(rained(*JAM_AT, s) for s in SEEDS)
    depth = tuple(rained(*DEPTH_AT, 1, b) for b in DEPTHS)
    branches = tuple(b for s in SEEDS for b in _branches(rained(*DEPTH_AT, s), STIFF_KN))
    # (t_max above 2600: where the slowest quantity's correlation time exceeds 30, as at
    # W = 40 (37.6), 600 averaged holds fewer than 10 jackknife blocks and 20 correlation
    # times; such a run goes on until it holds them, or drifts on to the cap)
    return Plan("widths", (*widths, *jam, *depth), branches, t_dev=2000.0,
                min_average=600.0, t_max=WIDTHS_T_MAX)


def paper_plan() -> Plan:
    """000's own scale: W = 60, 80, 100, 125, 150 x phi_bar = 0.59-0.62 at B = 40, H = 60,
    k_n = 1e6, to t = 2600 (steady after 2000, 600 averaged), REPLICAS seeds."""
    pts = tuple(Point(w, p, seed=s, kn=1e6, B=40.0, H=60.0)
                for s in SEEDS for w in (60.0, 80.0, 100.0, 125.0, 150.0)
                for p in (0.59, 0.60, 0.61, 0.62))
    return Plan("paper", pts, t_dev=2000.0, t_max=2600.0, min_average=600.0)


def quick_plan() -> Plan:
    """Minutes on two cores: W = 12 at phi_bar = 0.58 and 0.59, B = 5, H = 8, a short average
    at 3 % SE, and one k_n = 1e6 branch; one seed (a test of the machinery, not a
    measurement)."""
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


def point_row(point: Point, plan: Plan, bins: pa.Table, series: pa.Table,
              n: int | None = None) -> dict[str, Any]:
    """The row of a point from its tables: state (the fluctuation threshold scaled to its
    ``n`` particles where given, :func:`~granflow.analysis.channel_profiles.flow_state`),
    steady start and averaging time, the section 3 numbers with SEs, whether it met the
    plan's criterion; its half profile, zone means and SE rows under ``"profile_rows"``,
    ``"zone_rows"``, ``"se_rows"``."""
    from granflow.analysis import channel as ach
    from granflow.analysis.channel_profiles import flow_state, profiles

    row: dict[str, Any] = {**asdict(point), "state": "short", "converged": False,
                           "profile_rows": [], "zone_rows": [], "se_rows": []}
    t = np.asarray(series.column("t").to_numpy(), dtype=float)
    if t.size < 100:
        return row
    fs = flow_state(series, n_particles=n)
    # (vcm_state keeps the v_cm classification, 000's states, where a drifting mean
    # overrides state below)
    row.update(state=fs.state, vcm_state=fs.state, t_end=float(t[-1]), vcm_tail=fs.v_mean,
               rel_amplitude=fs.rel_amplitude, rel_drift=fs.rel_drift)
    t_dev = plan.t_dev_of(point)
    if not fs.is_steady or (t_dev and not plan.reached_least(point, float(t[-1]))):
        return row
    # (000's protocol averages from its development time on; MSER after it would only cut
    # a few windows of noise and leave the average short of min_average at t_max)
    prof = profiles(bins, start_time=t_dev) if t_dev else profiles(bins, series)
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
    chk = ach.steady_check(prof)
    row.update(drift_z=chk.stationarity.max_abs_z, drift_quantity=chk.stationarity.worst,
               drift_tested=chk.stationarity.tested, tau_max=chk.tau_max)
    row.update(creep_row(series, prof.t_start))
    # (the profile's shape on blocks of its own correlation time: where the level's slow mode
    # leaves the run too few blocks, these still have an SE; ach.own_blocked)
    for k, ob in ach.own_blocked(bins, t_dev if t_dev else prof.t_start).items():
        row[f"{k}_own"], row[f"{k}_own_se"] = ob.estimate.value, ob.estimate.se
        row[f"{k}_own_tau"], row[f"{k}_own_blocks"] = ob.tau, ob.n_blocks
        row[f"{k}_own_z"] = ob.drift_z
    if chk.drifting:
        row["state"] = FlowState.DRIFTING.value
    row["converged"] = converged(row, plan, point)
    return row


#: the creep's time unit: its slope is the relative change of |v_cm| per this many sqrt(d/g)
CREEP_PER = 1000.0


def creep_row(series: pa.Table, t_start: float) -> dict[str, Any]:
    """The straight-line trend of |v_cm| over the steady part (from ``t_start``) as the
    relative change per CREEP_PER time units, with its SE corrected for serial correlation
    (granflow.analysis.stats.steady.trend): ``creep``, ``creep_se``, ``creep_z``. Reported,
    not part of the stop rule: a slow creep within the thirds test's errors still biases a
    replica by where it stops (the report pools it over replicas)."""
    from granflow.analysis.stats.steady import trend

    t = np.asarray(series.column("t").to_numpy(), dtype=float)
    v = np.abs(np.asarray(series.column("vcm_y").to_numpy(), dtype=float))
    keep = t >= t_start
    tr = trend(t[keep], v[keep])
    scale = CREEP_PER / abs(tr.mean) if tr.mean else math.nan
    return {"creep": tr.slope * scale, "creep_se": tr.slope_se * scale, "creep_z": tr.t_stat}


def long_enough(row: Mapping[str, Any], plan: Plan, point: Point) -> bool:
    """Whether a steady run is stationary (tested by the thirds test and not drifting) and its
    steady part spans the plan's ``min_average`` and ``min_taus`` correlation times of its
    slowest reported quantity (``tau_max``): the minimum length before any SE target is
    consulted. With a development time the steady part starts after it, and the run must
    have reached ``t_dev + min_average`` (000's protocol is a run length: ``T_avg``, the
    span the blocks used, may fall short of it by the windows left out of whole blocks)."""
    state = row.get("state", "")
    t_avg = row.get("T_avg", 0.0)
    tau = row.get("tau_max", math.nan)
    t_dev = plan.t_dev_of(point)
    long = (plan.reached_least(point, row.get("t_end", 0.0)) if t_dev
            else t_avg >= plan.limits(point)[1])
    return (state in FlowState._value2member_map_ and FlowState(state).is_steady
            and bool(row.get("drift_tested")) and math.isfinite(tau)
            and long and t_avg >= plan.min_taus * tau
            and row.get("t_start", 0.0) >= t_dev - 1e-9)


def converged(row: Mapping[str, Any], plan: Plan, point: Point) -> bool:
    """The stop rule (module docstring): :func:`long_enough`, then the SE targets of u_slip
    and u_max (a NaN SE, from too few jackknife blocks, meets none)."""
    return long_enough(row, plan, point) and all(
        math.isfinite(row[f"{k}_se"]) and row[f"{k}_se"] <= plan.se_target * abs(row[k])
        for k in ("u_slip", "u_max"))


ROW_TABLES = {"profile_rows": "profiles", "zone_rows": "zones", "se_rows": "se_vs_time",
              "order_rows": "order"}


#: time units before the development time from which a committed copy keeps the bins
#: windows (profiles take those with t0 >= t_dev; the slack keeps a window either side)
WINDOW_SLACK = 5.0


def _blank_except(tab: pa.Table, keep: Sequence[str]) -> pa.Table:
    """``tab`` with its float columns not in ``keep`` NaN, "not kept" (the same schema, whose
    columns are never null: a restored scene's tables go on with its own; a constant column
    compresses to nothing). Other columns are kept: the channel's are the window, bin and
    step counters."""
    for i, f in enumerate(tab.schema):
        if f.name not in keep and pa.types.is_floating(f.type):
            tab = tab.set_column(i, f, pa.array(np.full(tab.num_rows, np.nan), f.type))
    return tab


def order_rows(point: Point, scene: Any) -> list[dict[str, Any]]:
    """The bond-orientational order across the channel of ``scene``'s present state
    (Channel.order_profile: Q6, crystal-like fraction, coordination per bin), a row per bin
    with the point's fields, the time, and ``xi`` = min(x, W - x), the distance from the
    nearer wall (the half profiles' bins)."""
    prof = scene.order_profile()
    t = float(scene.core.time)
    return [{**asdict(point), "t": t, "xi": min(r["x"], point.W - r["x"]),
             **{k: r[k] for k in ("x", "particles", "bonds", "Q6", "crystal_fraction", "Z")}}
            for r in prof.iter_rows(named=True)]


class ChannelStudy(Study):
    """The channel campaign on the engine: a point (or a branch, from its parent's
    checkpoint) in stints of ``plan.stint`` time units until :func:`point_row` says it is
    steady and converged, or it arrested at two stints running, or ``t_max``. Its row ends
    with ``prep_seconds``, the preparation's wall time (``wall_seconds`` is all of it)."""

    tables = ROW_TABLES
    final_tables = ("order_rows",)

    def scene(self, point: Point, plan: Plan, threads: int) -> Any:
        from granflow.scenes.channel import Channel

        return Channel(W=point.W, H=point.H, B=point.B, phi_bar=point.phi_bar, kn=point.kn,
                       dt=point.dt, seed=point.seed, threads=threads, preparation=point.prep,
                       sample_every=max(1, round(SAMPLE_DT / point.dt)), window=WINDOW)

    def start(self, scene: Any, point: Point, plan: Plan, work: Path) -> None:
        if point.parent:
            scene.branch_from(work / point.parent / "checkpoint.gfck")
        else:
            scene.prepare(progress=False)

    def starts_from(self, point: Point) -> tuple[str, ...]:
        return (point.parent,) if point.parent else ()

    def dependents(self, key: str, plan: Plan) -> tuple[str, ...]:
        return tuple(b.key for b in (*plan.branches, *plan.later) if b.parent == key)

    def kept_tables(self, point: Point, plan: Plan,
                    tables: Mapping[str, pa.Table]) -> Mapping[str, pa.Table]:
        # (a W = 150 run's tables reach ~80 MB by t = 2600, too much to commit each
        # session: the copy holds what point_row reads, the columns
        # granflow.analysis.channel.summary reads (the others NaN) and, with a development
        # time, the bins from there on; its rows equal the whole tables')
        from granflow.analysis.channel import BINS_READ, SERIES_READ

        t_dev = plan.t_dev_of(point)
        kept = dict(tables)
        for name, read in (("bins", BINS_READ), ("series", SERIES_READ)):
            if name in kept:
                kept[name] = _blank_except(kept[name], read)
        if t_dev and "bins" in kept:
            bins = kept["bins"]
            read = pc.greater_equal(bins["t0"], t_dev - WINDOW_SLACK)
            if not pc.any(read).as_py():
                # (before t_dev the last window stands in: a scene leaves an empty table out
                # of its tables, and a row needs a bins table even before it reads one)
                read = pc.equal(bins["window"], pc.max(bins["window"]))
            kept["bins"] = bins.filter(read)
        return kept

    def context(self, scene: Any) -> dict[str, Any]:
        return {"n": scene.prep_info.get("n")}

    def next_steps(self, scene: Any, point: Point, plan: Plan) -> int:
        t_max, _ = plan.limits(point)
        if scene.core.time >= t_max - 1e-9:
            return 0
        return min(max(1, round(plan.stint / point.dt)),
                   max(1, round((t_max - scene.core.time) / point.dt)))

    def describe(self, row: Mapping[str, Any]) -> str:
        return (f"{row.get('state')}{'' if row.get('converged') else ' (not converged)'}, "
                f"u_slip = {fmt(row, 'u_slip')}, u_max/u_slip = "
                f"{fmt(row, 'u_max_over_u_slip')}, t = {fmt(row, 't_run', '.0f')}, prep "
                f"{fmt(row, 'prep_seconds', '.1f')} s, {fmt(row, 'wall_seconds', '.0f')} s")

    def progress(self, scene: Any, prep_seconds: float) -> dict[str, Any]:
        return {"n": scene.prep_info.get("n"),
                "phi_bar_achieved": scene.prep_info.get("phi_bar_achieved"),
                "settle_time": scene.prep_info.get("settle_time"),
                "t_run": float(scene.core.time), "steps": int(scene.core.step),
                "prep_seconds": prep_seconds}

    def row(self, point: Point, plan: Plan, tables: Mapping[str, pa.Table],
            context: Mapping[str, Any]) -> dict[str, Any]:
        # (the rained campaign's state is judged with the N-scaled threshold; the committed
        # pour campaign keeps 000's 1 %, as it was run)
        n = context.get("n") if point.prep == "rain" else None
        return point_row(point, plan, tables["bins"], tables["series"], n)

    def final(self, point: Point, scene: Any) -> dict[str, list[dict[str, Any]]]:
        # (the plug's order parameter: a snapshot of the last state)
        return {"order_rows": order_rows(point, scene)}

    def stop(self, row: Mapping[str, Any], point: Point, plan: Plan,
             history: Sequence[str]) -> str | None:
        if row["converged"]:
            return "converged"
        if row["state"] == "arrested" and history[-1:] == ["arrested"]:
            return "arrested"
        if row["t_run"] >= plan.limits(point)[0] - 1e-9:
            return "budget"
        return None


#: the channel campaign's study (one instance: the engine sends it to the workers)
STUDY = ChannelStudy()


def reanalyse(out: str | os.PathLike[str], plan: Plan) -> int:
    """Recompute the finished points of ``out`` from their tables (the engine's
    :func:`~granflow.studies._campaign.engine.reanalyse`); returns the number dropped."""
    dropped = engine_reanalyse(STUDY, Point, plan, out)
    add_final_rows(STUDY, Point, plan, out)
    return dropped


# --------------------------------------------------------------------------------------------
# the campaign
# --------------------------------------------------------------------------------------------
def run_campaign(plan: Plan, out: str | os.PathLike[str], workers: int | None = None,
                 scheduler: str | None = None, log: Any = print,
                 threads: int | None = None, whole: Plan | None = None) -> pl.DataFrame:
    """Run the points of ``plan`` not yet in ``out/points.parquet`` (with the branches whose
    parents are done, first), then the other branches (their parents are done by then), then
    its later points; each finished point is appended there as it completes. ``whole``: the
    plan ``plan`` is a piece of (``--select``), whose branches keep their parents' copies."""
    kw: dict[str, Any] = {"workers": workers, "scheduler": scheduler, "threads": threads,
                          "log": log, "whole": whole}
    if (n := add_final_rows(STUDY, Point, plan, out)):
        log(f"{plan.name}: the order across the channel measured on {n} finished points' last "
            "states")
    done = done_keys(Path(out), Point, STUDY)
    ready = tuple(b for b in plan.branches if b.parent in done)
    run_points(STUDY, (*ready, *plan.points), plan, out, name=plan.name, **kw)
    waiting = tuple(b for b in plan.branches if b not in ready)
    run_points(STUDY, waiting, plan, out, name=f"{plan.name} branches", **kw)
    return run_points(STUDY, plan.later, plan, out, name=f"{plan.name} later", **kw)


def main(argv: Iterable[str] | None = None) -> None:
    from granflow.studies.reproduce_000_report import write_report

    from ._campaign import cli

    cli(argv, module="granflow.studies.reproduce_000", description=(__doc__ or "").splitlines()[0],
        plans={"quick": (quick_plan, "minutes-long subset (default)"),
               "full": (full_plan, "the width and phi_bar campaign"),
               "widths": (widths_plan, "000's rain, W to 150, 2000 + 600"),
               "paper": (paper_plan, "000's own scale (a cluster's work: the report's "
                                     "recipe)")},
        reanalyse=reanalyse, run_campaign=run_campaign,
        write_report=lambda out, path, plan: write_report(out, path, plan, paper_plan()))


if __name__ == "__main__":
    main()
