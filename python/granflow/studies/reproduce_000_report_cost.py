"""The 000 report's cost sections: the throughput measured on a dataset (per width), the
runs a plan has left and their core-hours, the paper-scale estimate and its recipe."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import polars as pl

from ._campaign import (
    cost,
    dask_recipe,
    md_table,
    paper_scale_estimate,
    run_seconds,
    span,
)
from ._campaign.engine import kept_dir


def particles(p: Any) -> float:
    """A point's particle count: W H B phi_bar / <pi d^3/6> of 000's mix."""
    from granflow.sizes import CHANNEL_MIX

    return float(p.W * p.H * p.B * p.phi_bar / CHANNEL_MIX.mean_volume)


def particle_steps(plan: Any) -> Callable[[Any], float]:
    """A point of ``plan`` (reproduce_000.paper_plan) to its t_max at its dt: its particles
    (:func:`particles`) times its steps."""
    return lambda p: particles(p) * plan.t_max / p.dt


#: the channel's throughput (particle-steps per core-second) where a dataset has no finished
#: point to measure it on: the widths plan's W = 150, phi_bar = 0.60 point, developed (seven
#: stints, t = 1350-1700, CPU time; one thread beside one other one-thread run;
#: benchmarks/NOTES.md, 2026-11-28 fourth session; one stint at t = 250-300 gave 4.15e6)
UNMEASURED_RATE = 5.6e6


def planning_rate(rate: float | None) -> tuple[float, str]:
    """The throughput that runs still to do are costed at, and its source: the slower of the
    dataset's measured ``rate`` (None: no finished point) and UNMEASURED_RATE."""
    # (a developed wide channel steps slower per particle than a narrow one, W = 60 at about
    # half W = 20's rate (benchmarks/NOTES.md, 2026-11-27 sixth session): so that the wide
    # runs are not underestimated from narrow ones)
    r = UNMEASURED_RATE if rate is None else min(rate, UNMEASURED_RATE)
    source = ("measured on this dataset" if r == rate else "the W = 150 run's stints, "
              "benchmarks/NOTES.md: " + ("no finished point here yet" if rate is None else
                                         "slower than this dataset's narrower runs"))
    return r, source


def width_rates(points: pl.DataFrame) -> dict[tuple[float, float], float]:
    """The throughput (particle-steps per core-second of the runs only, _campaign.run_seconds,
    as :func:`cost`) measured on the finished
    points of ``points`` per (W, k_n)."""
    need = {"n", "steps", "wall_seconds", "prep_seconds"}
    if not points.height or not need <= set(points.columns):
        return {}
    d = points.filter(pl.col("steps") > 0).with_columns(
        (pl.col("n") * pl.col("steps")).alias("ps"),
        run_seconds(points, "prep_seconds").alias("run_s"))
    per = d.group_by("W", "kn").agg((pl.col("ps").sum() / pl.col("run_s").sum()).alias("r"))
    return {(float(w), float(k)): float(r) for w, k, r in per.iter_rows()
            if math.isfinite(r) and r > 0}


def rate_at(w: float, kn: float, rates: Mapping[tuple[float, float], float],
            default: float = UNMEASURED_RATE) -> tuple[float, str]:
    """The throughput a run at width ``w`` and ``kn`` is costed at, and where it comes from:
    ``rates`` measured at that width, else at the nearest wider width measured (a wider
    channel steps slower per particle: benchmarks/NOTES.md, so that bounds it), else
    ``default``."""
    if (w, kn) in rates:
        return rates[(w, kn)], f"W = {w:g}"
    wider = sorted(x for x, k in rates if k == kn and x > w)
    if wider:
        return rates[(wider[0], kn)], f"W = {wider[0]:g}"
    return default, "W = 150 stints"


