"""Stress-controlled cell (002): compaction, imposed stress, fabric, bad input. Small N."""

import granflow as gf
import numpy as np
import polars as pl
import pytest
from granflow.analysis.stats import mean_se
from granflow.material import MATERIAL_002
from granflow.scenes.cell import ShearCell, fabric
from granflow.sizes import mono


def _series(c):
    return pl.from_arrow(c.tables()["series"])


@pytest.fixture(scope="module")
def sheared():
    c = ShearCell(N=300, mu=0.3, p_ext=1e-3, tau_ratio=0.5, sample_every=100, seed=3)
    c.run(60_000)
    return c


def test_tau_zero_compacts_isotropically_without_shear():
    c = ShearCell(N=200, mu=0.3, p_ext=1e-3, tau_ratio=0.0, sample_every=100, seed=2)
    c.run(30_000)
    s = _series(c)
    last = s.tail(50)
    assert last["phi"].mean() > 0.5  # compacted from 0.05
    # isotropic: F_xx = F_yy = F_zz, no tilt drift
    for a, b in (("F_xx", "F_yy"), ("F_xx", "F_zz")):
        assert np.allclose(last[a], last[b], rtol=1e-12)
    # no drift of the tilt once compacted (a transient shear during compaction stays put)
    assert last["F_xy"].max() - last["F_xy"].min() < 1e-3
    assert np.abs(last["F_xy"]).max() < 0.25
    # the shear rate vanishes within its error: the L_xy mean is zero within 3 SE
    m = mean_se(last["L_xy"].to_numpy())
    assert abs(m.value) < 3 * m.se + 1e-9
    # the internal pressure balances the imposed one
    assert last["p"].mean() == pytest.approx(1e-3, rel=0.1)


