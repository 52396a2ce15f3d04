"""Tests of granflow.analysis.stats and .binned on synthetic series with known answers."""

from __future__ import annotations

import numpy as np
import polars as pl
import pyarrow as pa
import pytest
from granflow.analysis import binned as P
from granflow.analysis import plots
from granflow.analysis import stats as S
from scipy.signal import lfilter


def ar1(a: float, n: int, seed: int, sigma_e: float = 1.0) -> np.ndarray:
    """Stationary AR(1): x_i = a x_{i-1} + e_i, var(x) = sigma_e^2 / (1 - a^2)."""
    rng = np.random.default_rng(seed)
    e = rng.normal(scale=sigma_e, size=n)
    e[0] *= np.sqrt(1.0 / (1.0 - a * a))
    return lfilter([1.0], [1.0, -a], e)


def ar1_se(a: float, n: int, sigma_e: float = 1.0) -> float:
    """Exact standard error of the mean of n samples of a stationary AR(1) process."""
    var = sigma_e**2 / (1 - a * a)
    g_n = (1 + a) / (1 - a) - 2 * a * (1 - a**n) / (n * (1 - a) ** 2)
    return float(np.sqrt(var * g_n / n))


def test_blocking_long_ar1_matches_analytic_se_and_tau():
    a, n, dt = 0.9, 2**17, 0.1
    x = 5.0 + ar1(a, n, seed=11)
    b = S.blocking(x, dt)
    se_true = ar1_se(a, n)
    tau_true = dt * (1 + a) / (1 - a) / 2  # dt (1/2 + sum rho_k)
    assert b.converged
    assert abs(b.se / se_true - 1) < 0.2
    assert abs(b.tau / tau_true - 1) < 0.3
    assert abs(b.mean - 5.0) < 4 * se_true
    # the naive (level 0) error underestimates by sqrt(g) ~ 4.4
    assert b.se_naive < 0.35 * b.se
    assert b.levels.height >= 10 and b.levels["se"][0] == pytest.approx(b.se_naive)
    assert b.se_err < 0.1 * b.se


def test_blocking_short_correlated_series_is_not_converged():
    x = ar1(0.99, 256, seed=3)  # tau ~ 100 samples: far too short
    b = S.blocking(x)
    assert not b.converged
    assert b.n == 256
    value, se = S.mean_se(x)  # an Estimate: the blocking's mean and SE
    assert value == b.mean and se == b.se


def test_uncorrelated_series():
    rng = np.random.default_rng(5)
    x = rng.normal(size=4000)
    res = S.blocking(x, dt=2.0)
    assert res.converged
    assert abs(res.se * np.sqrt(4000) - 1.0) < 0.1
    assert abs(res.tau - 1.0) < 0.3  # dt / 2


def test_blocking_many_vectorised_matches_single_and_handles_nan():
    cols = np.column_stack([ar1(0.5, 4096, s) for s in range(3)])
    cols[10, 2] = np.nan
    many = S.blocking_many(cols, 0.5)
    for j in range(2):
        one = S.blocking(cols[:, j], 0.5)
        assert many.se[j] == pytest.approx(one.se)
        assert many.tau[j] == pytest.approx(one.tau)
    one = S.blocking(cols[:, 2], 0.5)  # NaN sample dropped
    assert many.n[2] == 4095 and many.se[2] == pytest.approx(one.se)


def test_ratio_se_linearisation():
    rng = np.random.default_rng(2)
    a = 2.0 + 0.1 * rng.normal(size=20000)
    b = 4.0 + 0.1 * rng.normal(size=20000)
    r = S.ratio_se(a, b)
    se_delta = 0.5 * np.sqrt((0.1 / 2) ** 2 + (0.1 / 4) ** 2) / np.sqrt(20000)
    assert r.value == pytest.approx(0.5, abs=4 * se_delta)
    assert abs(r.se / se_delta - 1) < 0.15


