"""The cell campaign (reproduce_002, cross_scene, seed_coverage run it): a *point* is one
cell run, (mu_s, N, p_ext, tau/p, seed), from the compacted start
(:class:`granflow.scenes.cell.ShearCell`), run in stints until it is done or its budget of
shear (``max_shear``) is spent, or it arrested over ARREST_STINTS stints, or it ran away. A
point with ``inertial_number`` I > 0 (and tau/p = 0) is the rate-controlled cell
(:class:`granflow.scenes.RateCell`, the plan's ``rate_normal`` held at p_ext), which reaches
the slow flows where the stress-controlled cell arrests; below the plan's ``rate_I_ref`` its
times are those of the plan times rate_I_ref / I (:meth:`Plan.scale`), so that its floor and
budget stay the same in strain.

The stop rule (:func:`converged`), in this order: the run is flowing and stationary (the
thirds test of :func:`granflow.analysis.rheology.classify_run`: a drifting run goes on); its
steady part spans ``min_length`` t_c, ``min_taus`` integrated correlation times of the slowest
of I, phi, mu1, mu2 (MIN_LENGTH_COLUMNS) and a shear strain of ``min_strain``; only then are
the SE targets consulted (mu1 and phi within ``se_target`` of their means, I within 3x,
SE_TARGETS). The minimum length keeps a run from stopping because its SE estimate happened to
dip (optional stopping biases every SE small), and gives each SE at least min_taus / 2 blocks
of 2 tau.

Times (stints, budgets) are in contact times t_c, the cell's unit: a stint of ``stint`` t_c is
``round(stint / f)`` steps at the material's dt = f t_c.

Its row: the point, its state, steps, wall seconds, and mean / SE / correlation time of every
observable; the SE of I, phi, mu1 over the first quarter, half and all of its steady part go
to ``OUT/se_vs_time.parquet``.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
import polars as pl
import pyarrow as pa

from granflow.analysis.stats import MIN_SE_BLOCKS
from granflow.errors import ParameterError
from granflow.material import MATERIAL_000, MATERIAL_002, DtRule, Material

from .engine import Study, fmt, run_points
from .engine import reanalyse as engine_reanalyse

#: observables kept per point (docs/columns.md, cell series)
OBSERVABLES = ("mu1", "mu2", "mu3", "phi", "I", "p", "shear_rate", "beta", "N0_tau", "N1_tau",
               "Z2", "theta_c", "A_xx", "A_xy", "A_yy", "A_zz", "max_overlap")
#: the steady part's fractions at which the SE is recorded (error against run time)
SE_FRACTIONS = (0.25, 0.5, 1.0)
SE_COLUMNS = ("I", "phi", "mu1")


@dataclass(frozen=True)
class Point:
    """One cell run of the campaign: stress-controlled at ``tau_ratio`` = tau/p, or (tau_ratio
    0) rate-controlled at ``inertial_number`` (module docstring)."""

    mu_s: float
    tau_ratio: float
    seed: int
    N: int = 2000
    p_ext: float = 1e-4
    #: the imposed rate as 002's I (RateCell's parameter); 0: stress-controlled (every point
    #: before the field existed, which is what its default must say)
    inertial_number: float = 0.0

    def __post_init__(self) -> None:
        if (self.tau_ratio > 0) == (self.inertial_number > 0) or min(
                self.tau_ratio, self.inertial_number) < 0:
            raise ParameterError(
                f"invalid point tau_ratio = {self.tau_ratio}, inertial_number = "
                f"{self.inertial_number}: allowed exactly one of them > 0 (a stress- or a "
                "rate-controlled cell), the other 0")

    @property
    def key(self) -> str:
        drive = (f"tau{self.tau_ratio:g}" if self.inertial_number == 0
                 else f"I{self.inertial_number:g}")
        return f"mu{self.mu_s:g}_N{self.N}_p{self.p_ext:g}_{drive}_s{self.seed}"


#: relative SE targets, as multiples of the plan's ``se_target``: mu1 and phi (the issue's
#: 1 %), and I (the fits' abscissa, whose SE is ~10x phi's: 3 %)
SE_TARGETS = {"mu1": 1.0, "phi": 1.0, "I": 3.0}
#: the reported quantities whose slowest correlation time sets a run's minimum length (phi's,
#: the barostat's volume mode, is 100-900 t_c at N = 2000, I's ~10-900, mu1's ~3)
MIN_LENGTH_COLUMNS = ("I", "phi", "mu1", "mu2")


@dataclass(frozen=True)
class Plan:
    """A campaign: its points, in the order they are run, and when a point is done (times in
    contact times t_c)."""

    name: str
    points: tuple[Point, ...]
    se_target: float = 0.01
    #: t_c of shear after which a point stops unconverged, by N (1,500,000 steps at N = 2000)
    max_shear: Mapping[int, float] = field(default_factory=lambda: {2000: 30_000.0})
    #: t_c per stint (50,000 steps)
    stint: float = 1000.0
    sample_every: int = 200
    #: shear strain (2 |D| T, engineering) the steady part must span: an SE target is easily
    #: met by a short stretch of a slow flow (p = 1e-5 met it after 0.3 of strain, dilating)
    min_strain: float = 2.0
    #: integrated correlation times of the slowest of MIN_LENGTH_COLUMNS the steady part must
    #: span before the SE targets are consulted (10 blocks of 2 tau)
    min_taus: float = 20.0
    #: t_c the steady part must span whatever its correlation times: a short run cannot see a
    #: mode slower than itself and estimates tau small (phi's tau from 3000 t_c of mu_s = 0,
    #: tau/p = 0.4: 60 t_c; from 20,000 t_c: 570), so min_taus alone stopped it at 1500 t_c
    min_length: float = 10_000.0
    #: the cell's material (the point's mu_s overrides its friction; 002's by default, the
    #: channel's in granflow.studies.cross_scene); its dt rule must be a fraction of t_c
    material: Material = MATERIAL_002
    #: observables kept per point (OBSERVABLES, and rheology.GRADIENT_COLUMNS if wanted)
    observables: tuple[str, ...] = OBSERVABLES
    #: the pressure at which ``stint``, ``max_shear`` and ``min_length`` are given; at a
    #: point's own p_ext they are times sqrt(p_ref / p_ext) (:meth:`scale`). A flow's times
    #: at a given I go as the inertial time a sqrt(rho/p), in t_c as p^-1/2: the strain per
    #: t_c and the correlation times in t_c of a point at p = 1e-6 are 10x those at 1e-4, so
    #: that its floor and budget in strain and correlation times stay those of p_ref. None:
    #: the same t_c at every pressure.
    p_ref: float | None = None
    #: the inertial number below which a rate-controlled point's times (stint, budget, floor,
    #: sampling interval) grow as 1/I: its strain per t_c is proportional to I, and its
    #: correlation times are a fixed strain (phi's ~0.3 at every I, docs/cell.md)
    rate_I_ref: float = 0.01
    #: the normal stress a rate-controlled point holds at p_ext (RateCell's ``normal``)
    rate_normal: str = "yy"

    def scale(self, p_ext: float, inertial_number: float = 0.0) -> float:
        """The factor on the plan's times at pressure ``p_ext`` (``p_ref``) and, for a
        rate-controlled point, at ``inertial_number`` (``rate_I_ref``)."""
        f = 1.0 if self.p_ref is None else math.sqrt(self.p_ref / p_ext)
        return f * self.rate_factor(inertial_number)

    def rate_factor(self, inertial_number: float) -> float:
        """rate_I_ref / I for a rate-controlled point slower than ``rate_I_ref``, else 1."""
        return max(1.0, self.rate_I_ref / inertial_number) if inertial_number > 0 else 1.0

    @property
    def dt(self) -> float:
        """The step in t_c (the material's dt rule, a fraction of t_c)."""
        rule = self.material.dt_rule
        if rule is None or rule.kind != "tc_fraction":
            raise ParameterError(f"invalid material.dt_rule = {rule!r}: allowed a fraction of "
                                 "t_c (DtRule.tc_fraction), the unit of the plan's times")
        return float(rule.value)

    def steps(self, t: float) -> int:
        """Steps in ``t`` contact times (at least one)."""
        return max(1, round(t / self.dt))

    def max_steps(self, n: int, p_ext: float, inertial_number: float = 0.0) -> int:
        """Steps of shear after which a point of ``n`` particles at ``p_ext`` (and the rate
        ``inertial_number``) stops unconverged."""
        return self.steps(self.max_shear.get(n, max(self.max_shear.values()))
                          * self.scale(p_ext, inertial_number))

    def stint_steps(self, p_ext: float, inertial_number: float = 0.0) -> int:
        """Steps of a stint at ``p_ext`` (and the rate ``inertial_number``)."""
        return self.steps(self.stint * self.scale(p_ext, inertial_number))

    def min_length_at(self, p_ext: float, inertial_number: float = 0.0) -> float:
        """The floor on a steady part at ``p_ext`` (and the rate ``inertial_number``) in
        t_c."""
        return self.min_length * self.scale(p_ext, inertial_number)

    def sample_every_at(self, inertial_number: float = 0.0) -> int:
        """Steps between samples: ``sample_every``, times rate_I_ref / I for a slow
        rate-controlled point (the same samples per strain; a stress-controlled point's
        is the plan's at every pressure, as the campaigns have run it)."""
        return max(1, round(self.sample_every * self.rate_factor(inertial_number)))

    def targets(self) -> dict[str, float]:
        """Relative SE each observable must reach (SE_TARGETS x ``se_target``)."""
        return {k: f * self.se_target for k, f in SE_TARGETS.items()}


def channel_material() -> Material:
    """The channel's material (:data:`granflow.material.MATERIAL_000`: its size mix and the
    kernel's law defaults) for the cell, in the cell's units (kn = 1), with the channel's dt
    per contact time (dt = 1.2e-4 sqrt(d/g) at kn = 1e6 over the mean pair's collision time)
    as its dt rule."""
    dt = MATERIAL_000.dt()
    assert dt is not None
    frac = dt / MATERIAL_000.contact_time("mean", reading="collision")
    return MATERIAL_000.with_(kn=1.0, tc_reading="collision",
                              dt_rule=DtRule.tc_fraction(frac))


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


def enough_blocks(t_avg: float, tau: float) -> bool:
    """Whether an averaging time ``t_avg`` holds the MIN_SE_BLOCKS blocks of 2 ``tau`` an SE
    may rest on (:data:`granflow.analysis.stats.MIN_SE_BLOCKS`); fewer: the SE is NaN (not
    enough data) rather than a small number."""
    return math.isfinite(tau) and t_avg >= 2.0 * MIN_SE_BLOCKS * tau


def _analyse(s: pl.DataFrame, observables: Iterable[str] = OBSERVABLES) -> dict[str, Any]:
    from granflow.analysis import rheology as rh

    cols = [c for c in observables if c in s.columns]
    res = rh.analyse_run(s, columns=cols)
    t_avg = float(s["t"][-1] - res.state.t_start)
    out: dict[str, Any] = {"state": res.state.state, "t_start": res.state.t_start,
                           "T_avg": t_avg, "drift_z": res.state.drift_z,
                           "drift_quantity": res.state.drift_quantity}
    for r in res.stats.iter_rows(named=True):
        o, tau = r["observable"], r["tau"]
        out[o], out[f"{o}_tau"] = r["mean"], tau
        out[f"{o}_se"] = r["se"] if enough_blocks(t_avg, tau) else math.nan
    taus = [out.get(f"{c}_tau", math.nan) for c in MIN_LENGTH_COLUMNS if f"{c}_tau" in out]
    out["tau_max"] = max(taus) if taus and all(map(math.isfinite, taus)) else math.nan
    return out


#: stints of shear before a point may stop as arrested
ARREST_STINTS = 4

def long_enough(row: Mapping[str, Any], plan: Plan) -> bool:
    """Whether a flowing, stationary run's steady part spans ``plan.min_length`` contact
    times (at the row's p_ext: :meth:`Plan.min_length_at`), ``plan.min_taus`` correlation
    times of its slowest reported quantity and ``plan.min_strain`` of shear: the minimum
    length before any SE target is consulted."""
    t_avg = row.get("T_avg", 0.0)  # (kernel time, as tau_max; T_avg_tc in t_c)
    tau = row.get("tau_max", math.nan)
    return bool(row["state"] == "flowing" and math.isfinite(tau)
                and row.get("T_avg_tc", 0.0) >= plan.min_length_at(
                    row["p_ext"], row.get("inertial_number") or 0.0)
                and t_avg >= plan.min_taus * tau
                and 2.0 * row.get("shear_rate", 0.0) * t_avg >= plan.min_strain)


def converged(row: Mapping[str, Any], plan: Plan) -> bool:
    """The stop rule (module docstring): :func:`long_enough`, then the SE targets."""
    return long_enough(row, plan) and all(
        bool(math.isfinite(row.get(f"{k}_se", math.nan)) and row[f"{k}_se"] <= t * abs(row[k]))
        for k, t in plan.targets().items())


def _se_rows(point: Point, s: pl.DataFrame, t_start: float,
             taus: Mapping[str, float]) -> list[dict[str, Any]]:
    """SE of I, phi, mu1 over the first fractions of the steady part (error against time;
    stats.se_vs_time per observable, each row with its averaging time T); NaN where the
    fraction spans fewer than MIN_SE_BLOCKS blocks of 2 tau, tau the whole run's (``taus``):
    a prefix cannot see a mode slower than itself, and its own SE is too small."""
    from granflow.analysis.stats import se_vs_time

    t = s["t"].to_numpy()
    start = int(np.searchsorted(t, t_start))
    rows: dict[float, dict[str, Any]] = {}
    for col in SE_COLUMNS:
        tab = se_vs_time(t, s[col].to_numpy(), fractions=SE_FRACTIONS, start=start).table
        tau = taus.get(col, math.nan)
        for r in tab.iter_rows(named=True):
            row = rows.setdefault(r["fraction"], {**asdict(point), "fraction": r["fraction"],
                                                  "T_avg": r["T"]})
            row[f"{col}_se"] = r["se"] if enough_blocks(r["T"], tau) else math.nan
    return list(rows.values())


def point_row(point: Point, plan: Plan, series: pa.Table, shear0: float) -> dict[str, Any]:
    """The row of a point from its series (the steady part after the shear switch at
    ``shear0``): state, mean / SE / correlation time of every observable, whether it met the
    plan's SE targets, and its SE rows under ``"se_rows"``."""
    s = _steady_series(series, shear0, plan.observables)
    row: dict[str, Any] = {**asdict(point), "state": "short", "converged": False}
    if s.height >= 200:
        row.update(_analyse(s, plan.observables))
        # (the series' time is the kernel's; the plan's lengths are in t_c: dt per step over
        # the plan's dt in t_c is t_c)
        step, t = s["step"].to_numpy(), s["t"].to_numpy()
        t_c = (t[-1] - t[0]) / float(step[-1] - step[0]) / plan.dt
        row["T_avg_tc"] = row["T_avg"] / t_c
        row["converged"] = converged(row, plan)
    taus = {c: float(row.get(f"{c}_tau", math.nan)) for c in SE_COLUMNS}
    row["se_rows"] = (_se_rows(point, s, float(row["t_start"]), taus)
                      if row["state"] == "flowing" else [])
    return row


class CellStudy(Study):
    """The cell campaign on the engine: a point in stints of ``plan.stint`` until its SE
    targets are met (:func:`point_row`), it arrested over ARREST_STINTS stints, or its
    ``max_shear`` is spent; a runaway ends it with phi at the switch and at the last sample."""

    tables = {"se_rows": "se_vs_time"}

    def current(self, row: Mapping[str, Any]) -> bool:
        # every row the present stop rule judged carries tau_max (NaN where a quantity has
        # no correlation time); rows from before it (the first cross_scene calibration: no
        # stationarity test, no floor of correlation times, SEs on a few blocks) do not (rows
        # that ended on an error: the engine's is_current)
        return row.get("tau_max") is not None

    def scene(self, point: Point, plan: Plan, threads: int) -> Any:
        from granflow.scenes.cell import ShearCell
        from granflow.scenes.rate_cell import RateCell

        every = plan.sample_every_at(point.inertial_number)
        if point.inertial_number > 0:
            return RateCell(N=point.N, mu=point.mu_s, p_ext=point.p_ext,
                            inertial_number=point.inertial_number, normal=plan.rate_normal,
                            seed=point.seed, material=plan.material, sample_every=every,
                            threads=threads)
        return ShearCell(N=point.N, mu=point.mu_s, p_ext=point.p_ext,
                         tau_ratio=point.tau_ratio, seed=point.seed, material=plan.material,
                         sample_every=every, threads=threads)

    def next_steps(self, scene: Any, point: Point, plan: Plan) -> int:
        left = plan.max_steps(point.N, point.p_ext, point.inertial_number) - _shear_steps(scene)
        return (min(plan.stint_steps(point.p_ext, point.inertial_number), left) if left > 0
                else 0)

    def context(self, scene: Any) -> dict[str, Any]:
        return {"shear_start_time": float(scene.shear_start_time or 0.0)}

    def describe(self, row: Mapping[str, Any]) -> str:
        return (f"{row.get('state')}, I = {fmt(row, 'I')}, phi = {fmt(row, 'phi', '.4f')}, "
                f"{fmt(row, 'shear_steps', '.0f')} steps, {fmt(row, 'wall_seconds', '.0f')} s")

    def progress(self, scene: Any, prep_seconds: float) -> dict[str, Any]:
        return {"t_c": scene.t_c, "shear_steps": _shear_steps(scene),
                "T_shear": float(scene.core.time - scene.shear_start_time)}

    def row(self, point: Point, plan: Plan, tables: Mapping[str, pa.Table],
            context: Mapping[str, Any]) -> dict[str, Any]:
        return point_row(point, plan, tables["series"], float(context["shear_start_time"]))

    def failure(self, scene: Any, context: Mapping[str, Any]) -> dict[str, Any]:
        """phi at the shear switch and at the last sample, and the time sheared (the
        measurement that there is no steady state)."""
        shear0 = float(context["shear_start_time"])
        s = pl.from_arrow(scene.tables()["series"])
        assert isinstance(s, pl.DataFrame)
        before, after = s.filter(pl.col("t") <= shear0), s.filter(pl.col("t") > shear0)
        return {"phi_start": float(before["phi"][-1]) if before.height else math.nan,
                "phi_end": float(after["phi"][-1]) if after.height else math.nan,
                "t_end": float(scene.core.time - shear0)}

    def stop(self, row: Mapping[str, Any], point: Point, plan: Plan,
             history: Sequence[str]) -> str | None:
        # (arrest is final once it held over ARREST_STINTS stints: a creeping packing can
        # restart)
        if row["converged"]:
            return "converged"
        if (row["state"] == "arrested"
                and row["shear_steps"] >= ARREST_STINTS * plan.stint_steps(
                    point.p_ext, point.inertial_number)):
            return "arrested"
        if row["shear_steps"] >= plan.max_steps(point.N, point.p_ext, point.inertial_number):
            return "budget"
        return None


def _shear_steps(cell: Any) -> int:
    return round((cell.core.time - cell.shear_start_time) / cell.core.dt)


#: the cell campaign's study (one instance: the engine sends it to the workers)
STUDY = CellStudy()


def run_campaign(plan: Plan, out: str | os.PathLike[str], workers: int | None = None,
                 scheduler: str | None = None,
                 log: Callable[[str], Any] = print,
                 threads: int | None = None, whole: Plan | None = None) -> pl.DataFrame:
    """Run the points of ``plan`` not yet in ``out/points.parquet``; each finished point is
    appended there as it completes (local process pool by default, or a Dask scheduler).
    ``whole``: the plan ``plan`` is a piece of (``--select``)."""
    return run_points(STUDY, plan.points, plan, out, workers=workers, scheduler=scheduler,
                      threads=threads, log=log, name=plan.name, whole=whole)


def reanalyse(out: str | os.PathLike[str], plan: Plan) -> int:
    """Recompute the finished points of ``out`` from their series (the engine's
    :func:`~granflow.studies._campaign.engine.reanalyse`); returns the number dropped."""
    return engine_reanalyse(STUDY, Point, plan, out)
