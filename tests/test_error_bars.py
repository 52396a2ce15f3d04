"""Error bars that hold across replicas (issue 34): the stationarity test, the replica mean and
its SE, the coverage audit, and the campaign's stop rule, on synthetic data with known
answers."""

from __future__ import annotations

import math

import numpy as np
import polars as pl
import pytest
from granflow.analysis import coverage as cov
from granflow.analysis import rheology as rh
from granflow.analysis.replicas import replica_mean, small_sample_factor
from granflow.analysis.stats import DRIFT_Z, stationarity
from granflow.states import FlowState
from granflow.studies._campaign.cell import MIN_SE_BLOCKS, Plan, converged, long_enough
from scipy.signal import lfilter


def ar1(n: int, a: float, rng: np.random.Generator) -> np.ndarray:
    """A stationary AR(1) series of unit variance (started in its stationary distribution)."""
    e = rng.normal(size=n)
    e[0] /= math.sqrt(1 - a * a)
    return math.sqrt(1 - a * a) * lfilter([1.0], [1.0, -a], e)


# --------------------------------------------------------------------------------------------
# stationarity
# --------------------------------------------------------------------------------------------
def test_stationarity_catches_a_slow_drift_and_passes_a_stationary_ar1():
    n, a = 6000, 0.95  # tau ~ 20 samples: 300 correlation times in all
    flagged, zs = 0, []
    for seed in range(20):
        x = ar1(n, a, np.random.default_rng(seed))
        st = stationarity({"x": x})
        assert st.tested
        flagged += not st.stationary
        zs.append(st.z["x"])
    assert flagged <= 2  # |z| > 3 is a 0.3 % event for honest thirds' SEs
    assert 0.6 < float(np.sqrt(np.mean(np.square(zs)))) < 1.5
    # the same noise with a slow linear drift of 2 standard deviations across the run: the
    # drift is 10x the SE of the whole run's mean, which a blocking SE alone would not see
    for seed in range(5):
        x = ar1(n, a, np.random.default_rng(100 + seed)) + np.linspace(0.0, 2.0, n)
        st = stationarity({"flat": ar1(n, a, np.random.default_rng(seed)), "drift": x})
        assert not st.stationary and st.worst == "drift" and st.max_abs_z > DRIFT_Z


def test_stationarity_of_a_short_series_is_not_tested():
    st = stationarity({"x": np.arange(20.0)})
    assert not st.tested and not st.stationary and math.isnan(st.max_abs_z)
    with pytest.raises(ValueError):
        stationarity({})


def test_a_flowing_cell_run_that_drifts_is_drifting():
    rng = np.random.default_rng(4)
    n = 4000
    t = np.arange(n, dtype=float)
    base = {"t": t, "step": np.arange(n), "shear_rate": 0.1 * (1 + 0.05 * ar1(n, 0.8, rng)),
            "L_xy": 0.1 * (1 + 0.05 * ar1(n, 0.8, rng)), "mu1": 0.4 + 0.01 * ar1(n, 0.8, rng),
            "mu2": 0.1 + 0.01 * ar1(n, 0.8, rng), "I": 0.3 + 0.01 * ar1(n, 0.8, rng),
            "p": 1e-4 * (1 + 0.01 * ar1(n, 0.8, rng))}
    steady = {**base, "phi": 0.5 + 0.002 * ar1(n, 0.8, rng)}
    st = rh.classify_run(steady, start=0)
    assert st.state is FlowState.FLOWING and st.drift_z < DRIFT_Z
    # phi creeps down by 0.01 (5 of its standard deviations) over the run: a slow dilation
    drifting = {**base, "phi": steady["phi"] - np.linspace(0.0, 0.01, n)}
    st = rh.classify_run(drifting, start=0)
    assert st.state is FlowState.DRIFTING and st.drift_quantity == "phi"
    assert not st.averaged and not st.state.is_steady


