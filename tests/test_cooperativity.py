"""granflow.continuum.cooperativity: the nonlocal amplitude read off a channel profile bin by
bin, against profiles the nonlocal model itself made with a known amplitude; its window,
refusals and the trend test."""

from __future__ import annotations

import math

import numpy as np
import polars as pl
import pytest
from granflow.continuum import ChannelProblem
from granflow.continuum.channel_model import ChannelCase
from granflow.continuum.cooperativity import (
    X_BULK,
    amplitude_profile,
    bulk_amplitude,
    bulk_table,
    trend,
)
from granflow.continuum.given_phi import solve_nonlocal_given_phi
from granflow.errors import ParameterError
from model_law import MODEL_LAW

LAW = MODEL_LAW


def model_case(A: float, W: float = 40.0, g_wall: float = 5.0, se: float = 1e-9
               ) -> ChannelCase:
    """A channel 'run' whose 1 d bins are the nonlocal model's own solution (phi = 0.6,
    sigma_xx = 30) with amplitude ``A``: the DEM's bins, had the model been exact."""
    sxx, x0 = 30.0, 0.75
    prob = ChannelProblem(W=W, sigma_xx=sxx, u_wall=1.0, x0=x0, g_wall=g_wall)
    xi = np.concatenate([[x0], np.arange(2.0, W / 2 + 0.5, 1.0)])
    prof = solve_nonlocal_given_phi(LAW, A, prob, [0.0, W / 2], [0.6, 0.6])
    m = prof.at(xi)
    n = xi.size
    zone = ["wall", "wall", "loose"] + ["dense"] * (n - 3)
    t = pl.DataFrame({"xi": xi, "u": m["u"], "gamma_dot": m["dudx"], "mu": m["mu"],
                      "phi": np.full(n, 0.6), "I": m["I"], "zone": zone,
                      "u_se": np.full(n, se), "gamma_dot_se": se * np.abs(m["dudx"]),
                      "mu_se": np.full(n, se)})
    return ChannelCase(W, 0.6, 1e5, t, sxx, 3.0, seed=1)


@pytest.mark.parametrize("A", [0.35, 0.45, 0.6])
def test_the_bulk_amplitude_of_the_models_own_profile_is_its_amplitude(A):
    b = bulk_amplitude(model_case(A), LAW)
    assert b.n >= 3 and b.x_lo >= X_BULK
    # 1 d bins resolve a decay length of ~1-2 d to well under 1 % (central differences)
    assert b.A == pytest.approx(A, rel=0.01)
    # the line with a free intercept finds the law's yield ratio
    assert b.mu_s_free == pytest.approx(LAW.mu_s, abs=0.005)


def test_an_amplitude_off_by_a_fifth_is_told_apart():
    a, b = bulk_amplitude(model_case(0.4), LAW), bulk_amplitude(model_case(0.5), LAW)
    assert b.A - a.A == pytest.approx(0.1, abs=0.02)


def test_bins_beyond_the_creep_floor_or_above_yield_are_not_in_the_window():
    p = amplitude_profile(model_case(0.45), LAW)
    bulk = p.filter(pl.col("bulk"))
    assert (bulk["mu"] < LAW.mu_s).all() and (bulk["xi"] >= X_BULK).all()
    assert (bulk["g_min"] >= 1e-3).all()
    # deep inside, the fluidity falls below the floor: those bins are out
    assert not p.filter(pl.col("xi") > 15)["bulk"].any()


def test_a_run_without_a_bulk_window_is_refused_by_name():
    # the fluidity has decayed below the creep floor before x = 4 d
    case = model_case(0.45, g_wall=1e-3)
    with pytest.raises(ParameterError, match="W = 40.*0 bins in the bulk window"):
        bulk_amplitude(case, LAW)
    row = bulk_table([case], {1e-4: _Cal()}).row(0, named=True)
    assert math.isnan(row["A"]) and "bulk window" in row["why"]


class _Cal:
    law = LAW


