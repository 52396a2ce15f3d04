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


def _lammps_table(mu_s: float, inertial: float) -> pl.DataFrame:
    """A benchmarks/lammps_rate_cell.py table.parquet of one point (every quantity agrees)."""
    rows = [{"mu_s": mu_s, "I": inertial, "quantity": q, "granflow": 0.5, "granflow_se": 0.01,
             "lammps": 0.51, "lammps_se": 0.01, "z": -0.71, "verdict": "agrees",
             "replicas_granflow": 3, "replicas_lammps": 3}
            for q in ("mu", "phi", "N1_p", "N2_p", "syy_pext")]
    return pl.from_dicts(rows)


def test_the_protocol_section_shows_each_pressure_and_the_codes_shift(tmp_path):
    """The LAMMPS tables at both pressures and the shift table enter the report section; a
    shift both codes make beyond 2 SEs is named, one where they part is counted apart."""
    from granflow.studies.reproduce_002_report import protocol_checks

    out = tmp_path / "reproduce_002"
    out.mkdir()
    assert protocol_checks(out) == []  # nothing beside the dataset: no section
    high, low = tmp_path / "lammps_rate_cell", tmp_path / "lammps_rate_cell_p1e-5"
    high.mkdir()
    low.mkdir()
    _lammps_table(0.0, 0.05).write_parquet(high / "table.parquet")
    _lammps_table(0.0, 0.05).write_parquet(low / "table.parquet")
    pl.from_dicts([
        {"mu_s": 0.0, "I": 0.05, "quantity": "phi", "shift_granflow": 0.003,
         "shift_granflow_se": 0.0003, "z_granflow": 10.0, "shift_lammps": 0.0028,
         "shift_lammps_se": 0.0003, "z_lammps": 9.3, "codes_z": 0.47, "codes": "shift alike"},
        {"mu_s": 0.0, "I": 0.05, "quantity": "mu", "shift_granflow": 0.004,
         "shift_granflow_se": 0.001, "z_granflow": 4.0, "shift_lammps": -0.001,
         "shift_lammps_se": 0.001, "z_lammps": -1.0, "codes_z": 3.5, "codes": "shift apart"},
    ]).write_parquet(low / "shift.parquet")
    text = "\n".join(protocol_checks(out))
    assert "granflow against LAMMPS at p_ext = 1e-04" in text
    assert "granflow against LAMMPS at p_ext = 1e-05" in text
    assert "--p-ext 1e-05 --mu 0 --I 0.05 --seeds 1 2 3 --only-table" in text
    assert "phi at mu_s = 0, I = 0.05 (+0.0030 and +0.0028)" in text  # both codes moved
    assert "mu at mu_s = 0, I = 0.05" not in text  # only granflow moved: not named
    assert "agree within 2 combined SEs in 1 of 2" in text
    assert "| shift apart |" in text
