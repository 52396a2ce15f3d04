"""The seed-coverage study (granflow.studies.seed_coverage), a campaign on the engine: seeds of
one cell point at a fixed length, their spread against their SEs, and its report."""

from __future__ import annotations

import math

import polars as pl
import pytest
from granflow.studies import seed_coverage as sc

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    out = tmp_path_factory.mktemp("seeds")
    plan = sc.seed_plan("test", 4, 300, 0.5, 2000.0)
    sc.run_campaign(plan, out, workers=1, log=lambda *_: None)
    return plan, out


def test_every_seed_runs_the_same_length_and_the_ratio_is_measured(small):
    plan, out = small
    pts = pl.read_parquet(out / "points.parquet")
    assert sorted(pts["seed"].to_list()) == [1, 2, 3, 4]
    assert set(pts["shear_steps"].to_list()) == {100_000}  # 2000 t_c at dt = 0.02 t_c
    assert not pts["converged"].any()  # (no SE target: every seed runs the whole length)
    flowing = int((pts["state"] == "flowing").sum())
    assert flowing >= 3
    cov = sc.coverage(pts)
    assert cov["observable"].to_list() == list(sc.SHOWN)
    assert (cov["seeds"] == flowing).all()
    for r in cov.iter_rows(named=True):
        assert math.isclose(r["band_hi"] - 1, 1.96 / math.sqrt(2 * (flowing - 1)))
        if math.isnan(r["rms_se"]):
            # (2000 t_c is under 10 blocks of phi's slow mode: no SE, so no ratio)
            assert math.isnan(r["ratio"]) and r["observable"] == "phi"
            continue
        assert r["ratio"] == pytest.approx(r["spread"] / r["rms_se"])
        assert 0 < r["ratio"] < 5
    rms, ok = sc.verdict(cov)
    assert ok == (sc.BAND[0] <= rms <= sc.BAND[1])


def test_reanalyse_reproduces_the_points_and_the_report_says_the_verdict(small):
    plan, out = small
    before = pl.read_parquet(out / "points.parquet")
    assert sc.reanalyse(out, plan) == 0
    assert pl.read_parquet(out / "points.parquet").equals(before)
    text = sc.write_report(out, out / "report.md", plan).read_text()
    assert "| I | " in text and ("PASS" in text or "FAIL" in text)
    assert "100,000 steps of shear" in text


def test_the_command_refuses_two_modes():
    with pytest.raises(SystemExit):
        sc.main(["--quick", "--full"])
