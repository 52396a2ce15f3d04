"""The 002 campaign's machinery (granflow.studies.reproduce_002) on its --quick plan: points run
until their SE targets, are appended as they finish, are skipped when run again, and the report
gives the Table 1 rows, the figures and the cost."""

from __future__ import annotations

import math

import polars as pl
import pytest
from granflow.analysis.coverage import coverage, steady_rows
from granflow.studies import reproduce_002 as rp
from granflow.studies._campaign.cell import long_enough
from granflow.studies.reproduce_002_report import write_report

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("r002")
    plan = rp.quick_plan()
    rp.run_campaign(plan, out, workers=1, log=lambda *_: None)
    return plan, out


def test_points_reach_their_se_targets_and_are_kept(quick):
    plan, out = quick
    d = pl.read_parquet(out / "points.parquet")
    assert sorted(d["tau_ratio"].to_list()) == sorted(p.tau_ratio for p in plan.points)
    assert d.group_by("tau_ratio").len()["len"].min() == rp.REPLICAS
    for r in d.iter_rows(named=True):
        assert r["state"] not in ("runaway", "failed", "short"), r
        assert isinstance(r["converged"], bool)
        assert r["converged"] or r["shear_steps"] >= plan.max_steps(r["N"], r["p_ext"])
        if r["converged"]:
            # (no stop before the minimum length, whatever the SEs)
            assert long_enough(r, plan) and r["T_avg_tc"] >= plan.min_length_at(r["p_ext"])
            for k, t in plan.targets().items():
                assert r[f"{k}_se"] <= t * abs(r[k])
            assert 2 * r["shear_rate"] * r["T_avg"] >= plan.min_strain
        assert r["wall_seconds"] > 0 and math.isfinite(r["I"])
    # a faster flow at a larger stress ratio, and a looser packing (002 figs. 3, 6): the
    # replica means
    m = d.group_by("tau_ratio").agg(pl.col("I").mean(), pl.col("phi").mean()).sort("tau_ratio")
    assert m["I"].is_sorted() and m["phi"].is_sorted(descending=True)
    se = pl.read_parquet(out / "se_vs_time.parquet")
    assert set(se["fraction"].to_list()) <= set(rp.SE_FRACTIONS)


def test_a_finished_point_is_not_run_again(quick):
    plan, out = quick
    said = []
    rp.run_campaign(plan, out, workers=1, log=said.append)
    assert f"{len(plan.points)} done, 0 to run" in said[0]
    assert pl.read_parquet(out / "points.parquet").height == len(plan.points)


def test_the_report_has_table1_figures_and_cost(quick):
    plan, out = quick
    path = write_report(out, out / "report.md", plan, rp.paper_plan().points)
    text = path.read_text()
    for name in ("A1", "A4", "phi_0", "a4"):
        assert f"| 0.3 | {name} |" in text
    assert "core-hours" in text and "--scheduler" in text
    # the coverage audit, the curve comparison and the stop rule, from the data
    assert "## Coverage" in text and "python -m granflow.analysis.coverage" in text
    c = coverage(steady_rows(pl.read_parquet(out / "points.parquet")),
                 ["mu_s", "N", "p_ext", "tau_ratio"], ["I"]).row(0, named=True)
    assert c["pairs"] >= 3 and f"| I | {c['points']} | {c['pairs']} | {c['dof']} |" in text
    assert "curves agree" in text and "**The stop rule**" in text
    figs = sorted((out / "report_figures").glob("*.png"))
    assert len(figs) == 7 and all(f.stat().st_size > 10_000 for f in figs)
    for f in figs:
        assert f"report_figures/{f.name}" in text