def remaining(out: Path, plan: Any, default: float = UNMEASURED_RATE) -> list[str]:
    """The plan's runs not yet in ``out``, per (W, k_n, B): how many, and their core-hours at
    the throughput measured on ``out``'s finished points at that width (:func:`rate_at`;
    ``default`` where none bounds it), from the least each must run (Plan.t_least: its
    development and minimum average) to its cap (t_max), less what a started run has done
    (its series in the committed copy, ``out/progress``); the longest run's hours on one
    core; the recipe. Report lines; none when the plan is done."""
    from ._campaign import done_keys

    planned = (*plan.points, *plan.branches, *plan.later)
    if not planned:
        return []
    # (the plan's own point class: this module may not import reproduce_000, which imports it)
    done = done_keys(out, type(planned[0]))
    left = [p for p in planned if p.key not in done]
    if not left:
        return []
    f = out / "points.parquet"
    finished = pl.read_parquet(f) if f.exists() else pl.DataFrame()
    rates = width_rates(finished)
    rows: dict[tuple[float, float, float], dict[str, Any]] = {}
    # (the plan's first phi_bar at its first depth, every width: the piece it runs first,
    # where the plan's points begin with all of them)
    head = planned[0]

    def in_head(p: Any) -> bool:
        return not p.parent and (p.phi_bar, p.B, p.kn) == (head.phi_bar, head.B, head.kn)

    n_head = sum(map(in_head, plan.points))
    head_first = all(map(in_head, plan.points[:n_head]))
    first = [0, 0.0]
    for p in left:
        t_cap = plan.limits(p)[0]
        # (the committed copy of a running point's tables: the same on any clone)
        series = kept_dir(out / "work", p.key) / "series.parquet"
        t_done = (float(pl.read_parquet(series, columns=["t"])["t"].max())  # type: ignore[arg-type]
                  if series.exists() and not p.parent else 0.0)
        r, source = rate_at(p.W, p.kn, rates, default)
        per_t = particles(p) / p.dt / r / 3600  # core-hours per unit of time
        row = rows.setdefault((p.W, p.kn, p.B), {"W": p.W, "k_n": p.kn, "B": p.B, "runs": 0,
                                                 "rate": r, "rate from": source,
                                                 "core-hours (least)": 0.0,
                                                 "core-hours (cap)": 0.0,
                                                 "longest run (h, 1 core)": 0.0})
        row["runs"] += 1
        row["core-hours (least)"] += per_t * max(plan.t_least(p), t_done) - per_t * t_done
        row["core-hours (cap)"] += per_t * (t_cap - t_done)
        if head_first and in_head(p):
            first[0] += 1
            first[1] += per_t * (t_cap - t_done)
        row["longest run (h, 1 core)"] = max(row["longest run (h, 1 core)"],
                                             per_t * (t_cap - t_done))
    tab = pl.DataFrame(sorted(rows.values(), key=lambda d: (-d["W"], d["k_n"], d["B"])))
    lo, hi = float(tab["core-hours (least)"].sum()), float(tab["core-hours (cap)"].sum())
    longest = float(tab["longest run (h, 1 core)"].max())  # type: ignore[arg-type]
    after = getattr(plan, "superseded_by", "")
    return ["## Not yet run", "",
            *([f"The {after} campaign carries this one's question on: the runs below are "
               "what this plan would still run, for its own protocol only.", ""] if after
              else []),
            f"{len(left)} runs of the {plan.name} plan, each from the least it must run (a "
            "branch its minimum average; the others their development time and minimum average) "
            "to its cap "
            f"(t = {plan.t_max:g}), less what a started run has done, at the throughput "
            "(`rate`, particle-steps per core-second) measured on this dataset's finished "
            "points at that width and k_n, else at the nearest wider width measured (a wider "
            "channel steps slower per particle), else "
            f"{default:.3g} (`W = 150 stints`: the W = 150 run's stints, "
            "benchmarks/NOTES.md):", "",
            md_table(tab, {"W": ".0f", "k_n": ".0e", "B": ".0f", "rate": ".3g",
                           "core-hours (least)": ".1f", "core-hours (cap)": ".1f",
                           "longest run (h, 1 core)": ".1f"}), "",
            *tau_floor(finished, plan),
            f"About {lo:.0f}-{hi:.0f} core-hours: {lo / 6:.0f}-{hi / 6:.0f} sessions of 3 h "
            "on this 2-core machine"
            + (f"; of these, φ̄ = {head.phi_bar:g} at every width (B = {head.B:g}), which the "
               f"plan runs first, {first[0]} runs and at most {first[1]:.0f} core-hours "
               f"({first[1] / 6:.0f} session{'' if round(first[1] / 6) == 1 else 's'})"
               if first[0] else "")
            + ". On a cluster each point is one task of one "
            f"thread (it checkpoints every stint and resumes from there); the longest takes "
            f"{longest:.0f} h on one core, so the jobs' walltime below:", "",
            *dask_recipe("granflow.studies.reproduce_000", f"{out}",
                         f"{math.ceil(1.25 * longest):d}:00:00", plan.name)]


#: the columns besides W that set a run's correlation times (column, as the report names it)
_QUALIFIERS = (("B", "B"), ("kn", "k_n"))


