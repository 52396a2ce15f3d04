"""Predict the channel of 000 from the cell of 002: a local mu(I), phi(I) law and the nonlocal
granular fluidity model (Henann & Kamrin 2013), calibrated in the cell with the channel's
material (stress-controlled, and rate-controlled below its arrest), laid over the channel's
DEM profiles at several widths.

    python -m granflow.studies.cross_scene --quick [--out DIR] [--report FILE]
    python -m granflow.studies.cross_scene --full [--out DIR] [--report FILE] [--workers N]
           [--threads T]
           [--channel DIR] [--reanalyse] [--only-report]

This module is the command and the calibration campaign's plans; the
analysis is :mod:`granflow.continuum.calibration` and :mod:`granflow.continuum.channel_model`,
the report :mod:`granflow.studies.cross_scene_report`. The chain: (1) the calibration campaign,
cell runs (granflow.studies._campaign.cell: reproduce_002's points and stop rule) with the
channel's particles and contact law (_campaign.cell.channel_material) at the channel's pressure
scale,
appended point by point to ``OUT/points.parquet`` (resumable); (2) fits of mu(I) and phi(I) in
the channel's variables (rheology.gradient_frame) with their covariance, ``OUT/fits.parquet``;
(3) the continuum solutions (granflow.continuum) for every steady channel run of the
reproduce_000 dataset (``--channel``, default the committed docs/data/reproduce_000), the
nonlocal amplitude fitted on one width only; (4) the report (cross_scene_report), with the
comparison tables also written beside the points (cases,
compare, model_profiles, residuals, boundary).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

from granflow.analysis.rheology import GRADIENT_COLUMNS

from ._campaign.cell import OBSERVABLES, Plan, Point, channel_material

#: the channel's particle friction (its material's: 000's mu = 0.5), the cell points' mu_s
MU_CHANNEL = channel_material().mu_value
#: the channel's pressure scale, sigma_xx d/kn: 1.7e-4 (W = 20) to 5.3e-4 (W = 60) in the
#: reproduce_000 runs at kn = 1e5; the cell's p_ext a/kn (kn = 1 there) at both ends
P_LOW, P_HIGH = 2e-4, 5e-4
#: tau/p from below yield to runaway (a ratio that arrests or runs away is kept as such)
RATIOS = (0.38, 0.40, 0.42, 0.44, 0.46, 0.48, 0.50, 0.55, 0.60, 0.65, 0.675, 0.70, 0.75)
#: near yield, where N = 2000 creeps intermittently or arrests: more seeds, and N = 10,000
NEAR_YIELD = (0.40, 0.405, 0.41, 0.415)
NEAR_YIELD_LARGE = (0.40, 0.41, 0.42)
#: below 0.40 at N = 10,000 (N = 2000 arrests at 0.38 and, for some seeds, at 0.40): does a
#: larger cell hold a slower steady flow? (run last)
BELOW_YIELD_LARGE = (0.39, 0.395, 0.385, 0.38)
#: the rate-controlled cell's I (002's, RateCell's parameter), fastest first: from inside
#: the stress-controlled range (0.02: the two drives overlap) down to the channel's slowest
#: dense flows (1e-4), where the stress-controlled cell arrests. Its times grow as 1/I below
#: Plan.rate_I_ref (the same strain): at 5e-4 one run at 1e-4 is ~2e7 steps, ~45 min
RATE_I = (0.02, 0.01, 3e-3, 1e-3, 3e-4, 1e-4)


#: observables kept per calibration point
CAL_OBSERVABLES = (*OBSERVABLES, *GRADIENT_COLUMNS, "sigma_yy")


def _plan(name: str, points: Iterable[Point], stint_steps: int,
          max_shear_steps: Mapping[int, int], **kw: Any) -> Plan:
    """A calibration plan with its stint and budgets given in steps (the channel's dt, the
    calibration's committed stints), as the plan's contact times."""
    mat = channel_material()
    f = Plan(name, (), material=mat).dt
    return Plan(name, tuple(dict.fromkeys(points)), material=mat,
                observables=CAL_OBSERVABLES, stint=stint_steps * f,
                max_shear={n: s * f for n, s in max_shear_steps.items()}, **kw)


#: independent seeds per calibration point of the full plan (a point's SE from the spread
#: between replicas as well as from each run's own)
SEEDS = (1, 2, 3)


def full_plan() -> Plan:
    """N = 2000 over RATIOS at p a/kn = 2e-4 and 5e-4, then near yield NEAR_YIELD at 2e-4,
    then the rate-controlled cell over RATE_I at 5e-4 (the wider channels' stress) and at
    2e-4, then NEAR_YIELD_LARGE at N = 10,000 (p = 2e-4), NEAR_YIELD at 5e-4 and
    BELOW_YIELD_LARGE at N = 10,000: every point with the seeds SEEDS, seed by seed within each
    stage. A resumed campaign skips the runs its dataset holds (the committed one: seeds 1-2
    over RATIOS, 1-3 near yield at N = 2000, seed 1 at N = 10,000)."""
    pts = [Point(MU_CHANNEL, r, s, p_ext=p) for s in SEEDS for p in (P_LOW, P_HIGH)
           for r in RATIOS]
    pts += [Point(MU_CHANNEL, r, s, p_ext=P_LOW) for s in SEEDS for r in NEAR_YIELD]
    pts += [Point(MU_CHANNEL, 0.0, s, p_ext=p, inertial_number=i) for p in (P_HIGH, P_LOW)
            for s in SEEDS for i in RATE_I]
    pts += [Point(MU_CHANNEL, r, s, N=10_000, p_ext=P_LOW) for s in SEEDS
            for r in NEAR_YIELD_LARGE]
    pts += [Point(MU_CHANNEL, r, s, p_ext=P_HIGH) for s in SEEDS for r in NEAR_YIELD]
    pts += [Point(MU_CHANNEL, r, s, N=10_000, p_ext=P_LOW) for s in SEEDS
            for r in BELOW_YIELD_LARGE]
    # (a rate point's stint, budget and floor grow as Plan.rate_I_ref / I below it)
    return _plan("full", pts, stint_steps=20_000,
                 max_shear_steps={2000: 1_000_000, 10_000: 400_000})


def quick_plan() -> Plan:
    """Minutes on two cores: N = 500, five ratios, one seed, SE target 2 %; a smoke test of
    the chain, so without the full plans' minimum length (its runs are too short for it)."""
    pts = [Point(MU_CHANNEL, r, 1, N=500, p_ext=P_LOW) for r in (0.45, 0.5, 0.55, 0.6, 0.65)]
    return _plan("quick", pts, se_target=0.02, stint_steps=10_000,
                 max_shear_steps={500: 100_000}, min_length=0.0, min_taus=0.0)


# --------------------------------------------------------------------------------------------
# (4) the command
# --------------------------------------------------------------------------------------------
#: the channel dataset the study predicts (the committed reproduce_000 campaign)
CHANNEL_DATA = "docs/data/reproduce_000"


def main(argv: Iterable[str] | None = None) -> None:
    from granflow.studies.cross_scene_report import write_report

    from ._campaign import cli
    from ._campaign.cell import reanalyse, run_campaign

    cli(argv, module="granflow.studies.cross_scene", description=(__doc__ or "").splitlines()[0],
        plans={"quick": (quick_plan, "minutes-long calibration subset (default)"),
               "full": (full_plan, "the calibration campaign")},
        reanalyse=reanalyse, run_campaign=run_campaign, write_report=write_report,
        options={"channel": (CHANNEL_DATA, "the reproduce_000 dataset to predict"),
                 "tables": ("", "where the comparison's tables go (default: OUT, beside the "
                            "calibration)")})


if __name__ == "__main__":
    main()