def test_steady_flow_holds_the_imposed_stress(sheared):
    s = _series(sheared)
    steady = s.tail(s.height // 2)
    p = mean_se(steady["p"].to_numpy())
    sxy = mean_se(steady["sigma_xy"].to_numpy())
    assert abs(p.value - 1e-3) < max(4 * p.se, 0.03e-3)
    assert abs(-sxy.value - 0.5e-3) < max(4 * sxy.se, 0.03e-3)
    # simple shear in the flow plane
    assert steady["beta"].mean() > 0.9
    assert steady["tilt_flips"].max() > 0  # the tilt grew past half a box and was remapped
    assert steady["mu1"].mean() > 0.3 and steady["shear_rate"].mean() > 0
    for col in s.columns:
        assert s[col].is_finite().all()


def test_fabric_of_hand_built_contacts():
    ex = np.array([[1.0, 0, 0], [-1.0, 0, 0]])
    np.testing.assert_allclose(fabric(ex), np.diag([5.0, -2.5, -2.5]))
    iso = np.vstack([np.eye(3), -np.eye(3)])
    np.testing.assert_allclose(fabric(iso), 0.0, atol=1e-15)
    rng = np.random.default_rng(0)
    n = rng.normal(size=(200_000, 3))
    n /= np.linalg.norm(n, axis=1)[:, None]
    assert np.abs(fabric(n)).max() < 0.05
    assert abs(np.trace(fabric(ex))) < 1e-12


def test_scene_contains_only_what_it_needs():
    c = ShearCell(N=60, p_ext=1e-3, sample_every=10)
    with pytest.raises(gf.ConfigurationError, match="prepare"):
        c.core  # noqa: B018  (built by prepare(), as every scene)
    c.prepare()
    comps = c.core.components()
    assert any("triclinic" in x for x in comps)
    assert not any("walls" in x or "gravity" in x for x in comps)
    assert dict(c.core.memory())["wall history"] == 0


def test_n_is_the_count_that_N_volume_gives():
    # N sets the solid volume (N mean particles); the count is reported as n
    c = ShearCell(N=2000, seed=1)
    assert c.n == 1996 and c.parameters()["n"] == 1996 and c.summary()["n"] == 1996
    with pytest.raises(gf.ParameterError, match="solid volume"):
        ShearCell(N=10)


@pytest.mark.parametrize(
    "kw, name",
    [
        ({"p_ext": 0.0}, "p_ext"),
        ({"tau_ratio": 3.0}, "tau_ratio"),
        ({"N": 10}, "N"),
        ({"kt_ratio": 0.0}, "kt_ratio"),
        ({"e_n": 1.5}, "e_n"),
        ({"form": "walton"}, "form"),
        ({"tc_reading": "mass"}, "tc_reading"),
        ({"sizes": {0.9: 0.3, 1.0: 0.4, 1.1: 0.2}}, "sizes"),
        ({"sizes": {}}, "sizes"),
        ({"sizes": {-1.0: 1.0}}, "sizes"),
        ({"sizes": [1.2, 1.1]}, "sizes"),
        ({"sizes": "big"}, "sizes"),
        ({"mu": -0.1}, "mu"),
        ({"dt": 1.0}, "dt"),
        ({"material": "001"}, "material"),
    ],
)
def test_bad_input(kw, name):
    with pytest.raises(gf.ParameterError, match=name):
        ShearCell(**kw)


def test_cell_checkpoint_restart_is_bitwise(tmp_path):
    a = ShearCell(N=80, p_ext=1e-3, tau_ratio=0.5, sample_every=100, seed=5)
    a.run(2000)
    a.save_checkpoint(tmp_path / "c.gfck")
    a.run(1000)
    b = ShearCell(N=80, p_ext=1e-3, tau_ratio=0.5, sample_every=100, seed=5)
    b.restore(tmp_path / "c.gfck")
    b.run(1000)
    assert np.array_equal(a.core.positions(), b.core.positions())
    assert a.core.cell() == b.core.cell()


def test_contact_time_readings():
    # 002 prints t_c = pi (2 kn/m_e - g^2/4)^(-1/2) with g = 0.5/t_c; the force law's binary
    # collision lasts pi (kn/m_e - g^2/4)^(-1/2), and only then is e_n = exp(-g t_c/2) = exp(-1/4)
    mat = MATERIAL_002.with_(sizes=mono(1.0))  # mean mass pi/6: m_e = pi/12
    kn, m_e = 1.0, np.pi / 12
    tp = mat.contact_time("mean", reading="printed")
    g = 0.5 / tp
    assert tp == pytest.approx(np.pi / np.sqrt(2 * kn / m_e - g * g / 4), rel=1e-12)
    tc = mat.contact_time("mean")
    g = 0.5 / tc
    assert tc == pytest.approx(np.pi / np.sqrt(kn / m_e - g * g / 4), rel=1e-12)
    assert tc / tp == pytest.approx(np.sqrt(2), rel=1e-12)
    # a given restitution: the damped half-period with the rate that gives it
    e = 0.6
    t = mat.with_(e_n=e).contact_time("mean")
    g = -2 * np.log(e) / t
    assert t == pytest.approx(np.pi / np.sqrt(kn / m_e - g * g / 4), rel=1e-12)
    # the default reading is the collision time; 002's printed one is sqrt(2) shorter
    b = ShearCell(N=60, p_ext=1e-3, sample_every=None)
    b.prepare()
    m = b.core.law()
    assert b.t_c == MATERIAL_002.contact_time("mean", b._d)
    assert m["xi_n"] == 0.5 / b.t_c and m["kt"] == m["kn"]
    assert b.core.dt == pytest.approx(0.02 * b.t_c, rel=1e-15)
    assert b.core.dt == MATERIAL_002.dt(b._d)
    c = ShearCell(N=60, p_ext=1e-3, sample_every=None, tc_reading="printed")
    assert b.t_c / c.t_c == pytest.approx(np.sqrt(2), rel=1e-12)
    # the lightest pair is what the kernel reports
    assert MATERIAL_002.contact_time("lightest", b._d) == pytest.approx(b.core.contact_time,
                                                                       rel=1e-12)
    # an absolute dt replaces the rule
    assert ShearCell(N=60, sample_every=None, dt=0.01).timestep == 0.01


def test_cell_takes_the_channels_material():
    # 000's mix by number, kt = 2/7 kn, a restitution, Hertz: all reach the kernel, and it flows
    mix = {0.9: 0.3, 1.0: 0.4, 1.1: 0.3}
    c = ShearCell(N=200, p_ext=1e-4, tau_ratio=0.5, sample_every=100, seed=1, sizes=mix,
                  kt_ratio=2 / 7, e_n=0.8, form="hertz", mu=0.5)
    c.prepare()
    d = np.round(c._d, 9)
    for size, frac in mix.items():
        assert abs(np.count_nonzero(d == size) - frac * len(d)) <= 1
    law = c.core.law()
    assert law["kt"] == pytest.approx(2 / 7 * law["kn"]) and law["e_n"] == 0.8
    assert "xi_n" not in law
    assert any("hertz" in x for x in c.core.components())
    c.run(3000)
    s = _series(c)
    assert s["phi"].is_finite().all() and s["phi"][-1] > s["phi"][0]
    # TOML gives the mix's diameters as strings
    t = ShearCell.from_spec({"N": 60, "p_ext": 1e-3, "sizes": {"0.9": 0.5, "1.1": 0.5}})
    assert sorted(set(np.round(t._d, 9))) == [0.9, 1.1]


def test_compacted_start_compacts_unsheared_then_shears():
    c = ShearCell(N=200, mu=0.3, p_ext=1e-3, tau_ratio=0.5, sample_every=100, seed=2)
    c.prepare()
    t0 = c.shear_start_time
    assert t0 is not None and t0 > 0 and c.core.step > 0
    before = _series(c)
    assert before["t"].max() <= t0
    last = before.tail(20)  # the compaction's last stint: dense, at rest, no shear stress
    assert last["phi"].mean() > 0.55
    assert abs(last["sigma_xy"].mean()) < 0.05e-3
    c.run(20_000)
    after = _series(c).filter(pl.col("t") > t0 + 0.5 * (c.core.time - t0))
    assert abs(-after["sigma_xy"].mean() - 0.5e-3) < 0.05e-3  # tau_ext acts after the switch
    # 002's protocol: shear from t = 0 on the dilute gas, nothing run by prepare
    d = ShearCell(N=60, sample_every=None, start="dilute")
    d.prepare()
    assert d.core.step == 0 and d.shear_start_time == 0.0
    with pytest.raises(gf.ParameterError, match="start"):
        ShearCell(N=60, start="slow")


def test_set_stress_checks_its_values_and_its_domain():
    c = ShearCell(N=60, p_ext=1e-3, sample_every=None, start="dilute")
    c.prepare()
    with pytest.raises(gf.ParameterError, match="tau_ext/p_ext"):
        c.core.set_stress(1e-3, 2.5e-3)
    with pytest.raises(gf.ParameterError, match="p_ext"):
        c.core.set_stress(0.0, 0.0)
    gas = gf.scenes.PeriodicGas(L=6.0, seed=1)
    gas.prepare()
    with pytest.raises(gf.ParameterError, match="stress-controlled"):
        gas.core.set_stress(1e-3, 0.0)