def tau_floor(points: pl.DataFrame, plan: Any) -> list[str]:
    """What the cap leaves the stop rule: per width, the finished runs' slowest correlation
    time (``tau_max``, from their steady parts) and the averaging its floor of
    ``plan.min_taus`` of them asks, against the averaging the cap allows (t_max - t_dev).
    Report lines; none without a run that measured it."""
    if not points.height or "tau_max" not in points.columns:
        return []
    t = points.filter((pl.col("parent") == "") & pl.col("tau_max").is_finite())
    if not t.height:
        return []
    room = plan.t_max - (plan.t_dev or 0.0)
    # a depth or stiffness branch at a width is a line of its own, named where runs differ in it
    quals = [(c, label) for c, label in _QUALIFIERS if c in t.columns and t[c].n_unique() > 1]
    words, short = [], []
    for key, g in t.sort("W", *(c for c, _ in quals)).group_by(
            ["W", *(c for c, _ in quals)], maintain_order=True):
        name = f"W = {key[0]:g}" + "".join(
            f", {label} = {v:g}" for (_, label), v in zip(quals, key[1:], strict=True))
        lo, hi = float(g["tau_max"].min()), float(g["tau_max"].max())  # type: ignore[arg-type]
        need = (plan.min_taus * lo, plan.min_taus * hi)
        words.append(f"{name}: τ {span(lo, hi, '.0f')} ({plan.min_taus:g} τ = "
                     f"{span(*need, '.0f')}, {g.height} run{'s' if g.height > 1 else ''})")
        if need[1] > room:
            short.append(name.removeprefix("W = "))
    return [f"What the cap leaves the stop rule: it averages at most {room:g} time units "
            f"(t = {plan.t_dev or 0.0:g}-{plan.t_max:g}) and asks for {plan.min_taus:g} "
            "correlation times of the slowest quantity; the finished runs measure "
            + "; ".join(words)
            + (f". At W = {'; '.join(short)} that is more than the cap allows: a run there ends "
               "at the cap without the rule's SE unless the cap is raised." if short
               else "."), ""]


def cost_section(points: pl.DataFrame, paper: Any) -> tuple[list[str], float]:
    """The cost and paper-scale sections' lines, and the measured throughput."""
    # (per W: points, particles, preparation and run wall time, core-hours; the throughput
    # of the runs only)
    per, rate = cost(points, ["W", "kn"], "n", "steps",
                     columns=[pl.col("n").max().alias("particles"),
                              pl.col("prep_seconds").max().alias("longest preparation (s)")],
                     sort=["kn", "W"], prep="prep_seconds")
    r, source = planning_rate(rate)
    est = paper_scale_estimate(paper.points, particle_steps(paper), r)
    return ["## Cost", "",
            f"Measured throughput {rate:.3g} particle-steps per core-second (one thread "
            "a point, two points at a time on this 2-core machine; preparation not "
            "counted), from each point's CPU time where recorded, else its wall time (which "
            "overstates the core time of a point that shared its core with tests or builds: "
            "an upper bound); longest point: wall time.", "",
            md_table(per, {"core-hours": ".3f", "longest point (s)": ".0f",
                           "longest preparation (s)": ".1f", "kn": ".0e"}), "",
            f"Total: {per['core-hours'].sum():.2f} core-hours.", "",
            "## The paper-scale campaign (recipe)", "",
            "000 runs W = 60-150, B = 40, H = 60 + ΔH, φ̄ = 0.59-0.62 at k_n = 1e6 and "
            "averages over t = 2000-2600. `--paper` (reproduce_000.paper_plan) is that "
            f"campaign, W = 60, 80, 100, 125, 150 x four φ̄ x 3 seeds: {est['runs']:.0f} "
            f"runs to t = {paper.t_max:g}, {est['particle-steps']:.3g} particle-steps, "
            f"about {est['core-hours']:,.0f} core-hours at {r:.3g} particle-steps per "
            f"core-second ({source}; k_n = 1e6's smaller step builds the lists about three times "
            "less often per step, which this does not credit) "
            f"({est['core-hours'] / 64:,.0f} hours on 64 cores; fewer where a run "
            "arrests or meets its SE target early).", "",
            *_per_point_cost(paper, r),
            *dask_recipe("granflow.studies.reproduce_000", "results/paper_000", "24:00:00")], rate


#: two threads against one on the flowing channel (benchmarks/NOTES.md: 3.15-3.35e7 against
#: 1.77-1.83e7 particle-steps/s, 6754 particles): the only thread scaling measured here
TWO_THREAD_SPEEDUP = 1.8


def _per_point_cost(paper: Any, rate: float) -> list[str]:
    """Core-hours of one paper-scale point per W (at phi_bar = 0.60, to the plan's t_max) and
    the cores a node needs to finish one in a day (at linear scaling: measured here only to
    two threads)."""
    steps = particle_steps(paper)
    rows = []
    for w in sorted({p.W for p in paper.points}):
        p = next(q for q in paper.points if q.W == w and abs(q.phi_bar - 0.60) < 1e-9)
        ch = steps(p) / rate / 3600
        rows.append({"W": w, "particles": round(steps(p) / (paper.t_max / p.dt)),
                     "particle-steps": steps(p), "core-hours": ch, "cores for a day": ch / 24})
    tab = pl.DataFrame(rows)
    return ["One point of it (phi_bar = 0.60, B = 40, H = 60, k_n = 1e6, dt = 1.2e-4, to "
            f"t = {paper.t_max:g}), and the cores a node needs to run it in a day at linear "
            "scaling (measured here only from one thread to two, "
            f"x{TWO_THREAD_SPEEDUP:g} on the flowing channel: benchmarks/NOTES.md; the 16-core "
            "scaling is not measured):", "",
            md_table(tab, {"W": ".0f", "particles": ".0f", "particle-steps": ".3g",
                           "core-hours": ",.0f", "cores for a day": ".0f"}), ""]
