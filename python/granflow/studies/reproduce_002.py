"""Reproduce 002 (Srivastava, Silbert, Grest & Lechman): Table 1 and figures 3-8 from granflow's
own cell runs, as resumable pieces, and the report docs/reproduce_002.md.

    python -m granflow.studies.reproduce_002 --quick [--out DIR] [--report FILE]
    python -m granflow.studies.reproduce_002 --full | --paper [--out DIR] [--report FILE]
           [--workers N [--threads T] | --scheduler ADDRESS] [--reanalyse] [--only-report]

A *point* is one cell run, (mu_s, N, p_ext, tau/p, seed), run by the cell campaign
(:mod:`granflow.studies._campaign.cell`: its stints, stop rule and row). Each finished point is
appended at once to ``OUT/points.parquet`` (one row: the point, its state, steps, wall seconds,
and mean / SE / correlation time of every observable), and the SE of I, phi, mu1 over the first
quarter, half and all of its steady part to ``OUT/se_vs_time.parquet``: a run that is stopped
loses only its unfinished points, and those go on from their checkpoints under ``OUT/work/``
(not committed), or on another machine from the copy of them in ``OUT/progress/``. The
report pools the seeds of a point (inverse-variance), fits (4.2), (4.4), (4.6), (4.7) per
mu_s, prints each Table 1 row beside the paper's and draws figures 3-8.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from ._campaign.cell import (
    OBSERVABLES,
    SE_FRACTIONS,
    Plan,
    Point,
    reanalyse,
    run_campaign,
)

__all__ = ["OBSERVABLES", "PRESSURES", "SE_FRACTIONS", "Plan", "Point", "full_plan", "main",
           "paper_plan", "quick_plan", "ratio_range", "reanalyse", "run_campaign"]

#: tau/p per mu_s: from just above yield to the largest ratio with steady flow (measured from
#: the compacted start, docs/cell.md), then one ratio above it that records the runaway
RATIOS: dict[float, tuple[float, ...]] = {
    0.0: (0.15, 0.2, 0.25, 0.3, 0.35, 0.4),
    0.01: (0.15, 0.2, 0.25, 0.3, 0.35, 0.4),
    0.1: (0.25, 0.3, 0.35, 0.4, 0.45, 0.5),
    0.3: (0.4, 0.45, 0.5, 0.55, 0.6, 0.65),
}
#: ratios added after the first pass: nearer yield at mu_s = 0.3, to pin mu1_0 (run last)
NEAR_YIELD: dict[float, tuple[float, ...]] = {0.3: (0.36, 0.38)}
RUNAWAY: dict[float, float] = {0.0: 0.5, 0.01: 0.5, 0.1: 0.6, 0.3: 0.7}
#: further mu_s, run after the others
MORE_RATIOS: dict[float, tuple[float, ...]] = {
    0.03: (0.15, 0.2, 0.25, 0.3, 0.35, 0.4),
    0.2: (0.35, 0.4, 0.45, 0.5, 0.55, 0.6),
}


#: the frictions for which 002 gives every constant of its laws (§4): run whole first
CURVE_MU = (0.0, 0.3)
#: independent seeds of every point (its value is their mean, its SE from their spread and
#: their own SEs: granflow.analysis.replicas)
REPLICAS = 3
#: 002's three pressures p_ext a/kn, the first the campaign's main one (run first)
PRESSURES = (1e-4, 1e-5, 1e-6)
#: the size check at N = 10,000 (p_ext = 1e-4): one ratio of each of CURVE_MU, mid-range in I
SIZE_CHECK = {0.0: 0.3, 0.3: 0.5}


def full_plan() -> Plan:
    """The six mu_s at N = 2000 and 002's three pressures, REPLICAS seeds each.

    At p_ext = 1e-4: the ratios of RATIOS, MORE_RATIOS and NEAR_YIELD, then a runaway probe
    per mu_s of RUNAWAY (one seed). Then the lower pressures at the ratios of RATIOS and
    MORE_RATIOS (without the near-yield ratios, which arrest at 1e-4, and the runaway probes):
    mu_s = 0 and 0.3 at 1e-5, the size check (N = 10,000 at SIZE_CHECK), mu_s = 0 and 0.3 at
    1e-6 (with 1e-5: 002's collapse panels and the curve comparison), then the other mu_s at
    1e-5 and at 1e-6.

    Ordered so that a campaign stopped part way (it is split over sessions) leaves whole
    pieces: a ratio's seeds one after another, fast flows before slow ones. The plan's times
    are given at p_ext = 1e-4 and scale with the inertial time at the lower pressures
    (``Plan.p_ref``): a point at 1e-6 has 10x the t_c of one at 1e-4 for the same strain."""
    ratios = {mu: sorted({*rs, *NEAR_YIELD.get(mu, ())}, reverse=True)
              for mu, rs in sorted({**RATIOS, **MORE_RATIOS}.items())}
    seeds = range(1, REPLICAS + 1)
    pts = [Point(mu, rs[0], seed) for mu, rs in ratios.items() for seed in seeds]
    pts += [Point(mu, r, seed) for mu in CURVE_MU for r in ratios[mu][1:] for seed in seeds]
    pts += [Point(mu, rs[k], seed)
            for k in range(1, max(map(len, ratios.values())))
            for mu, rs in ratios.items() if mu not in CURVE_MU and k < len(rs)
            for seed in seeds]
    pts += [Point(mu, r, 1) for mu, r in RUNAWAY.items()]
    low = {mu: sorted(rs, reverse=True) for mu, rs in sorted({**RATIOS, **MORE_RATIOS}.items())}

    def at(p: float, mus: Iterable[float]) -> list[Point]:
        return [Point(mu, r, seed, p_ext=p) for mu in mus for r in low[mu] for seed in seeds]

    others = [mu for mu in low if mu not in CURVE_MU]
    pts += at(PRESSURES[1], CURVE_MU)
    pts += [Point(mu, r, seed, N=10_000) for mu, r in SIZE_CHECK.items() for seed in seeds]
    pts += at(PRESSURES[2], CURVE_MU)
    for p in PRESSURES[1:]:
        pts += at(p, others)
    # (2,000,000 steps at 1e-4: the slowest flows near yield stop there, with the SEs they
    # have; 20,000,000 at 1e-6)
    return Plan("full", tuple(pts), max_shear={2000: 40_000.0}, p_ref=PRESSURES[0])


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
                for p in PRESSURES for seed in (1, 2, 3)
                for row in TABLE1 for r in ratio_range(row[0]))
    # (4,000,000 steps at 1e-4; steps per strain grow as p^-1/2, the cap with them)
    return Plan("paper", pts, max_shear={10_000: 80_000.0}, p_ref=PRESSURES[0])


def quick_plan() -> Plan:
    """Minutes on two cores: N = 500, mu_s = 0.3, five ratios (the lowest may end without
    the data for an SE of phi: four to fit), REPLICAS seeds, SE target 2 %."""
    pts = tuple(Point(0.3, r, seed, N=500) for r in (0.45, 0.5, 0.525, 0.55, 0.6)
                for seed in range(1, REPLICAS + 1))
    # (stints of 50,000 steps, at most 300,000: phi's slow mode, ~100-200 t_c at N = 500,
    # needs 10 blocks of 2 tau for an SE)
    return Plan("quick", pts, se_target=0.02, max_shear={500: 6_000.0}, stint=1_000.0,
                min_length=4_000.0)


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