def test_steady_state_start_skips_transient():
    rng = np.random.default_rng(7)
    t = np.arange(4000) * 0.5
    x = 5.0 * np.exp(-t / 50.0) + rng.normal(size=t.size)
    st = S.steady_state_start(t, x)
    assert st.settled
    assert 100.0 < st.t_start < 600.0
    steady = S.blocking(x[st.index :])
    # the transient biases the plain average by ~0.12, 8x the error of the stationary noise
    assert abs(np.mean(x)) > 4 / np.sqrt(x.size)
    assert abs(steady.mean) < 4 * steady.se and steady.converged


def test_steady_state_start_stationary_and_drifting():
    rng = np.random.default_rng(8)
    t = np.arange(3000.0)
    st = S.steady_state_start(t, rng.normal(size=t.size))
    assert st.settled and st.index < 300
    ramp = S.steady_state_start(t, 0.01 * t + rng.normal(size=t.size))
    assert not ramp.settled


def test_se_vs_time_fit_and_time_to_reach():
    a, n, dt = 0.5, 2**15, 0.01
    x = ar1(a, n, seed=4)
    t = np.arange(n) * dt
    res = S.se_vs_time(t, x, wall_time_per_unit_t=3.0, start=0)
    var, g = 1 / (1 - a * a), (1 + a) / (1 - a)
    C_true = np.sqrt(var * g * dt)  # SE = C / sqrt(T)
    assert not res.too_short
    assert abs(res.C / C_true - 1) < 0.15
    assert abs(res.exponent + 0.5) < 0.15
    assert res.table["T"][-1] == pytest.approx(n * dt)
    assert res.table["wall_time"][-1] == pytest.approx(3.0 * n * dt)
    target = 0.5 * res.table["se"][-1]
    need = res.time_to_reach(target)
    assert need["T"] == pytest.approx((res.C / target) ** 2)
    assert 2.5 * n * dt < need["T"] < 6 * n * dt  # halving the error costs ~4x the time
    assert need["wall_time"] == pytest.approx(3.0 * need["T"])
    assert need["reliable"]


def test_se_vs_time_flags_short_data():
    x = ar1(0.99, 300, seed=9)
    res = S.se_vs_time(np.arange(300.0), x, start=0)
    assert res.too_short
    assert not res.time_to_reach(0.01)["reliable"]
    assert res.time_to_reach(0.01)["wall_time"] is None


def _bins_table(nw: int, sig: np.ndarray, seed: int) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    nb = sig.size
    w = np.repeat(np.arange(nw), nb)
    b = np.tile(np.arange(nb), nw)
    prof = np.linspace(1.0, 2.0, nb)
    return {
        "window": w,
        "bin": b,
        "t0": 10.0 * w,
        "t1": 10.0 * (w + 1),
        "n_samples": np.full(w.size, 50),
        "x": b + 0.5,
        "x_lo": b * 1.0,
        "x_hi": b + 1.0,
        "u_y": -(prof[b] + sig[b] * rng.normal(size=w.size)),
    }


def test_profile_se_per_bin_whole_profile_and_input_types():
    sig = np.linspace(0.01, 0.05, 12)
    nw = 256
    d = _bins_table(nw, sig, seed=1)
    pe = P.profile_se(d, ["u_y"], start_window=0)
    se = pe.table["u_y_se"].to_numpy()
    assert np.all(np.abs(se / (sig / np.sqrt(nw)) - 1) < 0.3)
    rms_true = np.sqrt(np.mean(sig**2)) / np.sqrt(nw)
    assert abs(pe.whole["u_y"]["rms_se"] / rms_true - 1) < 0.1
    assert pe.whole["u_y"]["rel_error"] == pytest.approx(
        pe.whole["u_y"]["rms_se"] / pe.whole["u_y"]["scale"]
    )
    assert pe.whole["u_y"]["frac_converged"] == 1.0
    # pyarrow and polars inputs give identical results
    for tab in (pa.table(d), pl.DataFrame(d)):
        other = P.profile_se(tab, ["u_y"], start_window=0)
        np.testing.assert_allclose(other.table["u_y_se"].to_numpy(), se)


