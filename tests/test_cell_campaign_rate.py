"""Rate-controlled points in the cell campaign (granflow.studies._campaign.cell): the point, its
scene, its times in strain below the plan's rate_I_ref, a short run to a row, datasets written
before the field existed, and the calibration that pools them apart from the stress points."""

from __future__ import annotations

import math

import numpy as np
import polars as pl
import pytest
from granflow.continuum.calibration import continuation_check, pooled_points
from granflow.errors import ParameterError
from granflow.scenes import RateCell
from granflow.scenes.cell import ShearCell
from granflow.studies._campaign.cell import STUDY, Plan, Point, channel_material
from granflow.studies._campaign.engine import point_of, run_point, with_defaults, write_rows
from granflow.studies.cross_scene import RATE_I, full_plan


def test_a_point_is_stress_or_rate_controlled_not_both():
    assert Point(0.3, 0.45, 1).key == "mu0.3_N2000_p0.0001_tau0.45_s1"  # (as committed)
    assert Point(0.3, 0.0, 2, inertial_number=1e-4).key == "mu0.3_N2000_p0.0001_I0.0001_s2"
    for tau, i in ((0.45, 1e-3), (0.0, 0.0), (-0.1, 0.0), (0.0, -1e-3)):
        with pytest.raises(ParameterError, match="tau_ratio .* inertial_number"):
            Point(0.3, tau, 1, inertial_number=i)


def test_the_study_builds_the_rate_cell_with_the_plans_normal():
    plan = Plan("t", (), rate_normal="yy", sample_every=100, rate_I_ref=0.01)
    rate = STUDY.scene(Point(0.3, 0.0, 1, N=200, inertial_number=1e-3), plan, 1)
    assert isinstance(rate, RateCell)
    assert (rate.inertial_number, rate.normal, rate.sample_every) == (1e-3, "yy", 1000)
    stress = STUDY.scene(Point(0.3, 0.45, 1, N=200), plan, 1)
    assert type(stress) is ShearCell and stress.sample_every == 100


def test_slow_rate_points_take_the_same_strain_as_the_reference_rate():
    plan = Plan("t", (), p_ref=1e-4, rate_I_ref=0.01)
    ref = plan.max_steps(2000, 1e-4, 0.01)
    assert plan.max_steps(2000, 1e-4, 1e-4) == 100 * ref  # strain per step goes as I
    assert plan.max_steps(2000, 1e-4, 0.05) == ref == plan.max_steps(2000, 1e-4)
    assert plan.stint_steps(1e-6, 1e-3) == 10 * 10 * plan.stint_steps(1e-4)
    assert math.isclose(plan.min_length_at(1e-4, 1e-3), 10 * plan.min_length)


def test_the_full_calibration_plan_runs_every_rate_with_three_seeds():
    rate = [p for p in full_plan().points if p.inertial_number > 0]
    assert {p.inertial_number for p in rate} == set(RATE_I) and min(RATE_I) <= 1e-4
    per = pl.DataFrame([(p.p_ext, p.inertial_number, p.seed) for p in rate],
                       schema=["p", "I", "seed"], orient="row").group_by("p", "I").len()
    assert per.height == 2 * len(RATE_I) and set(per["len"]) == {3}


def test_a_short_rate_point_runs_to_a_row_at_its_rate(tmp_path):
    plan = Plan("t", (), material=channel_material(), stint=400.0, max_shear={150: 800.0},
                min_length=0.0, min_taus=0.0, min_strain=0.0, sample_every=20,
                rate_I_ref=0.05)
    row = run_point(STUDY, Point(0.5, 0.0, 1, N=150, p_ext=5e-4, inertial_number=0.05), plan,
                    str(tmp_path))
    assert row["inertial_number"] == 0.05 and row["tau_ratio"] == 0.0
    assert row["state"] in ("flowing", "drifting") and row["shear_steps"] > 0
    # (002's I = |D| a / sqrt(p/rho) with p the measured mean pressure: the imposed rate's I
    # at p_ext, within the pressure's fluctuation)
    assert row["I"] == pytest.approx(0.05, rel=0.15)
    assert (tmp_path / "mu0.5_N150_p0.0005_I0.05_s1" / "checkpoint.gfck").exists()


def test_rows_written_before_the_field_take_its_default(tmp_path):
    f = tmp_path / "points.parquet"
    old = {"mu_s": 0.3, "tau_ratio": 0.45, "seed": 1, "N": 2000, "p_ext": 1e-4, "I": 0.08}
    write_rows(f, [old])
    new = {**old, "tau_ratio": 0.0, "inertial_number": 1e-3, "I": 1e-3}
    write_rows(f, [new], append=True, point=Point)
    d = pl.read_parquet(f)
    assert d["inertial_number"].to_list() == [0.0, 1e-3]
    assert [point_of(Point, r).key for r in d.iter_rows(named=True)] == [
        "mu0.3_N2000_p0.0001_tau0.45_s1", "mu0.3_N2000_p0.0001_I0.001_s1"]
    assert with_defaults(pl.DataFrame([old]), Point)["inertial_number"].to_list() == [0.0]


