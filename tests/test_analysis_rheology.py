"""Tests of granflow.analysis.rheology on synthetic cell data with known answers."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import polars as pl
import pyarrow as pa
import pytest
from granflow.analysis import plots
from granflow.analysis import rheology as rh
from granflow.states import FlowState
from scipy.signal import lfilter

# paper values for mu_s = 0.3 (Table 1 A's and the exponents / offsets quoted in the text)
TRUE = {
    "mu1": (0.33, 0.573, 0.70),
    "mu2": (0.10, 0.398, 0.44),
    "mu3": (0.02, 0.084, 0.50),
    "phi": (0.59, 0.230, 0.92),
}


def ar_noise(n: int, scale: float, rng: np.random.Generator, a: float = 0.8) -> np.ndarray:
    e = rng.normal(size=n)
    e[0] *= 1 / math.sqrt(1 - a * a)
    return scale * math.sqrt(1 - a * a) * lfilter([1.0], [1.0, -a], e)


def cell_series(
    inum: float, kind: str = "flowing", n: int = 4000, seed: int = 0
) -> dict[str, np.ndarray]:
    """A cell ``series`` with the flow laws at inertial number ``inum`` plus AR(1) noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 1.0
    gd = inum * 10.0
    if kind == "flowing":
        sr = gd * (1 + ar_noise(n, 0.05, rng))
        lxy = sr
    elif kind == "arrested":
        lxy = ar_noise(n, 1e-4, rng)
        sr = np.abs(lxy) + 1e-5
    elif kind == "accelerating":
        sr = gd * (1 + t / t[-1]) * (1 + ar_noise(n, 0.02, rng))
        lxy = sr
    else:
        raise ValueError(kind)
    out = {
        "step": np.arange(n) * 10,
        "t": t,
        "H_xx": 20 + 1e-3 * t,
        "F_xy": 1 + gd * t,
        "tilt_flips": (t // 1000).astype(np.int64),
        "shear_rate": sr,
        "L_xy": lxy,
        "L_yx": ar_noise(n, 1e-4, rng),
        "p": 1e-4 * (1 + ar_noise(n, 0.01, rng)),
        "I": inum * (1 + ar_noise(n, 0.03, rng)),
    }
    for law, (c0, A, a) in TRUE.items():
        out[law] = rh.law_value(law, inum, c0, A, a) + ar_noise(
            n, 0.02 if law != "phi" else 0.002, rng
        )
    out["N0_tau"] = -out["mu2"] / out["mu1"]
    out["N1_tau"] = 4 * out["mu3"] / out["mu1"]
    return out


@pytest.mark.parametrize("law", ["mu1", "mu2", "mu3", "phi"])
def test_fit_law_recovers_parameters_within_3_sigma(law):
    rng = np.random.default_rng(42)
    inum = np.logspace(-3.5, -0.5, 30)
    c0, A, a = TRUE[law]
    se = np.full(inum.size, 0.003 if law != "phi" else 0.0005)
    y = rh.law_value(law, inum, c0, A, a) + se * rng.normal(size=inum.size)
    fit = rh.fit_law(law, inum, y, se)
    assert fit.success and fit.n == 30 and fit.dof == 27
    for name, true in zip(rh.LAWS[law].params, (c0, A, a), strict=True):
        assert abs(fit.params[name] - true) < 3 * fit.errors[name], name
        assert fit.errors[name] < 0.5 * true
    assert 0.4 < fit.red_chi2 < 2.0
    np.testing.assert_allclose(fit(inum), rh.law_value(law, inum, *fit.params.values()))


def test_fit_law_with_x_errors_and_bad_points():
    rng = np.random.default_rng(1)
    inum = np.logspace(-3, -0.5, 25)
    y = rh.law_value("mu1", inum, *TRUE["mu1"]) + 0.003 * rng.normal(size=25)
    se = np.full(25, 0.003)
    y[3], se[5] = np.nan, 0.0  # dropped
    fit = rh.fit_law("mu1", inum, y, se, I_se=0.02 * inum)
    assert fit.n == 23
    assert abs(fit.params["a1"] - 0.70) < 3 * fit.errors["a1"]
    plain = rh.fit_law("mu1", inum, y, se)
    assert fit.errors["a1"] >= plain.errors["a1"]  # extra variance from the I errors
    assert not rh.fit_law("mu1", inum[:3], y[:3], se[:3]).success


def test_classify_and_analyse_run():
    st = rh.classify_run(cell_series(0.01, "flowing"))
    assert st.state is FlowState.FLOWING and st.averaged and st.shear_component == "L_xy"
    assert st.shear_mean > 10 * st.shear_se
    assert rh.classify_run(pa.table(cell_series(0.01, "arrested"))).state == "arrested"
    acc = rh.classify_run(pl.DataFrame(cell_series(0.01, "accelerating")))
    assert acc.state == "accelerating" and not acc.averaged
    res = rh.analyse_run(cell_series(0.02, "flowing", seed=3))
    stats = {r["observable"]: r for r in res.stats.iter_rows(named=True)}
    assert "H_xx" not in stats and "F_xy" not in stats and "tilt_flips" not in stats
    mu1 = stats["mu1"]
    assert abs(mu1["mean"] - rh.law_value("mu1", 0.02, *TRUE["mu1"])) < 4 * mu1["se"]
    assert mu1["converged"]
    # AR(1) with a = 0.8, dt = 1: tau = (1 + a) / (1 - a) / 2 = 4.5
    assert 3.0 < mu1["tau"] < 6.5


def test_collect_runs_and_fit_through_the_pipeline():
    inums = np.logspace(-3, -0.7, 12)
    runs = [
        ({"mu_s": 0.3, "tau_ext": float(k)}, cell_series(i, seed=k)) for k, i in enumerate(inums)
    ]
    runs.append(({"mu_s": 0.3, "tau_ext": 99.0}, cell_series(0.01, "accelerating", seed=99)))
    runs.append(({"mu_s": 0.3, "tau_ext": -1.0}, cell_series(0.01, "arrested", seed=98)))
    df = rh.collect_runs(runs)
    assert df.height == 14
    assert df["state"].to_list() == ["flowing"] * 12 + ["accelerating", "arrested"]
    assert df.schema["state"] == pl.String  # a table holds the state's plain string
    assert df.filter(pl.col("state") == "accelerating")["mu1"].is_null().all()
    assert {"mu1", "mu1_se", "mu1_tau", "I_se", "n_unconverged", "T_avg"} <= set(df.columns)
    flowing = df.filter(pl.col("state") == "flowing")
    true_mu1 = rh.law_value("mu1", inums, *TRUE["mu1"])
    pull = (flowing["mu1"].to_numpy() - true_mu1) / flowing["mu1_se"].to_numpy()
    assert np.all(np.abs(pull) < 4)
    fits = rh.fit_all(df)  # flowing rows only
    assert set(fits) == {"mu1", "mu2", "mu3", "phi"}
    f = fits["mu1"]
    assert f.n == 12
    for name, true in zip(("mu1_0", "A1", "a1"), TRUE["mu1"], strict=True):
        assert abs(f.params[name] - true) < 3 * f.errors_scaled[name], name
    assert rh.fit_all(df.to_arrow())["mu1"].params == f.params  # pyarrow input
    row = rh.table1_row(fits, 0.3)
    assert row["A1"] == f.params["A1"] and row["A4_err"] == fits["phi"].errors["A4"]
    text = rh.format_table1([row])
    lines = text.splitlines()
    assert lines[0].split()[:6] == ["source", "mu_s", "A1", "A2", "A3", "A4"]
    assert lines[1].startswith("fit") and "±" in lines[1]
    assert lines[2].startswith("paper") and "0.573" in lines[2] and "0.330" in lines[2]


def test_pool_realizations():
    df = pl.DataFrame(
        {
            "tau": [1.0, 1.0, 2.0],
            "averaged": [True, True, True],
            "mu1": [0.40, 0.42, 0.5],
            "mu1_se": [0.01, 0.02, 0.01],
        }
    )
    pooled = rh.pool_realizations(df, ["tau"])
    r = pooled.row(0, named=True)
    w = np.array([1 / 0.01**2, 1 / 0.02**2])
    assert r["n_runs"] == 2
    assert r["mu1"] == pytest.approx(np.sum(w * [0.40, 0.42]) / w.sum())
    assert r["mu1_se"] == pytest.approx(1 / np.sqrt(w.sum()))


def test_table1_reference_values(monkeypatch, tmp_path):
    monkeypatch.setattr(rh, "DEFAULT_TABLE1_PATH", Path(tmp_path / "missing.csv"))
    np.testing.assert_allclose(rh.load_table1().to_numpy(), np.array(rh.TABLE1))  # embedded
    monkeypatch.undo()
    tab = rh.load_table1()
    assert tab.columns == ["mu_s", "A1", "A2", "A3", "A4"] and tab.height == 14
    np.testing.assert_allclose(tab.to_numpy(), np.array(rh.TABLE1))
    if rh.DEFAULT_TABLE1_PATH.exists():
        np.testing.assert_allclose(
            rh.load_table1(rh.DEFAULT_TABLE1_PATH).to_numpy(), np.array(rh.TABLE1)
        )
    ref = rh.reference_parameters(0.3)
    assert (ref["A1"], ref["mu1_0"], ref["a1"], ref["phi_0"], ref["a4"]) == (
        0.573,
        0.33,
        0.70,
        0.59,
        0.92,
    )
    assert not ref["interpolated"] and math.isnan(ref["mu3_0"])
    mid = rh.reference_parameters(0.2)
    assert mid["interpolated"] and 0.554 < mid["A1"] < 0.562 and math.isnan(mid["a1"])
    assert rh.reference_curve("mu1", 0.1, 0.3) == pytest.approx(0.33 + 0.573 * 0.1**0.7)
    with pytest.raises(ValueError):
        rh.reference_curve("mu3", 0.1, 0.3)
    assert rh.reference_curve("mu3", 0.1, 0.3, offset=0.02) == pytest.approx(
        0.02 - 0.084 * 0.01**0.5
    )


def test_cell_plot(tmp_path):
    inums = np.logspace(-3, -0.7, 6)
    df = rh.collect_runs(
        [({"mu_s": 0.3}, cell_series(i, seed=k, n=1500)) for k, i in enumerate(inums)]
    )
    fits = rh.fit_all(df)
    p = plots.plot_cell_rheology(df, tmp_path / "cell.png", fits=fits, mu_s=0.3)
    data = p.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 20000


def test_a_constant_is_undetermined_when_its_error_exceeds_half_its_size():
    from granflow.analysis.rheology import undetermined

    assert not undetermined(0.30, 0.14)
    assert undetermined(0.30, 0.16)
    # beside a larger reference value the reference sets the size
    assert not undetermined(0.05, 0.04, reference=0.09)
    assert undetermined(-0.051, 0.059, reference=0.09)
    # no finite error: not determined
    assert undetermined(0.3, float("nan")) and undetermined(0.3, float("inf"))
