"""Vertical channel (000): preparation, statistics, balances, bad input. Small channels."""

import json

import granflow as gf
import numpy as np
import polars as pl
import pytest
from granflow import _core
from granflow.scenes.channel import Channel
from reference_samplers import cap_volume_below


@pytest.fixture(scope="module")
def flowing():
    # (the soft pour: it packs phi_bar = 0.61 in this small channel, the rain does not)
    c = Channel(W=8, H=12, B=4, phi_bar=0.61, kn=1e5, dt=3e-4, seed=2, sample_every=20,
                window=10, threads=2, preparation="pour")
    c.run(6000)
    return c


def test_preparation_hits_phi_bar(flowing):
    c = flowing
    info = c.prep_info
    vmax = np.pi * 1.1**3 / 6
    assert abs(info["phi_bar_achieved"] - 0.61) < vmax / (8 * 12 * 4)
    d = c.core.diameters()
    assert info["phi_bar_achieved"] == pytest.approx(np.sum(np.pi * d**3 / 6) / (8 * 12 * 4))
    # the 30/40/30 % mix by number
    frac = [np.mean(np.isclose(d, s)) for s in (0.9, 1.0, 1.1)]
    assert np.allclose(frac, [0.3, 0.4, 0.3], atol=1.5 / len(d))


def test_scene_contains_only_what_it_needs(flowing):
    comps = flowing.core.components()
    assert "walls: 2 planes" in comps and any("gravity" in c for c in comps)
    assert not any(w in c.lower() for c in comps for w in ("triclinic", "barostat", "parrinello"))


def test_bins_tile_the_channel_and_sphere_slab_volumes():
    c = Channel(W=8.3, H=12, B=4)
    e = c.bin_edges()
    assert e[0] == 0 and e[-1] == 8.3 and np.all(np.diff(e) > 0)
    assert np.isclose(e[1], 1.5) and np.isclose(8.3 - e[-2], 1.5)
    # a sphere's slices over any bins sum to its volume
    r = np.array([0.55])
    xc = 3.7
    below = cap_volume_below(np.array(e)[None, :] - xc, r[:, None])
    assert np.isclose(np.diff(below[0]).sum(), 4 / 3 * np.pi * 0.55**3)


def test_momentum_balance_walls_carry_weight_less_momentum_change(flowing):
    s = pl.from_arrow(flowing.tables()["series"])
    m = flowing.core.masses().sum()
    t, py, iy = s["t"].to_numpy(), s["py"].to_numpy(), s["wall_impulse_y"].to_numpy()
    # dP_y = -M g dt - (impulse on the walls): exact for the discrete trajectory
    lhs = py[-1] - py[0]
    rhs = -m * (t[-1] - t[0]) - (iy[-1] - iy[0])
    assert abs(lhs - rhs) <= 0.02 * m * (t[-1] - t[0])
    assert abs(lhs - rhs) <= 1e-8 * m * (t[-1] - t[0])  # in fact to round-off


def test_sigma_xx_uniform_and_wall_bins_include_wall_contacts(flowing):
    b = pl.from_arrow(flowing.tables()["bins"])
    late = b.filter(pl.col("window") >= b["window"].max() // 2)
    g = late.group_by("bin").agg(
        pl.col("sigma_xx").mean().alias("m"), pl.col("sigma_xx").std().alias("s"),
        pl.len().alias("n"), pl.col("x").first()).sort("bin")
    se = (g["s"] / np.sqrt(g["n"])).to_numpy()
    mean = g["m"].to_numpy()
    overall = mean.mean()
    assert np.all(np.abs(mean - overall) < 5 * np.sqrt(se**2 + se.mean() ** 2) + 0.15 * overall)
    # the wall bins carry the wall's normal stress: without wall contacts they would be far
    # below the interior (LAMMPS's per-atom stress leaves walls out)
    assert mean[0] > 0.5 * overall and mean[-1] > 0.5 * overall
    s = pl.from_arrow(flowing.tables()["series"])
    wall_sxx = 0.5 * (-s["wall0_sigma_xx"] + s["wall1_sigma_xx"]).mean()
    assert wall_sxx == pytest.approx(overall, rel=0.35)


def test_momentum_balance_per_bin(flowing):
    """-d sigma_xy/dx + rho phi g_y = rho phi du_y/dt per bin, within the binned errors."""
    b = pl.from_arrow(flowing.tables()["bins"])
    nw = int(b["window"].max()) + 1
    xs = b.filter(pl.col("window") == 0)["x"].to_numpy()
    sxy = b["sigma_xy"].to_numpy().reshape(nw, -1)
    phi = b["phi"].to_numpy().reshape(nw, -1)
    uy = b["u_y"].to_numpy().reshape(nw, -1)
    t1 = b["t1"].to_numpy().reshape(nw, -1)[:, 0]
    # windows in the second half; acceleration from the change of the bin velocity
    k0 = nw // 2
    dudt = (uy[-1] - uy[k0]) / (t1[-1] - t1[k0])
    ds = np.gradient(sxy[k0:].mean(0), xs)
    lhs = -ds
    rhs = phi[k0:].mean(0) * (1.0 + dudt)  # rho_p = 1, g = 1 along -y
    err = np.gradient(sxy[k0:].std(0) / np.sqrt(nw - k0), xs)
    inner = slice(1, -1)
    resid = lhs[inner] - rhs[inner]
    scale = np.abs(rhs[inner]).mean()
    assert np.sqrt(np.mean(resid**2)) < 0.05 * scale + 3 * np.abs(err[inner]).mean()


@pytest.mark.parametrize(
    "kw, name",
    [({"W": 2.0}, "W"), ({"phi_bar": 0.7}, "phi_bar"), ({"phi_bar": 0.0}, "phi_bar"),
     ({"sizes": {-1.0: 1.0}}, "sizes"), ({"H": 1.0}, "H"), ({"window": 0}, "window")],
)
def test_bad_input_is_refused_before_anything_runs(kw, name):
    with pytest.raises(gf.ParameterError, match=name):
        Channel(**kw)


def test_no_nan_in_tables(flowing):
    for t in flowing.tables().values():
        for col in t.columns:
            a = col.to_numpy()
            if a.dtype.kind == "f":
                assert np.isfinite(a).all()


def test_channel_checkpoint_restart_is_bitwise(tmp_path):
    kw = dict(W=6, H=8, B=3.5, phi_bar=0.6, kn=1e5, dt=3e-4, seed=4, sample_every=50,
              window=4, preparation="pour")
    a = Channel(**kw)
    a.run(500)
    a.save_checkpoint(tmp_path / "c.gfck")
    a.run(500)
    b = Channel(**kw)
    b.restore(tmp_path / "c.gfck")
    b.run(500)
    assert np.array_equal(a.core.positions(), b.core.positions())
    assert np.array_equal(a.core.angular_velocities(), b.core.angular_velocities())
    assert b.prep_info == a.prep_info and b.achieved_phi_bar == a.achieved_phi_bar
    # one checkpoint header for every scene: the scene, its parameters, its state
    head = json.loads(_core.read_checkpoint_header(str(tmp_path / "c.gfck"))[1])["scene"]
    assert head["scene"] == "channel" and head["state"] == a.prep_info
    assert head["parameters"]["n"] == a.prep_info["n"] and head["parameters"]["mu"] is None
    assert not (tmp_path / "c.gfck.prep.json").exists()  # no side-car