# --------------------------------------------------------------------------------------------
# replicas
# --------------------------------------------------------------------------------------------
def test_replica_se_is_right_for_replicas_of_known_variance():
    rng = np.random.default_rng(7)
    sigma, k, groups = 0.3, 3, 4000
    x = rng.normal(1.0, sigma, size=(groups, k))
    d = pl.DataFrame({"point": np.repeat(np.arange(groups), k), "x": x.ravel(),
                      "x_se": np.full(groups * k, sigma)})
    r = replica_mean(d, ["point"], ["x"])
    assert r.height == groups and (r["replicas"] == k).all()
    # the within SE: sigma / sqrt(k) exactly (honest run SEs)
    assert np.allclose(r["x_se_within"].to_numpy(), sigma / math.sqrt(k))
    # the between SE with the small-sample factor is a 68.3 % interval (Student, k - 1 dof)
    hit = np.abs(r["x"].to_numpy() - 1.0) <= r["x_se_between"].to_numpy()
    assert abs(hit.mean() - 0.6827) < 0.025
    assert small_sample_factor(3) == pytest.approx(1.3213, abs=1e-3)
    # the point's SE is the larger; a replica without an SE leaves the point without one
    assert (r["x_se"] >= r["x_se_within"]).all() and (r["x_se"] >= r["x_se_between"]).all()
    d2 = pl.DataFrame({"point": [0, 0, 0], "x": [1.0, 2.0, 3.0], "x_se": [0.1, math.nan, 0.1]})
    assert math.isnan(replica_mean(d2, ["point"], ["x"])["x_se"][0])


def test_replica_se_shows_run_errors_that_are_too_small():
    rng = np.random.default_rng(8)
    x = rng.normal(0.0, 1.0, size=(2000, 3))
    d = pl.DataFrame({"point": np.repeat(np.arange(2000), 3), "x": x.ravel(),
                      "x_se": np.full(6000, 0.25)})  # 4x too small
    r = replica_mean(d, ["point"], ["x"])
    # (the median between SE ~ 0.83 sigma x 1.32 / sqrt 3 ~ 0.63 against within 0.144)
    assert float(r["x_se"].median()) > 3 * float(r["x_se_within"].median())


# --------------------------------------------------------------------------------------------
# coverage
# --------------------------------------------------------------------------------------------
def _replicas(groups: int, k: int, true_sd: float, reported: float, seed: int) -> pl.DataFrame:
    rng = np.random.default_rng(seed)
    return pl.DataFrame({
        "mu_s": np.repeat(np.arange(groups) * 0.1, k), "seed": np.tile(np.arange(1, k + 1), groups),
        "state": ["flowing"] * (groups * k), "I": rng.normal(0.1, true_sd, groups * k),
        "I_se": np.full(groups * k, reported)})


def test_coverage_is_one_for_honest_errors_and_finds_small_ones():
    honest = cov.coverage(_replicas(200, 3, 0.01, 0.01, 1), ["mu_s"], ["I"]).row(0, named=True)
    assert honest["pairs"] == 600 and honest["dof"] == 400 and honest["points"] == 200
    assert honest["rms_z_lo"] < 1.0 < honest["rms_z_hi"]
    small = cov.coverage(_replicas(200, 3, 0.03, 0.01, 2), ["mu_s"], ["I"]).row(0, named=True)
    assert small["rms_z_lo"] > 2.5
    # few pairs: a wide interval
    few = cov.coverage(_replicas(3, 2, 0.01, 0.01, 3), ["mu_s"], ["I"]).row(0, named=True)
    assert few["dof"] == 3 and few["rms_z_hi"] / few["rms_z_lo"] > 3


def test_coverage_counts_only_steady_replicas_and_has_a_command(tmp_path, capsys):
    d = _replicas(10, 3, 0.01, 0.01, 4).with_columns(
        pl.when(pl.col("seed") == 3).then(pl.lit("drifting")).otherwise(pl.col("state"))
        .alias("state"))
    steady = cov.steady_rows(d)
    assert steady.height == 20 and set(steady["state"].to_list()) == {"flowing"}
    one = cov.coverage(steady, ["mu_s"], ["I"]).row(0, named=True)
    assert one["pairs"] == 10 and one["dof"] == 10
    d.write_parquet(tmp_path / "points.parquet")
    tab = cov.main([str(tmp_path), "--by", "mu_s", "--observables", "I"])
    assert tab["pairs"][0] == 10 and "rms_z" in capsys.readouterr().out


def test_coverage_names_the_worst_pair_by_the_fields_that_differ():
    d = _replicas(5, 2, 0.01, 0.01, 5).with_columns(pl.lit(0.0).alias("inertial_number"))
    d = d.with_columns(pl.when((pl.col("mu_s") > 0.35) & (pl.col("seed") == 2))
                       .then(pl.col("I") + 1.0).otherwise(pl.col("I")).alias("I"))
    worst = cov.coverage(d, ["mu_s", "inertial_number"], ["I"])["worst"][0]
    # a field all points share says nothing; the one that tells them apart names the pair
    assert worst == "mu_s 0.4 (seeds 1, 2)"
    one = cov.coverage(d.filter(pl.col("mu_s") > 0.35), ["mu_s", "inertial_number"], ["I"])
    assert one["worst"][0] == "mu_s 0.4, inertial_number 0 (seeds 1, 2)"


