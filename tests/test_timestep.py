"""granflow.studies.timestep: work-precision studies (binary collision against the analytic e_n,
a generic scene study on the periodic gas)."""

from __future__ import annotations

import sys

import granflow as gf
import numpy as np
import polars as pl
import pytest
from granflow.analysis.collision import collision_law, head_on_collision
from granflow.studies import timestep as ts


@pytest.fixture(scope="module")
def collision():
    return ts.binary_collision_study(phases=8)


def test_binary_collision_converges_to_analytic_e_n(collision):
    t = collision
    assert t.columns == list(ts.SCHEMA)
    en = t.filter(pl.col("observable") == "e_n").sort("frac")
    assert en["dt_label"].to_list() == ["t_c/10", "t_c/20", "t_c/50", "t_c/100", "t_c/200"]
    dev = np.abs(en["deviation"].to_numpy())
    # measured (phase mean over 8 contact onsets): 8.9e-3, 2.3e-3, 3.6e-4, 9.2e-5, 2.3e-5
    assert dev[2] < 1e-3
    assert np.all(np.diff(dev) < 0)
    assert dev[-1] < 1e-4
    # about second order: t_c/100 -> t_c/200 divides the error by ~4
    assert 3.0 < dev[3] / dev[4] < 5.0
    worst = t.filter(pl.col("observable") == "e_n_max_error").sort("frac")
    assert np.all(worst["value"].to_numpy() >= dev - 1e-15)
    assert (en["wall_time"].to_numpy() > 0).all()
    assert np.allclose(en["dt"].to_numpy() * en["frac"].to_numpy(), en["dt"][0] * 10)


def test_single_collision_energy_and_overlap():
    law = collision_law(0.5, 1e7)
    c = head_on_collision(law, phase=0.25)
    assert c.finite and 0 < c.max_overlap < 0.01
    assert c.dt == pytest.approx(c.t_c / 50)
    assert c.e_n == pytest.approx(0.5, abs=3e-3)
    # energy left after the collision: e_n^2 of the initial (head-on, no rotation)
    assert c.energy_after / c.energy_before == pytest.approx(c.e_n**2, rel=1e-6)


def test_refusals():
    with pytest.raises(gf.ParameterError, match="fracs"):
        ts.binary_collision_study(fracs=(5, 50))
    with pytest.raises(gf.ParameterError, match="xi_n"):
        head_on_collision(collision_law(None, 1e6, xi_n=1e5))
    with pytest.raises(gf.ParameterError, match="phase"):
        head_on_collision(collision_law(), phase=1.5)


def test_scene_study_on_gas_and_plot(tmp_path):
    obs = {"ke": ts.kinetic_energy}
    t = ts.scene_study(ts.gas_factory(), obs, fracs=(10, 20, 50, 100), steps_time=0.1)
    ke = t.filter(pl.col("observable") == "ke").sort("frac")
    dev = np.abs(ke["deviation"].to_numpy())
    assert dev[-1] == 0.0  # the finest run is the reference
    # short run (about one collision per particle): the kinetic energy converges with dt
    # (measured: 2.5, 0.95, 0.19 against t_c/100, of 202)
    assert np.all(np.diff(dev[:-1]) < 0)
    assert np.all(ke["steps"].to_numpy() * ke["dt"].to_numpy() == pytest.approx(0.1, rel=0.02))
    png = ts.work_precision_plot(t, tmp_path / "wp.png")
    assert png.exists()
    assert "t_c/10" in ts.format_table(t)


def test_scene_study_series_observable():
    from granflow.scenes import PeriodicGas

    def factory(dt):  # the gas scene has no dt parameter: only its default is studied here
        return PeriodicGas(L=8.0, phi=0.2, sample_every=10, seed=1)

    t = ts.scene_study(factory, ["ke_trans"], fracs=(50,), steps_time=0.05)
    assert t.height == 1 and t["deviation"][0] == 0.0 and t["value"][0] > 0


def test_sheared_packing_without_the_cell_is_a_clear_error(monkeypatch):
    from granflow import scenes

    monkeypatch.setitem(sys.modules, "granflow.scenes.cell", None)  # import fails: module missing
    monkeypatch.delitem(scenes.SCENES, "cell", raising=False)
    with pytest.raises(gf.GranflowError, match="stress-controlled cell"):
        ts.sheared_packing_study()


def test_sheared_packing_with_the_cell_as_built():
    """Runs a tiny study when the kernel has the cell; a clear error when it does not yet."""
    from granflow import _core

    kw = {"params": {"N": 60}, "fracs": (12, 50), "time_tc": 2.0, "warmup_tc": 50.0}
    if not hasattr(_core, "cell_sim"):
        with pytest.raises(gf.GranflowError, match="rebuild"):
            ts.sheared_packing_study(**kw)
        return
    t = ts.sheared_packing_study(**kw)
    assert set(t["observable"]) == {"mu1", "phi", "I"}
    assert t.filter(pl.col("frac") == 50)["deviation"].to_list() == [0.0, 0.0, 0.0]
    assert np.isfinite(t["value"].to_numpy()).all()
