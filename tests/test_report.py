"""granflow.analysis.report: SE of a run's key figures against averaging and wall time, on
synthetic channel and cell tables with known statistics (AR(1) noise across windows/samples)."""

from __future__ import annotations

import math

import numpy as np
import polars as pl
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from granflow.analysis.report import CELL_FIGURES, CHANNEL_FIGURES, error_vs_time

W = 20.0
WINDOW = 0.5  # window length (time)
NOISE_U = 0.02


def ar1(n: int, a: float, rng: np.random.Generator, shape: tuple[int, ...] = ()) -> np.ndarray:
    """Unit-variance AR(1) series (statistical inefficiency g = (1 + a)/(1 - a))."""
    e = rng.normal(size=(n, *shape))
    x = np.empty_like(e)
    x[0] = e[0] / math.sqrt(1 - a * a)
    for i in range(1, n):
        x[i] = a * x[i - 1] + e[i]
    return x * math.sqrt(1 - a * a)


def channel_tables(nw: int = 2048, a: float = 0.3, seed: int = 0) -> dict[str, pa.Table]:
    """A steady channel: 1.5 d wall bins and 1 d interior bins over W = 20 (19 bins), velocity
    u = 1 + 0.4 (1 - exp(-3 xi / 4)) in -y, phi and sigma_xx with AR(1) noise per bin."""
    rng = np.random.default_rng(seed)
    edges = np.concatenate([[0.0], np.arange(1.5, W - 1.5 + 0.01, 1.0), [W]])
    x_lo, x_hi = edges[:-1], edges[1:]
    x = 0.5 * (x_lo + x_hi)
    nb = x.size
    xi = np.minimum(x, W - x)
    u = 1.0 + 0.4 * (1 - np.exp(-3 * xi / 4.0))
    phi = 0.6 - 0.05 * np.exp(-xi / 2)
    w = np.repeat(np.arange(nw), nb)
    bins = {
        "window": w.astype(np.int64),
        "t0": w * WINDOW,
        "t1": (w + 1) * WINDOW,
        "n_samples": np.full(nw * nb, 50, np.int64),
        "bin": np.tile(np.arange(nb), nw).astype(np.int64),
        "x_lo": np.tile(x_lo, nw),
        "x_hi": np.tile(x_hi, nw),
        "x": np.tile(x, nw),
        "phi": (phi + 0.002 * ar1(nw, a, rng, (nb,))).ravel(),
        "u_y": (-u - NOISE_U * ar1(nw, a, rng, (nb,))).ravel(),
        "sigma_xx": (10.0 + 0.5 * ar1(nw, a, rng, (nb,))).ravel(),
        "sigma_xy": np.tile(-0.3 * (x - W / 2), nw),
    }
    ns = nw * 10
    t = (np.arange(ns) + 1) * WINDOW / 10
    series = {"step": np.arange(ns, dtype=np.int64), "t": t, "vcm_x": 0 * t,
              "vcm_y": -(1.3 + 0.01 * ar1(ns, 0.9, rng)), "vcm_z": 0 * t}
    return {"bins": pa.table(bins), "series": pa.table(series)}


def cell_tables(n: int = 8192, a: float = 0.5, seed: int = 0, dt: float = 0.5) -> dict:
    rng = np.random.default_rng(seed)
    t = (np.arange(n) + 1) * dt
    cols: dict[str, np.ndarray] = {"step": np.arange(n, dtype=np.int64), "t": t}
    for k, m, s in (("mu1", 0.4, 0.02), ("mu2", 0.1, 0.01), ("mu3", 0.05, 0.01),
                    ("phi", 0.58, 0.002), ("I", 0.01, 0.001), ("shear_rate", 0.01, 0.001),
                    ("p", 1e-3, 1e-5)):
        cols[k] = m + s * ar1(n, a, rng)
    return {"series": pa.table(cols)}


def ratios(rep, fig: str) -> tuple[float, float]:
    """SE(whole) / SE(first 1/16) and the fitted exponent of SE vs T."""
    tab = rep.table.filter(pl.col("figure") == fig)
    fr, se = tab["fraction"].to_numpy(), tab["se"].to_numpy()
    e = rep.estimates.filter(pl.col("figure") == fig)
    return float(se[fr == 1.0][0] / se[fr == 1 / 16][0]), float(e["exponent"][0])


@pytest.fixture(scope="module")
def channel_report():
    return error_vs_time("channel", channel_tables(), wall_seconds=512.0, target_rel_se=2e-4)


