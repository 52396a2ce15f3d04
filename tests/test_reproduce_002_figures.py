"""The 002 report's figures (granflow.studies.reproduce_002_figures) from a synthetic pooled
table on 002's own laws: every figure is written with one pressure and with two, and fig. 7's
paper curves are 002's N0/tau = -mu2/mu1 and N1/tau = 4 mu3/mu1."""

from __future__ import annotations

import numpy as np
import polars as pl
import pytest
from granflow.analysis import rheology as rh
from granflow.studies.reproduce_002_figures import FIGURES, _curves, plot_figures

MU3_0 = 0.01


def _pool(pressures: tuple[float, ...]) -> pl.DataFrame:
    """Points on 002's curves at mu_s = 0 and 0.3 (mu3 with MU3_0), 2 % noise, every pressure
    (lower pressures at lower I, as in 002), one N = 10,000 point."""
    rng = np.random.default_rng(1)
    rows = []
    for mu in (0.0, 0.3):
        for k, p in enumerate(pressures):
            for i, tau in enumerate(np.linspace(0.1, 0.8, 7)):
                ii = float(np.logspace(-2.5, -0.4, 7)[i] / (1 + k))
                r = {"mu_s": mu, "N": 2000, "p_ext": p, "tau_ratio": float(tau), "I": ii,
                     "I_se": 0.02 * ii}
                for law in rh.LAWS:
                    y = float(rh.reference_curve(law, ii, mu, offset=MU3_0 if law == "mu3"
                                                 else None)[()])
                    se = 0.002 if law != "phi" else 0.0005
                    r[law], r[f"{law}_se"] = y + rng.normal(0, se), se
                r["N0_tau"], r["N1_tau"] = -r["mu2"] / r["mu1"], 4 * r["mu3"] / r["mu1"]
                r["A_xy"], r["Z2"], r["theta_c"] = -0.5 - ii, 4 - 5 * ii, 10 * ii
                for c in ("N0_tau", "N1_tau", "A_xy", "Z2", "theta_c"):
                    r[f"{c}_se"] = 0.01
                rows.append(r)
    big = dict(rows[3], N=10_000)
    return pl.DataFrame([*rows, big])


def _fits(pool: pl.DataFrame) -> dict[float, dict[str, rh.FitResult]]:
    main = pool.filter(pl.col("N") == 2000)
    return {float(mu): rh.fit_all(g, include_x_errors=True, states=None)
            for (mu,), g in main.group_by(["mu_s"], maintain_order=True)}


@pytest.mark.parametrize("pressures", [(1e-4,), (1e-4, 1e-5)])
def test_every_figure_is_written(tmp_path, pressures):
    pool = _pool(pressures)
    paths = plot_figures(pool, _fits(pool), tmp_path / "figs", n=2000)
    assert [p.name for p in paths] == [f for f, _, _ in FIGURES]
    for p in paths:
        head = p.read_bytes()[:8]
        assert head == b"\x89PNG\r\n\x1a\n" and p.stat().st_size > 10_000


def test_a_missing_column_leaves_a_panel_without_data(tmp_path):
    pool = _pool((1e-4,)).drop("theta_c", "theta_c_se")
    paths = plot_figures(pool, _fits(pool), tmp_path, n=2000)
    assert (tmp_path / "fig8_fabric.png") in paths


def test_fig7_paper_curves_are_the_laws_ratios():
    pool = _pool((1e-4,))
    fits = _fits(pool)
    grid = np.logspace(-2, -0.5, 20)
    for mu in (0.0, 0.3):
        mu1 = rh.reference_curve("mu1", grid, mu)
        n0 = dict((ls, y) for y, ls in _curves("N0_tau", grid, mu, fits[mu]))
        np.testing.assert_allclose(n0["--"], -rh.reference_curve("mu2", grid, mu) / mu1)
        f1, f2 = fits[mu]["mu1"], fits[mu]["mu2"]
        np.testing.assert_allclose(n0["-"], -f2(grid) / f1(grid))
        # 002 gives no mu3_0: its N1/tau takes our fitted one
        n1 = dict((ls, y) for y, ls in _curves("N1_tau", grid, mu, fits[mu]))
        off = fits[mu]["mu3"].params["mu3_0"]
        np.testing.assert_allclose(
            n1["--"], 4 * rh.reference_curve("mu3", grid, mu, offset=off) / mu1)
    # no paper constants at mu_s = 0.1: our fits' curve only
    assert [ls for _, ls in _curves("N0_tau", grid, 0.1, fits[0.3])] == ["-"]


def test_the_constants_panels_draw_our_fitted_values_and_the_papers():
    from dataclasses import replace

    from granflow.studies.reproduce_002_figures import Panel, _constant_panel, _Style
    from matplotlib.figure import Figure

    pool = _pool((1e-4, 1e-5))
    fits = _fits(pool)
    style = _Style.of(pool, 2000)
    ax = Figure().add_subplot()
    assert _constant_panel(ax, fits, Panel("mu1", 1, "mu1_0", "c0"), style) == \
        "mu1_0 against mu_s"
    ys = [float(y) for ln in ax.get_lines() for y in np.atleast_1d(ln.get_ydata())]
    for mu in (0.0, 0.3):
        assert fits[mu]["mu1"].params["mu1_0"] in ys
        # 002's mu1_0 (§4): 0.09 and 0.33
        assert rh.reference_parameters(mu)["mu1_0"] in ys
    assert not ax.texts
    # an exponent whose error exceeds half its value is drawn open, the axis scaled without it
    loose = dict(fits)
    f = fits[0.3]["phi"]
    loose[0.3] = {**fits[0.3], "phi": replace(f, errors={**f.errors, "a4": 10.0})}
    ax = Figure().add_subplot()
    _constant_panel(ax, loose, Panel("phi", 1, "a4", "exponent"), style)
    assert "mu_s = 0.3" in ax.texts[0].get_text()
    assert ax.get_ylim()[1] < f.params["a4"] + 10.0