def test_the_bulk_table_holds_the_reference_amplitude_and_measures_the_wall_share():
    ref, other = model_case(0.45), model_case(0.45, W=60.0)
    t = bulk_table([ref, other], {1e-4: _Cal()}, reference=ref)  # type: ignore[dict-item]
    assert t["A_ref"].to_list() == pytest.approx([t["A"][0]] * 2)
    # the model's own profile, predicted with (nearly) its own amplitude from the first
    # bulk bin on, is met to within the bins' difference error
    assert (t["u_rel_bulk"] < 0.05).all()
    assert ((t["wall_share"] > 0) & (t["wall_share"] < 1)).all()


def test_the_trend_test_finds_an_imposed_slope_and_none_in_a_constant():
    base = pl.DataFrame({"W": [20.0, 40.0, 60.0, 40.0], "phi_bar": [0.6, 0.59, 0.6, 0.61],
                         "A": [0.4, 0.4, 0.4, 0.4], "A_se": [0.01] * 4})
    flat = trend(base, "W")
    assert flat.z == pytest.approx(0.0) and flat.chi2_dof == pytest.approx(0.0)
    sloped = trend(base.with_columns((0.3 + 0.005 * pl.col("W")).alias("A")), "W")
    assert sloped.slope == pytest.approx(0.005) and sloped.z > 10
    # one value of phi_bar, with SEs whose weighted mean does not round back to it exactly
    # (a centred sum of squares of ~1e-30, not 0): no slope rather than one of SE ~1e13
    one = pl.DataFrame({"W": [20.0, 40.0, 60.0, 100.0, 150.0], "phi_bar": [0.6] * 5,
                        "A": [0.4, 0.5, 0.45, 0.42, 0.41],
                        "A_se": [0.02763762458180572, 0.04681854876560065,
                                 0.040976824151955075, 0.0011341865083372568,
                                 0.0430128095527909]})
    assert math.isnan(trend(one, "phi_bar").slope) and math.isfinite(trend(one, "W").z)
    with pytest.raises(ParameterError, match="against"):
        trend(base, "seed")
    with pytest.raises(ParameterError, match=">= 3"):
        trend(base.head(2), "W")


def test_a_wall_layer_with_the_bulks_amplitude_is_no_layer_and_a_wider_one_spreads_further():
    case = model_case(0.45)
    prob, t = case.problem(0), case.profile
    xs, ph = t["xi"].to_numpy(), t["phi"].to_numpy()
    plain = solve_nonlocal_given_phi(LAW, 0.45, prob, xs, ph)
    same = solve_nonlocal_given_phi(LAW, 0.45, prob, xs, ph, layer=(X_BULK, 0.45))
    np.testing.assert_array_equal(plain.u, same.u)
    # the wall's fluidity reaches further into the channel the larger the layer's amplitude
    g_at = [np.interp(X_BULK, p.x, p.fluidity) for p in (
        solve_nonlocal_given_phi(LAW, 0.45, prob, xs, ph, layer=(X_BULK, a))
        for a in (0.2, 0.45, 0.9))]
    assert g_at[0] < g_at[1] < g_at[2]
    with pytest.raises(ParameterError, match="A_layer"):
        solve_nonlocal_given_phi(LAW, 0.45, prob, xs, ph, layer=(X_BULK, 0.0))


def test_the_layer_amplitude_of_a_profile_made_with_one_is_found_and_transfers():
    from granflow.continuum.cooperativity import fit_layer_amplitude, layer_table

    # the model's own runs, made with one amplitude throughout: the layer needs that same one
    ref, other = model_case(0.45), model_case(0.45, W=60.0)
    assert fit_layer_amplitude(ref, LAW, 0.45) == pytest.approx(0.45, rel=0.05)
    t = layer_table([ref, other], {1e-4: _Cal()}, 0.45, ref)  # type: ignore[dict-item]
    assert (t["u_rel_held"] < 0.01).all() and (t["u_rel_one"] < 0.01).all()