def test_channel_se_falls_as_inverse_sqrt_time(channel_report):
    rep = channel_report
    assert set(rep.too_short) == set(CHANNEL_FIGURES)
    assert not rep.any_too_short
    exps = []
    for fig in CHANNEL_FIGURES:
        r, ex = ratios(rep, fig)
        assert 0.12 < r < 0.5, (fig, r)  # 1/sqrt(16) = 0.25
        exps.append(ex)
    assert -0.6 < float(np.median(exps)) < -0.4
    # linear figures against their exact SE: u_slip (mean of the two wall bins), u_max
    # (the central bin), g = (1 + a)/(1 - a) for AR(1) with a = 0.3
    g, n = 1.3 / 0.7, 2048
    est = {r["figure"]: r for r in rep.estimates.iter_rows(named=True)}
    assert est["u_slip"]["se"] == pytest.approx(NOISE_U / math.sqrt(2) * math.sqrt(g / n), rel=0.3)
    assert est["u_max"]["se"] == pytest.approx(NOISE_U * math.sqrt(g / n), rel=0.3)
    assert est["u_slip"]["value"] == pytest.approx(1.0 + 0.4 * (1 - math.exp(-3 * 0.75 / 4)),
                                                   abs=4 * est["u_slip"]["se"])


def test_channel_wall_time_and_target(channel_report):
    rep = channel_report
    # wall rate = wall_seconds / (t_end - t_begin) = 512 s / 1024 time units
    assert rep.wall_per_time == pytest.approx(0.5)
    t = rep.table
    assert np.allclose(t["wall_seconds"].to_numpy(), 0.5 * t["averaging_time"].to_numpy())
    assert np.allclose(t["rel_se"].to_numpy(), (t["se"] / t["value"].abs()).to_numpy())
    for r in rep.estimates.iter_rows(named=True):
        # time to the target from the fitted C / sqrt(T)
        assert r["time_needed"] == pytest.approx((r["C"] / (2e-4 * abs(r["value"]))) ** 2)
        assert r["wall_needed"] == pytest.approx(0.5 * r["time_needed"])
        assert r["time_more"] == pytest.approx(max(0.0, r["time_needed"] - r["averaging_time"]))
    txt = rep.text()
    for fig in CHANNEL_FIGURES:
        assert fig in txt
    assert "too short" not in txt


def test_cell_se_falls_as_inverse_sqrt_time():
    rep = error_vs_time("cell", cell_tables(), wall_seconds=100.0, target_rel_se=1e-3)
    assert set(rep.too_short) == set(CELL_FIGURES) and not rep.any_too_short
    g, n = 3.0, 8192
    est = {r["figure"]: r for r in rep.estimates.iter_rows(named=True)}
    for fig, s in (("mu1", 0.02), ("mu2", 0.01), ("mu3", 0.01), ("phi", 0.002), ("I", 0.001)):
        r, ex = ratios(rep, fig)
        assert 0.12 < r < 0.5, (fig, r)
        assert -0.75 < ex < -0.3, (fig, ex)
        # the steady part (MSER) may drop a few samples: n within a few percent
        assert est[fig]["se"] == pytest.approx(s * math.sqrt(g / n), rel=0.3), fig
    assert rep.wall_per_time == pytest.approx(100.0 / 4096.0)


def test_too_short_is_flagged():
    rep = error_vs_time("channel", channel_tables(nw=24, a=0.95), wall_seconds=10.0,
                        target_rel_se=1e-3)
    assert all(rep.too_short.values())
    assert not rep.estimates["reliable"].any()
    assert "too short" in rep.text()
    rep = error_vs_time("cell", cell_tables(n=64, a=0.95), wall_seconds=1.0)
    assert all(rep.too_short.values())


def test_parquet_and_plot(channel_report, tmp_path):
    a, b = channel_report.to_parquet(tmp_path / "errors.parquet", params={"scene": "channel"},
                                     seed=3)
    t = pl.read_parquet(a)
    assert t.columns[:6] == ["figure", "fraction", "n", "averaging_time", "wall_seconds",
                             "value"]
    assert {"se", "rel_se", "converged"} <= set(t.columns)
    assert pl.read_parquet(b).height == len(CHANNEL_FIGURES)
    md = pq.read_schema(a).metadata
    assert b"granflow.params" in md and md[b"granflow.seed"] == b"3"
    png = channel_report.plot(tmp_path / "errors.png")
    assert png.exists() and png.stat().st_size > 1000


def test_bad_input():
    with pytest.raises(ValueError, match="scene"):
        error_vs_time("gas", cell_tables(n=64), 1.0)
    with pytest.raises(ValueError, match="target_rel_se"):
        error_vs_time("cell", cell_tables(n=64), 1.0, target_rel_se=-1.0)
    with pytest.raises(ValueError, match="bins"):
        error_vs_time("channel", cell_tables(n=64), 1.0)