def _run(tau: float, i: float, seed: int, ig: float) -> dict[str, float | int | str | bool]:
    return {"mu_s": 0.5, "tau_ratio": tau, "inertial_number": i, "seed": seed, "N": 2000,
            "p_ext": 5e-4, "state": "flowing", "converged": True, "I_g": ig, "I_g_se": 1e-4,
            "mu_g": 0.3 + ig, "mu_g_se": 1e-3, "phi": 0.6 - ig, "phi_se": 1e-4,
            "sigma_g_p": 1.0, "sigma_g_p_se": 1e-3}


def test_the_calibration_pools_rate_points_apart_from_stress_points():
    runs = pl.DataFrame([_run(0.0, 1e-3, s, 2e-3) for s in (1, 2)]
                        + [_run(0.0, 1e-4, s, 2e-4) for s in (1, 2, 3)]
                        + [_run(0.45, 0.0, s, 0.03) for s in (1, 2)])
    pooled = pooled_points(runs).sort("I_g")
    assert pooled["replicas"].to_list() == [3, 2, 2]
    # a dataset from before rate points has no such column, and pools as before
    old = runs.filter(pl.col("inertial_number") == 0).drop("inertial_number")
    assert pooled_points(old)["replicas"].to_list() == [2]


def test_select_runs_a_piece_of_a_plan_with_its_settings():
    from granflow.studies import reproduce_000
    from granflow.studies._campaign.command import select

    plan = full_plan()
    one = select(plan, r"_I0\.001_s1$")
    assert [p.key for p in one.points] == ["mu0.5_N2000_p0.0005_I0.001_s1",
                                           "mu0.5_N2000_p0.0002_I0.001_s1"]
    assert one.max_shear == plan.max_shear and one.stint == plan.stint
    wide = select(reproduce_000.widths_plan(), "^W150_")
    assert wide.points and all(p.W == 150 for p in (*wide.points, *wide.branches, *wide.later))
    for bad in ("(", "no_such_point"):
        with pytest.raises(ParameterError, match="select"):
            select(plan, bad)


def test_select_runs_a_piece_but_reports_on_the_whole_plan(tmp_path):
    from granflow.studies._campaign.command import cli

    plan = full_plan()
    seen: dict[str, object] = {}

    def run(p, out, **kw):
        seen["run"] = p

    def report(out, path, p, **kw):
        seen["report"] = p
        return path

    cli(["--full", "--out", str(tmp_path), "--select", r"_I0\.001_s1$"], module="m",
        description="d", plans={"full": (full_plan, "")}, reanalyse=lambda o, p: 0,
        run_campaign=run, write_report=report)
    assert len(seen["run"].points) == 2  # type: ignore[attr-defined]
    # (what is left of the campaign, and its cost, are the whole plan's)
    assert seen["report"].points == plan.points  # type: ignore[attr-defined]


def _on_law(tau: float, i: float, seed: int, ig: float, shift: float = 0.0,
            rng: np.random.Generator | None = None) -> dict[str, float | int | str | bool]:
    """A steady calibration run on mu = 0.35 + 0.3 I/(I + 0.1), phi = 0.59 - 0.15 I (with
    noise of its SEs), ``shift`` added to mu."""
    r = rng or np.random.default_rng(seed)
    return {"mu_s": 0.5, "tau_ratio": tau, "inertial_number": i, "seed": seed, "N": 2000,
            "p_ext": 5e-4, "state": "flowing", "converged": True,
            "I_g": ig, "I_g_se": 0.01 * ig,
            "mu_g": 0.35 + 0.3 * ig / (ig + 0.1) + shift + r.normal(0, 1e-3), "mu_g_se": 1e-3,
            "phi": 0.59 - 0.15 * ig + r.normal(0, 3e-4), "phi_se": 3e-4,
            "sigma_g_p": 1.0, "sigma_g_p_se": 1e-3}


def test_rate_points_are_checked_against_the_stress_law_alone():
    rng = np.random.default_rng(4)
    stress = [_on_law(0.4 + 0.02 * k, 0.0, s, ig, rng=rng) for k, ig in
              enumerate((0.02, 0.04, 0.08, 0.15, 0.3, 0.5)) for s in (1, 2)]
    on = [_on_law(0.0, 1e-3, s, 0.002, rng=rng) for s in (1, 2, 3)]
    check = continuation_check(pl.DataFrame(stress + on))
    assert check["quantity"].to_list() == ["mu_g", "phi"]
    assert check["where"].to_list() == ["continuation"] * 2
    assert (check["z"].abs() < 3).all() and (check["replicas"] == 3).all()
    # a rate point 0.04 above the law (40 SEs; the four-constant continuation's band at
    # I_g = 0.002, from six stress points at 0.02-0.5, is ~0.005) is found; one inside the
    # range is "overlap"
    off = [_on_law(0.0, 1e-3, s, 0.002, shift=0.04, rng=rng) for s in (1, 2, 3)]
    mid = [_on_law(0.0, 0.02, s, 0.05, rng=rng) for s in (1, 2, 3)]
    check = continuation_check(pl.DataFrame(stress + off + mid)).filter(
        pl.col("quantity") == "mu_g").sort("I_g")
    assert check["z"][0] > 5 and abs(check["z"][1]) < 3
    assert check["where"].to_list() == ["continuation", "overlap"]
    # no rate points (or no stress points): nothing to check
    assert continuation_check(pl.DataFrame(stress)).is_empty()