def test_profile_se_vs_time():
    sig = np.full(8, 0.04)
    d = _bins_table(512, sig, seed=2)
    res = P.profile_se_vs_time(pl.DataFrame(d), "u_y", wall_time_per_unit_t=0.2, start_window=0)
    assert not res.too_short
    # rms SE = sigma / sqrt(n_windows) = sigma sqrt(window) / sqrt(T): C = sigma sqrt(10)
    assert abs(res.C / (0.04 * np.sqrt(10.0)) - 1) < 0.15
    assert abs(res.exponent + 0.5) < 0.15


def test_plots_se_vs_time_and_work_precision(tmp_path):
    x = ar1(0.5, 2**13, seed=1)
    res = S.se_vs_time(np.arange(x.size) * 0.1, x, wall_time_per_unit_t=0.5, start=0)
    p1 = plots.plot_se_vs_time({"obs": res}, tmp_path / "se.png")
    wp = pl.DataFrame(
        {
            "dt_label": ["dt", "dt/2", "dt/4"] * 2,
            "wall_time": [1.0, 2.0, 4.0] * 2,
            "observable": ["u_slip"] * 3 + ["phi"] * 3,
            "deviation": [1e-2, 2.6e-3, 6e-4, 3e-3, 8e-4, 2e-4],
        }
    )
    p2 = plots.plot_work_precision(wp.to_arrow(), tmp_path / "wp.png")
    for p in (p1, p2):
        data = p.read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 5000


def test_time_to_reach_agrees_with_the_measured_error():
    # correlations that short prefixes miss (a slow component): the estimate must not promise
    # the target sooner than the full-length SE already implies
    rng = np.random.default_rng(11)
    n, dt = 2**14, 1.0
    slow = np.repeat(rng.normal(size=n // 512), 512)
    x = ar1(0.3, n, seed=12) + 0.5 * slow
    t = np.arange(n) * dt
    res = S.se_vs_time(t, x, start=0)
    se_last, T_last = res.table["se"][-1], res.table["T"][-1]
    target = 0.5 * se_last
    need = res.time_to_reach(target)
    assert need["T"] >= (se_last / target) ** 2 * T_last * (1 - 1e-9)


def test_steady_state_start_of_several_observables_is_the_latest():
    rng = np.random.default_rng(11)
    t = np.arange(3000.0)
    fast = 3.0 * np.exp(-t / 20.0) + rng.normal(size=t.size)
    slow = 3.0 * np.exp(-t / 200.0) + rng.normal(size=t.size)
    one = {k: S.steady_state_start(t, v) for k, v in (("fast", fast), ("slow", slow))}
    both = S.steady_state_start(t, {"fast": fast, "slow": slow})
    assert one["slow"].index > one["fast"].index
    assert (both.index, both.t_start) == (one["slow"].index, one["slow"].t_start)
    assert both.settled == (one["fast"].settled and one["slow"].settled)
    assert both.criterion.endswith("latest over fast, slow")
    with pytest.raises(ValueError):
        S.steady_state_start(t, {})


def test_the_weighted_mean_weighs_by_inverse_variance():
    from granflow.analysis.stats import weighted_mean

    m, se = weighted_mean([1.0, 2.0, 4.0], [1.0, 1.0, 1.0])
    assert m == pytest.approx(7.0 / 3.0) and se == pytest.approx(3.0 ** -0.5)
    # a value with half the SE weighs four times as much
    m, se = weighted_mean([0.0, 1.0], [0.5, 1.0])
    assert m == pytest.approx(0.2) and se == pytest.approx(5.0 ** -0.5)
