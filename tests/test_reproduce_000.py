"""The 000 campaign's machinery (granflow.studies.reproduce_000) on its --quick plan: points run
in stints until steady and converged (or t_max), a branch continues its parent's final state
at another k_n, finished points are kept and skipped when run again, and the report gives the
fig. 5 numbers, the stiffness table, the figures and the cost."""

from __future__ import annotations

import math

import numpy as np
import polars as pl
import pytest
from granflow.analysis.stats import MIN_SE_BLOCKS
from granflow.studies import reproduce_000 as rp
from granflow.studies._campaign import point_of
from granflow.studies.reproduce_000_report import write_report

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("r000")
    plan = rp.quick_plan()
    rp.run_campaign(plan, out, workers=1, log=lambda *_: None)
    return plan, out


def test_points_stop_by_the_stated_criterion(quick):
    plan, out = quick
    d = pl.read_parquet(out / "points.parquet")
    assert sorted(point_of(rp.Point, r).key for r in d.iter_rows(named=True)) == sorted(
        p.key for p in (*plan.points, *plan.branches))
    for r in d.iter_rows(named=True):
        point = point_of(rp.Point, r)
        t_max, min_average = plan.limits(point)
        # these small channels flow (a drifting one runs on to t_max)
        assert r["state"] in ("steady", "fluctuating", "drifting"), r
        # v_cm's state (000's) is kept where a drifting mean overrides the run's state
        assert r["vcm_state"] in ("steady", "fluctuating")
        assert r["state"] in ("drifting", r["vcm_state"])
        assert r["converged"] or r["t_run"] >= t_max - 1e-6
        if r["converged"]:
            # the minimum length first, then the SE targets
            assert r["state"] != "drifting" and r["drift_tested"]
            assert r["T_avg"] >= min_average and r["T_avg"] >= plan.min_taus * r["tau_max"]
            for k in ("u_slip", "u_max"):
                assert r[f"{k}_se"] <= plan.se_target * r[k]
        assert 1.0 < r["u_max_over_u_slip"] < 2.0
        # an SE from fewer than 10 jackknife blocks is not given
        assert math.isfinite(r["u_max_over_u_slip_se"]) == (
            r["n_blocks"] >= MIN_SE_BLOCKS)
        assert r["prep_seconds"] >= 0 and r["wall_seconds"] > r["prep_seconds"]
    # a denser channel flows slower (000 fig. 5)
    base = d.filter(pl.col("kn") == 1e5).sort("phi_bar")
    assert base["u_slip"][0] > base["u_slip"][1]


def test_a_branch_starts_from_its_parents_state(quick):
    plan, out = quick
    d = pl.read_parquet(out / "points.parquet")
    br = d.filter(pl.col("parent") != "").row(0, named=True)
    parent = d.filter(pl.col("parent") == "", pl.col("phi_bar") == br["phi_bar"]).row(
        0, named=True)
    assert br["kn"] == 1e6 and br["n"] == parent["n"]
    # it starts flowing: its steady part begins within a stint, not after a new development
    assert br["t_start"] < plan.stint
    prof = pl.read_parquet(out / "profiles.parquet")
    assert prof.filter(pl.col("parent") != "").height == prof.filter(
        pl.col("parent") == "", pl.col("phi_bar") == br["phi_bar"]).height


def test_a_finished_point_is_not_run_again(quick):
    plan, out = quick
    said: list[str] = []
    rp.run_campaign(plan, out, workers=1, log=said.append)
    phases = [s for s in said if "to run" in s]
    assert phases and all(s.endswith(" 0 to run") for s in phases)
    assert pl.read_parquet(out / "points.parquet").height == len(plan.points) + len(
        plan.branches)
    # every point kept a committed copy between its stints; none outlives its row
    assert (out / "progress").is_dir() and not list((out / "progress").iterdir())


def test_the_report_has_fig5_stiffness_figures_and_cost(quick):
    plan, out = quick
    path = write_report(out, out / "report.md", plan, rp.paper_plan())
    text = path.read_text()
    for head in ("## Stiffness (fig. 10)", "## Error against run time", "## Coverage audit",
                 "## Cost", "core-hours", "--scheduler", "Drifting runs"):
        assert head in text
    assert "| 12 | 0.58 |" in text
    # the fig. 5 and zone sections (7 figures) are there when a k_n = 1e5 point is steady and
    # stationary (these short runs of a 12 d channel may drift: then they are listed instead)
    d = pl.read_parquet(out / "points.parquet")
    steady = d.filter(pl.col("kn") == 1e5, pl.col("state").is_in(["steady", "fluctuating"]))
    assert ("## Fig. 5" in text) == (steady.height > 0)
    for r in d.filter(pl.col("state") == "drifting").iter_rows(named=True):
        assert f"W = 12, φ̄ = {r['phi_bar']:g}, k_n = {r['kn']:.0e}, seed 1 (" in text
    figs = sorted((out / "report_figures").glob("*.png"))
    # se_vs_time; figs 4-9 and 13 with a steady point; fig. 10 where the branch's parent is
    parent = steady.filter(pl.col("phi_bar") == plan.branches[0].phi_bar)
    assert len(figs) == 1 + (7 if steady.height else 0) + (1 if parent.height else 0)
    assert all(f.stat().st_size > 10_000 for f in figs)
    for f in figs:
        assert f"report_figures/{f.name}" in text


def test_reanalyse_keeps_finished_points(quick):
    plan, out = quick
    before = pl.read_parquet(out / "points.parquet")
    rp.reanalyse(out, plan)
    after = pl.read_parquet(out / "points.parquet")
    assert after.height == before.height
    kept = after.join(before, on=["W", "phi_bar", "kn"], suffix="_old")
    # the same tables give the same numbers
    assert (kept["u_slip"] - kept["u_slip_old"]).abs().max() == 0.0


def test_the_command_line_writes_the_report(quick, capsys):
    _, out = quick
    rp.main(["--quick", "--out", str(out), "--report", str(out / "cli.md"), "--only-report"])
    assert (out / "cli.md").exists() and "report:" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        rp.main(["--quick", "--full"])  # one mode at a time
    # --status: where the plan stands, nothing run or written
    before = sorted(p.name for p in out.iterdir())
    rp.main(["--quick", "--out", str(out), "--status"])
    said = capsys.readouterr().out
    from granflow.studies._campaign.engine import plan_points

    n = len(plan_points(rp.quick_plan()))  # (its points and its k_n branch, all finished)
    assert said.startswith(f"quick in {out}: {n} points, {n} with a row in points.parquet, "
                           "0 started"), said
    assert sorted(p.name for p in out.iterdir()) == before


def test_every_finished_point_has_its_order_across_the_channel(quick):
    plan, out = quick
    d = pl.read_parquet(out / "points.parquet")
    order = pl.read_parquet(out / "order.parquet")
    for r in d.iter_rows(named=True):
        o = order.filter(*(pl.col(c) == r[c] for c in ("W", "phi_bar", "kn", "seed")))
        # the channel's bins from wall to wall, taken at the run's last state, folded onto
        # the half profile's distance from the nearer wall
        assert o.height > 0 and (o["t"] == r["t_run"]).all()
        assert o["particles"].sum() == r["n"]
        x = o["x"].to_numpy()
        assert np.allclose(o["xi"].to_numpy(), np.minimum(x, r["W"] - x), rtol=0, atol=1e-12)
        assert o["Q6"].is_between(0.0, 1.0).all() and o["Z"].is_between(3.0, 13.0).all()
