"""granflow.continuum.wall_layer: the wall layer's local laws per distance, fitted back from
profiles they made, predicting a run they were not fitted on; refusals."""

from __future__ import annotations

import math

import numpy as np
import polars as pl
import pytest
from granflow.continuum.channel_model import ChannelCase
from granflow.continuum.wall_layer import (
    LayerLaws,
    fit_layer_laws,
    layered_table,
    predict_layered,
)
from granflow.errors import ParameterError
from model_law import MODEL_LAW

LAW = MODEL_LAW
XI = (0.75, 2.0, 3.0, 4.0)
LAWS = LayerLaws(XI, (40.0, 20.0, 18.0, 19.0), (4.0, 4.2, 4.6, 4.8), "made up")


class _Cal:
    law = LAW


def made_case(sigma_xx: float, W: float = 40.0) -> ChannelCase:
    """A run whose profile the layered model itself made with LAWS (bulk A = 0.45, phi 0.6):
    its u, and the first bulk bin's shear rate from the last law."""
    xi = np.concatenate([XI, np.arange(5.0, W / 2 + 0.5, 1.0)])
    n = xi.size
    base = pl.DataFrame({"xi": xi, "u": np.zeros(n), "gamma_dot": np.ones(n),
                         "mu": np.full(n, 0.2), "phi": np.full(n, 0.6),
                         "zone": ["wall"] * 2 + ["dense"] * (n - 2)})
    case = ChannelCase(W, 0.6, 1e5, base.with_columns(pl.col("u") + 3.0), sigma_xx, 3.0, 1)
    u = predict_layered(case, LAWS, LAW, 0.45).u
    mu_b = 0.6 * (W / 2 - 4.0) / sigma_xx  # (B2) with phi = 0.6
    gd = base["gamma_dot"].to_numpy().copy()
    gd[3] = math.sqrt(sigma_xx) * LAWS.c[3] * mu_b ** LAWS.n[3]
    return ChannelCase(W, 0.6, 1e5, base.with_columns(pl.Series("u", u),
                                                      pl.Series("gamma_dot", gd)),
                       sigma_xx, 3.0, 1)


def test_the_laws_are_fitted_back_from_the_profiles_they_made_and_predict_another_run():
    fitted = fit_layer_laws([made_case(s) for s in (28.0, 32.0, 38.0)])
    assert fitted.x == XI
    np.testing.assert_allclose(fitted.c, LAWS.c, rtol=1e-6)
    np.testing.assert_allclose(fitted.n, LAWS.n, rtol=1e-6)
    # the runs pack at 0.6 everywhere: the layer's packing laws are flat at 0.6, and the
    # prediction's phi is 0.6 in the layer and the law's phi(I) (0.6) beyond
    np.testing.assert_allclose(fitted.phi_a, 0.6, atol=1e-9)
    np.testing.assert_allclose(fitted.phi_b, 0.0, atol=1e-9)
    other = made_case(45.0, W=60.0)
    np.testing.assert_allclose(predict_layered(other, fitted, LAW, 0.45).phi, 0.6, atol=1e-9)
    t = layered_table([other], {1e-4: _Cal()}, fitted, 0.45)  # type: ignore[dict-item]
    assert t["u_rel"][0] < 1e-6 and t["du_ratio"][0] == pytest.approx(1.0, abs=1e-6)


def test_a_steeper_law_shears_the_layer_more():
    case = made_case(32.0)
    steep = LayerLaws(XI, tuple(2 * c for c in LAWS.c), LAWS.n, "steeper")
    u0, u1 = (predict_layered(case, laws, LAW, 0.45).u for laws in (LAWS, steep))
    assert np.all(np.diff(u1[:4]) > np.diff(u0[:4]))


def test_one_run_or_runs_binned_otherwise_are_refused():
    with pytest.raises(ParameterError, match=">= 2"):
        fit_layer_laws([made_case(30.0)])
    odd = made_case(30.0)
    shifted = ChannelCase(odd.W, odd.phi_bar, odd.kn,
                          odd.profile.with_columns(pl.col("xi") + 0.25), odd.sigma_xx,
                          odd.delta_095, odd.seed)
    with pytest.raises(ParameterError, match="binned alike"):
        fit_layer_laws([made_case(30.0), shifted])
    with pytest.raises(ParameterError, match="not the laws'"):
        predict_layered(shifted, LAWS, LAW, 0.45)


def test_the_example_fits_the_committed_runs_and_predicts_the_widths_run():
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).parent.parent
    out = subprocess.run([sys.executable, "examples/wall_layer_transfer.py"], cwd=root,
                         capture_output=True, text=True, timeout=300, check=True).stdout
    assert "laws fitted on 3 runs at W = 40" in out and "u_rel" in out