# --------------------------------------------------------------------------------------------
# the stop rule
# --------------------------------------------------------------------------------------------
def test_the_stop_rule_refuses_to_stop_before_its_minimum_length():
    plan = Plan("t", (), min_length=1000.0, min_taus=20.0, min_strain=2.0)

    def row(t_tc: float, **kw: object) -> dict[str, object]:
        # (kernel time = 2 t_c: T_avg and tau_max in kernel time, the floor in t_c)
        return {"state": "flowing", "p_ext": 1e-4, "T_avg": 2.0 * t_tc, "T_avg_tc": t_tc,
                "tau_max": 10.0,
                "shear_rate": 0.1, "mu1": 0.4, "mu1_se": 1e-6, "phi": 0.5, "phi_se": 1e-6,
                "I": 0.1, "I_se": 1e-6, **kw}

    assert not long_enough(row(900.0), plan) and not converged(row(900.0), plan)  # too short
    assert converged(row(1000.0), plan)
    # the slowest quantity's correlation time, not the fixed floor, sets the length
    assert not converged(row(1500.0, tau_max=200.0), plan)  # 3000 < 20 x 200
    assert converged(row(2000.0, tau_max=200.0), plan)
    # ... and only then the SE targets; a drifting run never stops on them
    assert not converged(row(2000.0, mu1_se=0.1), plan)
    assert not converged(row(5000.0, state="drifting"), plan)
    assert not converged(row(5000.0, tau_max=math.nan), plan)


def test_a_plan_given_at_one_pressure_scales_its_times_with_the_inertial_time():
    plan = Plan("t", (), min_length=1000.0, min_taus=20.0, min_strain=2.0, stint=100.0,
                max_shear={2000: 5000.0}, p_ref=1e-4)
    # (dt = 0.02 t_c: 50 steps per t_c)
    assert plan.stint_steps(1e-4) == 5000 and plan.max_steps(2000, 1e-4) == 250_000
    assert plan.stint_steps(1e-6) == 50_000 and plan.max_steps(2000, 1e-6) == 2_500_000
    assert plan.min_length_at(1e-5) == pytest.approx(1000.0 * math.sqrt(10.0))
    row = {"state": "flowing", "T_avg": 2e4, "T_avg_tc": 1e4, "tau_max": 10.0,
           "shear_rate": 0.1}
    assert long_enough({**row, "p_ext": 1e-6}, plan)  # 10,000 t_c >= 10 x 1000
    assert not long_enough({**row, "p_ext": 1e-6, "T_avg_tc": 9000.0}, plan)
    # without p_ref the times are the same t_c at every pressure
    flat = Plan("t", (), min_length=1000.0, stint=100.0, max_shear={2000: 5000.0})
    assert flat.stint_steps(1e-6) == 5000 and flat.max_steps(2000, 1e-6) == 250_000
    assert flat.min_length_at(1e-6) == 1000.0


def test_no_se_from_fewer_than_ten_blocks():
    from granflow.studies._campaign.cell import _analyse

    rng = np.random.default_rng(5)
    n = 3000
    t = np.arange(n, dtype=float)
    s = pl.DataFrame({"t": t, "step": np.arange(n), "L_xy": 0.1 + 0.001 * ar1(n, 0.5, rng),
                      "shear_rate": 0.1 + 0.001 * ar1(n, 0.5, rng),
                      "mu1": 0.4 + 0.01 * ar1(n, 0.5, rng),
                      # a quantity correlated over ~300 samples: ~5 blocks of 2 tau in 3000
                      "phi": 0.5 + 0.002 * ar1(n, math.exp(-1 / 300), rng)})
    row = _analyse(s, ("mu1", "phi"))
    assert math.isfinite(row["mu1_se"]) and row["T_avg"] >= 2 * MIN_SE_BLOCKS * row["mu1_tau"]
    assert row["T_avg"] < 2 * MIN_SE_BLOCKS * row["phi_tau"] and math.isnan(row["phi_se"])
    assert row["tau_max"] == pytest.approx(row["phi_tau"])


