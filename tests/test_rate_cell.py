"""The rate-controlled cell (issue 35): the imposed rate, the held normal stress, bad input,
restarts and threads. Small N."""

import granflow as gf
import numpy as np
import polars as pl
import pytest
from granflow.analysis.stats import blocking
from granflow.scenes import RateCell


def _sheared(c):
    s = pl.from_arrow(c.tables()["series"])
    return s.filter(pl.col("t") > c.shear_start_time)


@pytest.fixture(scope="module")
def yy():
    c = RateCell(N=300, p_ext=1e-3, inertial_number=0.02, normal="yy", sample_every=1,
                 seed=3)
    c.run(8000, progress=False)
    return c


def test_the_tilt_follows_the_rate_while_the_gradient_length_breathes(yy):
    s = _sheared(yy)
    dt = yy.timestep
    hxy, hyy = s["H_xy"].to_numpy(), s["H_yy"].to_numpy()
    flips = s["tilt_flips"].to_numpy()
    same = np.diff(flips) == 0  # a flip remaps the tilt by a box length
    rate = np.diff(hxy)[same] / (dt * hyy[:-1][same])
    assert np.abs(rate / yy.shear_rate - 1).max() < 1e-6
    assert hyy.std() > 1e-6 * hyy.mean()  # the gradient length does move
    # sigma_yy alone is driven: x and z keep their lengths, no xz / yz tilt
    for c in ("L_xx", "L_zz", "L_xz", "L_yz"):
        assert (s[c] == 0).all(), c
    assert (s["L_xy"] == yy.shear_rate).all()


def test_the_pressure_form_breathes_isotropically():
    c = RateCell(N=200, p_ext=1e-3, inertial_number=0.02, sample_every=50, seed=2)
    c.run(4000, progress=False)
    s = _sheared(c)
    assert (s["L_xy"] == c.shear_rate).all()
    assert np.array_equal(s["L_xx"], s["L_yy"]) and np.array_equal(s["L_xx"], s["L_zz"])
    assert s["L_xx"].abs().max() > 0


def test_the_normal_stress_is_held_at_its_target():
    c = RateCell(N=300, p_ext=1e-3, inertial_number=0.02, normal="yy", sample_every=20,
                 seed=4)
    c.run(60_000, progress=False)
    s = _sheared(c).tail(2000)
    b = blocking(s["sigma_yy"].to_numpy())
    assert abs(b.mean - 1e-3) < 3 * b.se
    # a flowing steady state: positive shear stress ratio, sheared at the rate
    assert s["mu1"].mean() > 0.2
    assert s["I"].mean() == pytest.approx(0.02, rel=0.2)  # I at p, not sigma_yy
    for col in s.columns:
        assert s[col].is_finite().all()


@pytest.mark.parametrize(
    ("kw", "name"),
    [
        ({"inertial_number": -0.01}, "inertial_number"),
        ({"inertial_number": 0.0}, "inertial_number"),
        ({"inertial_number": float("nan")}, "inertial_number"),
        ({"inertial_number": float("inf")}, "inertial_number"),
        ({"normal": "xx"}, "normal"),
        ({"p_ext": 0.0}, "p_ext"),
        ({"p_ext": -1e-4}, "p_ext"),
        ({"tau_ratio": 0.3}, "tau_ratio"),
        ({"omega_g_factor": 1e3}, "omega_g_factor"),
        ({"omega_g_factor": 0.0}, "omega_g_factor"),
    ],
)
def test_bad_input(kw, name):
    with pytest.raises(gf.ParameterError, match=name):
        RateCell(N=60, **kw)


def test_set_rate_checks_its_values_and_its_domain():
    c = RateCell(N=60, p_ext=1e-3, sample_every=None, start="dilute")
    c.prepare()
    for bad in (-1e-4, float("nan"), float("inf")):
        with pytest.raises(gf.ParameterError, match="shear rate"):
            c.core.set_rate(bad, 1e-3)
    with pytest.raises(gf.ParameterError, match="p_ext"):
        c.core.set_rate(1e-4, 0.0)
    gas = gf.scenes.PeriodicGas(L=6.0, seed=1)
    gas.prepare()
    with pytest.raises(gf.ParameterError, match="imposed rate"):
        gas.core.set_rate(1e-4, 1e-3)


@pytest.mark.parametrize("normal", ["pressure", "yy"])
def test_checkpoint_restart_is_bitwise(tmp_path, normal):
    kw = dict(N=80, p_ext=1e-3, inertial_number=0.05, normal=normal, sample_every=100, seed=5)
    a = RateCell(**kw)
    a.run(2000, progress=False)
    a.save_checkpoint(tmp_path / "c.gfck")
    a.run(1000, progress=False)
    b = RateCell(**kw)
    b.restore(tmp_path / "c.gfck")
    b.run(1000, progress=False)
    assert np.array_equal(a.core.positions(), b.core.positions())
    assert a.core.cell() == b.core.cell()
    assert dict(a.core.domain_observables()) == dict(b.core.domain_observables())


def test_a_stress_checkpoint_does_not_restore_as_a_rate_cell(tmp_path):
    a = gf.scenes.ShearCell(N=60, p_ext=1e-3, sample_every=None, seed=1)
    a.run(500, progress=False)
    a.save_checkpoint(tmp_path / "c.gfck")
    with pytest.raises(gf.ParameterError, match="rate_cell"):
        RateCell(N=60, p_ext=1e-3, sample_every=None, seed=1).restore(tmp_path / "c.gfck")


def test_same_numbers_for_any_thread_count():
    tabs = []
    for threads in (1, 2):
        c = RateCell(N=300, p_ext=1e-3, inertial_number=0.02, normal="yy", sample_every=100,
                     seed=6, threads=threads)
        c.run(3000, progress=False)
        tabs.append(c.tables()["series"])
    assert tabs[0].equals(tabs[1])
