"""The verdict table of the cross-scene prediction (granflow.continuum.verdict): the misfit's
propagated SE, the classification against a target, the worst run per width and zone, and
the one-line answer."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import polars as pl
import pytest
from granflow.continuum import verdict as vd
from granflow.errors import ParameterError


def test_a_uniform_residual_has_the_se_of_a_mean():
    """r_i = c with SEs s: the RMS is c and its SE s / sqrt(n), as the mean of n values."""
    e, se = vd.misfit_with_error(np.full(16, 0.2), np.full(16, 0.04))
    assert e == pytest.approx(0.2)
    assert se == pytest.approx(0.04 / 4)


def test_a_misfit_below_the_noise_takes_the_noise_as_its_se():
    """Residuals smaller than their SEs are not resolved: the SE is the noise's RMS."""
    e, se = vd.misfit_with_error(np.array([0.001, -0.001]), np.array([0.03, 0.04]))
    assert e == pytest.approx(0.001)
    assert se == pytest.approx(math.sqrt((0.03**2 + 0.04**2) / 2))
    assert vd.classify(e, se, 0.05) == "at the target"  # 0.001 + 2 x 0.035 > 0.05


def test_classify_uses_two_ses_either_side():
    assert vd.classify(0.05, 0.02, 0.10) == "within"
    assert vd.classify(0.15, 0.02, 0.10) == "outside"
    assert vd.classify(0.09, 0.02, 0.10) == "at the target"
    assert vd.classify(math.nan, 0.02, 0.10) == ""
    with pytest.raises(ParameterError, match="target"):
        vd.classify(0.1, 0.01, 0.0)


def test_mismatched_ses_are_refused():
    with pytest.raises(ParameterError, match="se"):
        vd.misfit_with_error(np.zeros(3), np.zeros(4))


@dataclass
class _Case:
    """The fields of a ChannelCase that zone_errors reads."""

    W: float
    phi_bar: float
    profile: pl.DataFrame
    seed: int | None = 1

    @property
    def name(self) -> str:
        return f"W = {self.W:g}"


def _run(W: float, du_error: float, phi_error: float) -> tuple[_Case, pl.DataFrame]:
    """A DEM half profile (wall bin, 4 dense bins, 2 plug bins) and a model that misses it by
    ``du_error`` of the span in u - u_slip and by ``phi_error`` in phi, with no band."""
    xi = np.arange(7) + 0.5
    u = np.array([1.0, 2.0, 3.0, 4.0, 5.0, 5.5, 6.0])
    phi = np.full(7, 0.62)
    dem = pl.DataFrame({"xi": xi, "u": u, "phi": phi, "u_se": np.full(7, 0.01),
                        "phi_se": np.full(7, 1e-4),
                        "zone": ["wall", "dense", "dense", "dense", "dense", "plug", "plug"]})
    span = u[-1] - u[0]
    model = pl.DataFrame({"W": W, "phi_bar": 0.6, "seed": 1, "model": "nonlocal", "xi": xi,
                          "du": u - u[0] + du_error * span, "phi": phi + phi_error})
    return _Case(W, 0.6, dem), model


def test_the_verdict_table_and_answer_follow_the_targets():
    """A wide run missed by 3 % of the span in u and 0.002 in phi is within both targets; a
    narrow one missed by 30 % and 0.05 is outside both; the plug has no phi verdict; the
    answer reads only the wide runs."""
    wide, m_wide = _run(60.0, 0.03, 0.002)
    narrow, m_narrow = _run(20.0, 0.30, 0.05)
    errors = vd.zone_errors([wide, narrow], pl.concat([m_wide, m_narrow]))
    dense = errors.filter((pl.col("W") == 60) & (pl.col("zone") == "dense")).row(0, named=True)
    assert dense["u_rel"] == pytest.approx(0.03)
    assert dense["phi_abs"] == pytest.approx(0.002)
    assert errors.filter(pl.col("zone") == "wall").is_empty()  # the boundary bin only
    table = vd.verdict_table(errors)
    row = {(r["W"], r["zone"]): r for r in table.iter_rows(named=True)}
    assert row[(60.0, "dense")]["u"] == "within" and row[(60.0, "dense")]["phi"] == "within"
    assert row[(20.0, "dense")]["u"] == "outside" and row[(20.0, "dense")]["phi"] == "outside"
    assert row[(60.0, "plug")]["phi"] == ""
    assert vd.answer(table).startswith("Yes, with nonlocal: at W >= 60 (60)")
    assert vd.answer(table, wide=20).startswith("No")
    assert vd.answer(table, wide=100).startswith("Cannot tell: no run at W >= 100")
    with pytest.raises(ParameterError, match="u_target"):
        vd.verdict_table(errors, u_target=-1)


def test_a_model_profile_on_other_bins_is_refused():
    case, model = _run(60.0, 0.0, 0.0)
    with pytest.raises(ParameterError, match="profiles"):
        vd.zone_errors([case], model.head(5))