# --------------------------------------------------------------------------------------------
# the 002 report's comparisons
# --------------------------------------------------------------------------------------------
def _paper_pool(shift: float, p_ext: float = 1e-4, lo: float = 0.01,
                noise: np.random.Generator | None = None) -> pl.DataFrame:
    """Replica means at mu_s = 0.3 on 002's curves (mu1 shifted by ``shift``), SE 0.002
    (0.0005 for phi), at ``p_ext``, I from ``lo`` to 0.4; scattered by their SEs with
    ``noise``."""
    inum = np.geomspace(lo, 0.4, 8)
    row: dict[str, object] = {"mu_s": 0.3, "N": 2000, "p_ext": p_ext,
                              "tau_ratio": np.linspace(0.4, 0.6, 8), "I": inum,
                              "I_se": 1e-4 * inum}
    for law in ("mu1", "mu2", "mu3", "phi"):
        y = rh.reference_curve(law, inum, 0.3, offset=0.01 if law == "mu3" else None)
        se = 0.002 if law != "phi" else 0.0005
        row[law] = (y + (shift if law == "mu1" else 0.0)
                    + (noise.normal(0.0, se, 8) if noise is not None else 0.0))
        row[f"{law}_se"] = np.full(8, se)
    return pl.DataFrame(row)


def test_the_curve_comparison_and_the_printed_precision():
    from granflow.studies import reproduce_002_report as rep

    same = _paper_pool(0.0)
    cmp = rep.curve_comparison(same, rep.fits_by_mu(same))
    assert set(cmp["law"].to_list()) == {"(4.2) mu1", "(4.4) mu2", "(4.7) phi"}
    assert (cmp["verdict"] == "agrees").all() and cmp["largest |ours - paper|"].max() < 0.002
    off = _paper_pool(0.03)
    cmp = rep.curve_comparison(off, rep.fits_by_mu(off)).filter(pl.col("law") == "(4.2) mu1")
    assert cmp["verdict"][0].startswith("differs")
    assert cmp["largest |ours - paper|"][0] == pytest.approx(0.03, abs=0.003)
    # phi_0 = 0.63 as printed stands for 0.625-0.635: 0.634 +- 0.001 agrees with it
    assert rh.printed_unit("phi_0") == 0.01 and rh.printed_unit("A1") == 0.001
    rows = rep.table_rows(rep.fits_by_mu(same))
    assert rows.filter(pl.col("parameter") == "phi_0")["verdict"][0] == "agrees"
    with pytest.raises(KeyError):
        rh.printed_unit("nope")


def test_the_laws_are_fitted_over_every_pressure_and_the_collapse_is_tested():
    from granflow.studies import reproduce_002_report as rep

    rng = np.random.default_rng(3)
    one = _paper_pool(0.0, noise=rng)
    assert not rep.collapse(one).height  # one pressure: nothing to test
    both = pl.concat([one, _paper_pool(0.0, p_ext=1e-5, lo=0.003, noise=rng)])
    fits = rep.fits_by_mu(both)
    assert fits[0.3]["mu1"].n == 16  # (both pressures in one fit, as 002)
    tab = rep.collapse(both)
    assert set(tab["p_ext"].to_list()) == {1e-4, 1e-5}
    assert set(tab["law"].to_list()) == set(rep.COLLAPSE_LAWS)
    assert (tab["verdict"] == "collapses").all(), tab
    # mu1 at the lower pressure 0.01 above the others' curve (5 SEs of a point): apart, by
    # the F test (the per-pressure mean residuals say so too here: same I range)
    apart = pl.concat([one, _paper_pool(0.01, p_ext=1e-5, lo=0.003, noise=rng)])
    tab = rep.collapse(apart)
    mu1 = tab.filter(pl.col("law") == "mu1")
    assert all(v.startswith("apart") for v in mu1["verdict"]), mu1
    assert (tab.filter(pl.col("law") != "mu1")["verdict"] == "collapses").all(), tab
    z = dict(zip(mu1["p_ext"].to_list(), mu1["z"].to_list(), strict=True))
    assert z[1e-5] > 2 and z[1e-4] < -2
    assert "## Pressure collapse" in rep.collapse_section(apart, 2000)[0]


def test_the_collapse_at_the_same_imposed_stress():
    """The law-free test: the same tau/p at two pressures, I 6 % lower at the lower one is
    apart (SE of I 0.01 %), mu1 on the same curve collapses; one pressure: nothing to test."""
    from granflow.studies import reproduce_002_report as rep

    rng = np.random.default_rng(5)
    one = _paper_pool(0.0, noise=rng)
    assert not rep.matched_stress(one)[0].height
    same = pl.concat([one, _paper_pool(0.0, p_ext=1e-5, noise=rng)])
    pairs, tests = rep.matched_stress(same)
    assert pairs.height == 8 and set(pairs["p_ext"].to_list()) == {1e-5}
    assert (tests["verdict"] == "collapses").all(), tests
    slower = pl.concat([one, _paper_pool(0.0, p_ext=1e-5, noise=rng).with_columns(
        pl.col("I") * 0.94)])
    pairs, tests = rep.matched_stress(slower)
    assert pairs["dI/I"].to_numpy() == pytest.approx(-0.06)
    verdict = dict(zip(tests["quantity"].to_list(), tests["verdict"].to_list(), strict=True))
    assert verdict["I"].startswith("apart") and verdict["mu1"] == "collapses", tests
    text = "\n".join(rep.collapse_section(slower, 2000))
    assert "At the same imposed stress" in text and "apart are I at mu_s = 0.3" in text


def test_the_size_effect_table_writes_a_dash_for_a_missing_se():
    """The N = 10,000 point beside its N = 2000 state: value ± SE at fixed decimals and the
    difference in combined SEs; a point without an SE shows its value alone and '-' for the
    difference, never NaN; no N = 10,000 point, no section."""
    from granflow.studies import reproduce_002_report as rep

    def row(n: int, i: float, i_se: float) -> dict[str, float | int]:
        return {"mu_s": 0.3, "p_ext": 1e-4, "tau_ratio": 0.5, "N": n, "I": i, "I_se": i_se,
                "phi": 0.562, "phi_se": 0.0001}

    assert rep.size_effect_lines(pl.from_dicts([row(2000, 0.13, 0.0006)]), 2000) == []
    text = "\n".join(rep.size_effect_lines(
        pl.from_dicts([row(2000, 0.1298, 0.0006), row(10_000, 0.1305, 0.0004)]), 2000))
    assert "| 0.1298 ± 0.0006 | 0.1305 ± 0.0004 | 0.5620 ± 0.0001 |" in text
    assert "| 1.0 | 0.0 |" in text  # (0.1305 - 0.1298) / sqrt(0.0006^2 + 0.0004^2)
    text = "\n".join(rep.size_effect_lines(
        pl.from_dicts([row(2000, 0.1298, 0.0006), row(10_000, 0.1305, float("nan"))]), 2000))
    assert "| 0.1305 |" in text and "| - |" in text and "nan" not in text.lower()


def test_the_shared_slow_mode_is_in_the_se():
    """x = large fast noise + a slow mode that the reference carries almost alone (I and phi
    in the cell): x's own blocking SE misses the slow share, the shared-mode SE has it."""
    from granflow.analysis.stats import blocking_many, shared_mode_se

    rng = np.random.default_rng(11)
    reps, n = 300, 4000
    means, own, shared = [], [], []
    for _ in range(reps):
        slow = ar1(n, math.exp(-1 / 400), rng)  # tau 400 samples: 10 in the run
        ref = slow + 0.1 * ar1(n, 0.5, rng)
        x = 20.0 * ar1(n, 0.3, rng) - slow  # (the slow share: 1/400 of x's variance)
        means.append(x.mean())
        own.append(blocking_many(x).se[0])
        shared.append(shared_mode_se(x, ref)[0][0])
    spread = float(np.std(means, ddof=1))
    ratio_own = spread / math.sqrt(np.mean(np.square(own)))
    ratio_shared = spread / math.sqrt(np.mean(np.maximum(own, shared) ** 2))
    # (measured: 1.13 and 0.78; a ratio from 300 replicas is itself uncertain by ~4 %)
    assert ratio_own > 1.05 and 0.7 < ratio_shared < 1.05, (ratio_own, ratio_shared)
    assert all(math.isnan(v) for v in shared_mode_se(np.ones(10), np.arange(10.0))[0])


def test_replicas_that_disagree_are_found():
    d = pl.DataFrame({"point": [0, 0, 0, 1, 1, 1], "x": [1.0, 1.01, 0.99, 1.0, 1.0, 1.2],
                      "x_se": [0.01] * 6})
    r = replica_mean(d, ["point"], ["x"])
    p = dict(zip(r["point"], r["x_agree_p"], strict=True))
    assert p[0] > 0.3 and p[1] < 1e-6  # (Q = 2 + 0 + ... against 1800 for the second)
    one = replica_mean(d.head(1), ["point"], ["x"])
    assert math.isnan(one["x_agree_p"][0]) and one["x_se"][0] == 0.01
