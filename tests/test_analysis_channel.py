"""Tests of granflow.analysis.channel on synthetic channel tables with known answers."""

from __future__ import annotations

import numpy as np
import polars as pl
import pyarrow as pa
import pytest
from granflow.analysis import channel as ch
from granflow.analysis import channel_profiles as cp
from granflow.analysis import plots
from granflow.states import FlowState

US, UM, DELTA, W = 3.0, 4.2, 8.0, 40.0
LC, TC, D_PHI, SXX = 11.5, 1e-4, 5.0, 100.0


def phi_profile(xi: np.ndarray) -> np.ndarray:
    """phi = 0.63 in the plug, crossing phi_ad = 0.587 at xi = 6 ln(0.1/0.043) = 5.063."""
    return 0.63 - 0.1 * np.exp(-xi / 6.0)


XI_AD = 6.0 * np.log(0.1 / 0.043)


def synthetic_bins(
    nw: int = 64, noise_u: float = 0.02, rel: float = 0.01, seed: int = 0, t_first: float = 2000.0
) -> tuple[pa.Table, dict[str, np.ndarray]]:
    """A channel ``bins`` table: 1.5 d wall bins, 1 d interior bins, the velocity of (3.1)
    (measured from the wall), Omega_z = (du_y/dx)/2, T = (B13) in the plug, Gamma = D_phi T^1.5,
    uniform sigma_xx and a linear sigma_xy; independent noise in every window."""
    rng = np.random.default_rng(seed)
    edges = np.concatenate([[0.0], np.arange(1.5, W - 1.5 + 0.01, 1.0), [W]])
    x_lo, x_hi = edges[:-1], edges[1:]
    x = 0.5 * (x_lo + x_hi)
    nb = x.size
    xi = np.minimum(x, W - x)
    u = ch.velocity_profile_31(xi, US, UM, DELTA)
    # the gradient as the analysis measures it on the bins (finite differences of the profile)
    duy_dx = np.gradient(-u, x)
    phi = phi_profile(xi)
    T = ch.conduction_profile_B13(W / 2 - xi, TC, LC) + 0.5 * np.exp(-2 * xi)
    sxy = -0.6 * (x - W / 2)
    cols: dict[str, list[np.ndarray]] = {}

    def add(k: str, v: np.ndarray) -> None:
        cols.setdefault(k, []).append(np.asarray(v))

    for w in range(nw):
        add("window", np.full(nb, w))
        add("t0", np.full(nb, t_first + 10.0 * w))
        add("t1", np.full(nb, t_first + 10.0 * (w + 1)))
        add("n_samples", np.full(nb, 100))
        add("bin", np.arange(nb))
        add("x_lo", x_lo)
        add("x_hi", x_hi)
        add("x", x)
        add("phi", phi + 0.001 * rng.normal(size=nb))
        add("u_y", -u + noise_u * rng.normal(size=nb))
        add("w_z", 0.5 * duy_dx + 1e-4 * rng.normal(size=nb))
        add("T", T * (1 + rel * rng.normal(size=nb)))
        add("sigma_xx", SXX * (1 + rel * rng.normal(size=nb)))
        add("sigma_xy", sxy + rel * rng.normal(size=nb))
        add("Gamma", D_PHI * T**1.5 * (1 + rel * rng.normal(size=nb)))
        add("shear_production", sxy * duy_dx)
    tab = {k: np.concatenate(v) for k, v in cols.items()}
    for k in ("window", "bin", "n_samples"):
        tab[k] = tab[k].astype(np.int64)
    return pa.table(tab), {
        "x": x,
        "xi": xi,
        "u": u,
        "duy_dx": duy_dx,
        "phi": phi,
        "T": T,
        "sxy": sxy,
    }


def synthetic_series(kind: str, n: int = 4000, seed: int = 0) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.5
    v = {
        "steady": 3.0 * (1 + 0.001 * rng.normal(size=n)),
        "accelerating": 0.5 + 0.05 * t + 0.01 * rng.normal(size=n),
        "arrested": 1e-5 * rng.normal(size=n),
        "fluctuating": 3.0 * (1 + 0.02 * np.sin(2 * np.pi * t / 37.0) + 0.001 * rng.normal(size=n)),
        "decelerating": np.maximum(3.0 - 0.002 * t, 0.1) + 0.001 * rng.normal(size=n),
    }[kind]
    return {"step": np.arange(n), "t": t, "vcm_x": 0 * t, "vcm_y": -v, "vcm_z": 0 * t}


@pytest.fixture(scope="module")
def run():
    tab, truth = synthetic_bins()
    return ch.summary(tab), truth


def test_velocity_scaling_recovers_31(run):
    s, truth = run
    # (u_slip, u_max) by the paper's definitions: wall-bin and centre-bin velocities
    for key, true in (("u_slip", truth["u"][0]), ("u_max", truth["u"][len(truth["u"]) // 2])):
        assert abs(s[key].value - true) < 4 * s[key].se
        assert 0 < s[key].se < 0.005
    # three-parameter fit of (3.1): the generating parameters
    for key, true in (("u_slip_fit", US), ("u_max_fit", UM), ("delta_fit", DELTA)):
        assert abs(s[key].value - true) < 4 * s[key].se, key
        assert s[key].se < 0.02 * true
    # delta_0.95 with x from the wall and u_slip at the wall-bin centre: continuous answer
    xi0, xic = 0.75, W / 2
    f = lambda z: 1 - np.exp(-3 * z / DELTA)  # noqa: E731
    target = f(xi0) + 0.95 * (f(xic) - f(xi0))
    d_true = -DELTA / 3 * np.log(1 - target)
    assert abs(s["delta_095"].value - d_true) < 4 * s["delta_095"].se + 0.05
    assert s["u_max_over_u_slip"].value == pytest.approx(
        s["u_max"].value / s["u_slip"].value
    )
    assert s["residual_fit"].value < 0.005  # (3.1) describes the data
    # (3.2) against the width-averaged profile (differences: wall-bin offset of u_slip)
    assert s["mean_velocity_ratio"].value == pytest.approx(1.0, abs=0.01)
    assert s["mean_velocity"].value == pytest.approx(
        np.mean(ch.velocity_profile_31(np.linspace(0, W / 2, 20001), US, UM, DELTA)), rel=2e-3
    )


def test_zones(run):
    s, truth = run
    z = s["zones"]
    labels = z["labels"]
    xi = s["profile"]["xi"].to_numpy()
    assert labels[0] == "wall" and labels[-1] == "plug"
    assert all(lab == "wall" for lab, x in zip(labels, xi, strict=True) if x <= 2.0)
    # zones are ordered wall < loose < dense < plug going inward
    order = {"wall": 0, "loose": 1, "dense": 2, "plug": 3}
    assert all(order[a] <= order[b] for a, b in zip(labels, labels[1:], strict=False))
    # the shear rate is large (>> its SE) for xi < 8, so the plug starts beyond
    assert 8.0 < z["xi_plug"] < W / 2
    assert abs(z["xi_ad"].value - XI_AD) < 4 * z["xi_ad"].se + 0.1
    plug = np.array([lab == "plug" for lab in labels])
    phi_plug_true = np.mean(phi_profile(xi[plug]))
    assert abs(z["phi_plug"].value - phi_plug_true) < 4 * z["phi_plug"].se + 1e-5


def test_zone_means_weight_bins_by_width():
    tab, _ = synthetic_bins()
    prof = cp.profiles(tab)
    zn = ch.zones(prof)
    means = ch.zone_means(prof, zn)
    q = prof.derived()
    width = prof.xi_hi - prof.xi_lo
    for zone, est in means.items():
        idx = np.array([i for i, lab in enumerate(zn.labels) if lab == zone])
        assert est["phi"].value == pytest.approx(np.average(q["phi"][idx], weights=width[idx]))
        assert 0 < est["phi"].se < 0.01
    # phi rises from the wall to the plug (phi_profile), so do the zone means
    assert means["wall"]["phi"].value < means["dense"]["phi"].value < means["plug"]["phi"].value


def test_fit_phi_ad_recovers_the_divergence():
    rng = np.random.default_rng(3)
    phi = np.linspace(0.45, 0.58, 10)
    y = 2.0 / (0.59 - phi) * (1 + 0.03 * rng.standard_normal(phi.size))
    f = ch.fit_phi_ad(phi, y, 0.03 * np.abs(y))
    assert abs(f["phi_ad"] - 0.59) < 3 * f["phi_ad_se"] and f["phi_ad_se"] < 0.003
    assert f["n"] == 10 and f["chi2_per_dof"] < 3
    # too few bins: no fit
    assert np.isnan(ch.fit_phi_ad(phi[:2], y[:2], y[:2] * 0.03)["phi_ad"])


def test_conduction_length_and_kinetic_coefficients(run):
    s, truth = run
    lc = s["conduction"]["l_c"]
    assert abs(lc.value - LC) < 3 * lc.se + 0.05
    assert lc.se < 0.1 * LC
    p = s["profile"]
    shear = p.filter(pl.col("zone").is_in(["dense", "loose"]))
    # D_phi = Gamma / T^1.5 and p_phi = sigma_xx / T (B8, B10)
    d_phi = shear["D_phi"].to_numpy()
    assert np.all(np.abs(d_phi - D_PHI) < 4 * shear["D_phi_se"].to_numpy() + 1e-3)
    np.testing.assert_allclose(shear["p_phi"].to_numpy() * shear["T"].to_numpy(), SXX, rtol=0.01)
    # Omega_z / (du_y/dx) = 1/2 in the shearing zones
    om = s["omega_ratio_shearing"]
    assert abs(om.value - 0.5) < 4 * om.se and om.se < 0.01
    assert s["sigma_xx_mean"].value == pytest.approx(SXX, rel=1e-3)


def test_mu_I_table(run):
    s, truth = run
    r = s["rheology"].filter(pl.col("zone") != "plug")
    h = r.height
    mu_true = np.abs(truth["sxy"][:h] / SXX)
    I_true = np.abs(truth["duy_dx"][:h]) / np.sqrt(SXX)
    mu, mu_se = r["mu"].to_numpy(), r["mu_se"].to_numpy()
    assert np.all(np.abs(mu - mu_true) < 4 * mu_se + 1e-4)
    inum, inum_se = r["I"].to_numpy(), r["I_se"].to_numpy()
    assert np.all(np.abs(inum - I_true) < 4 * inum_se + 0.01 * I_true)
    assert np.all(inum_se < 0.1 * I_true[0])
    np.testing.assert_allclose(r["mu_B3"].to_numpy(), ch.mu_B3(r["I"].to_numpy()))


def test_B3_B4_and_model_curves():
    assert ch.mu_B3(0.3) == pytest.approx((0.384 + 0.625) / 2)
    assert ch.mu_B3(1e-9) == pytest.approx(0.384, abs=1e-6)
    assert ch.phi_B4(0.0) == pytest.approx(0.6)
    assert ch.phi_B4(0.5) == pytest.approx(0.5)
    assert ch.scaled_profile_31(8.0, 8.0) == pytest.approx(1 - np.exp(-3))  # ~0.95 at delta
    # (3.2) equals the width average of (3.1) over half the channel
    xs = np.linspace(0, 50, 200001)
    avg = np.mean(ch.velocity_profile_31(xs, 2.0, 3.0, 15.0))
    assert ch.mean_velocity_32(2.0, 3.0, 15.0, 100.0) == pytest.approx(avg, rel=1e-5)
    # (B13): T^{3/2} satisfies d2/dx2 T^{3/2} = T^{3/2} / l_c^2
    xc = np.linspace(0, 10, 1001)
    t32 = ch.conduction_profile_B13(xc, 2.0, 4.0) ** 1.5
    d2 = np.gradient(np.gradient(t32, xc), xc)
    np.testing.assert_allclose(d2[5:-5], t32[5:-5] / 16.0, rtol=1e-3)


@pytest.mark.parametrize(
    "kind", ["steady", "accelerating", "arrested", "fluctuating", "decelerating"]
)
def test_flow_state(kind):
    fs = cp.flow_state(synthetic_series(kind))
    assert fs.state is FlowState(kind)  # a member of the one vocabulary, equal to its string
    assert fs.state == kind and f"{fs.state}" == kind
    assert fs.is_steady == (kind in ("steady", "fluctuating"))


def test_flow_state_numbers():
    fs = cp.flow_state(pl.DataFrame(synthetic_series("accelerating")))
    assert fs.slope == pytest.approx(0.05, rel=0.01)
    assert fs.t_stat > 3


def test_summary_input_types_and_series():
    tab, _ = synthetic_bins(nw=48, seed=3, t_first=0.0)
    ser = synthetic_series("steady", n=1000)
    ser["t"] = np.linspace(0, 480, 1000)
    n = ser["t"].size
    for k in ("wall0_sigma_xx", "wall1_sigma_xx"):
        ser[k] = (100.0 if k.startswith("wall0") else -100.0) + np.random.default_rng(1).normal(
            size=n
        )
    ser["wall0_sigma_xy"] = -30.0 + np.random.default_rng(2).normal(size=n)
    ser["wall1_sigma_xy"] = -30.0 + np.random.default_rng(3).normal(size=n)
    s1 = ch.summary(tab, pa.table(ser), start_time=0.0)
    s2 = ch.summary(pl.from_arrow(tab), pl.DataFrame(ser), start_time=0.0)
    s3 = ch.summary({c: tab.column(c).to_numpy() for c in tab.column_names}, ser, start_time=0.0)
    for s in (s2, s3):
        assert s["u_slip"].value == pytest.approx(s1["u_slip"].value)
        assert s["delta_fit"].se == pytest.approx(s1["delta_fit"].se)
    assert s1["flow_state"]["state"] == "steady"
    assert s1["wall_friction"].value == pytest.approx(0.3, abs=4 * s1["wall_friction"].se)
    assert s1["vcm"].value == pytest.approx(3.0, abs=0.01)


def test_unfolded_profile_uses_wall0_half():
    tab, truth = synthetic_bins(nw=32, seed=5)
    prof = cp.profiles(tab, symmetrise=False)
    assert not prof.folded
    est = ch.velocity_scaling(prof)
    assert abs(est["delta_fit"].value - DELTA) < 4 * est["delta_fit"].se


def test_profile_start_time_selects_windows():
    tab, _ = synthetic_bins(nw=40, seed=6, t_first=0.0)
    prof = cp.profiles(tab, start_time=200.0)
    assert prof.t_start >= 200.0 and prof.n_windows <= 20


def test_channel_plots(run, tmp_path):
    s, _ = run
    paths = [
        plots.plot_channel_velocity([("W=40", s)], tmp_path / "fig4.png"),
        plots.plot_channel_fields(s, tmp_path / "fig8.png"),
        plots.plot_channel_mu_phi_I(s, tmp_path / "fig11.png"),
    ]
    for p in paths:
        data = p.read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10000


def test_flow_state_vocabulary_keeps_the_committed_strings():
    import json

    # the strings the committed datasets hold: a member must keep its value
    assert [s.value for s in FlowState] == [
        "steady", "fluctuating", "flowing", "arrested", "accelerating", "decelerating",
        "drifting", "short", "runaway", "failed"]
    s = FlowState.FLUCTUATING
    assert s == "fluctuating" and str(s) == f"{s}" == "fluctuating" and f"{s:>12}".strip() == s
    assert json.dumps({"state": s}) == '{"state": "fluctuating"}'
    assert pl.DataFrame([{"state": s}]).schema["state"] == pl.String  # rows: plain strings
    assert pl.DataFrame({"state": ["fluctuating"]}).filter(pl.col("state") == s).height == 1


def _with_level(tab: pa.Table, level: np.ndarray, shape: np.ndarray | None = None) -> pa.Table:
    """``tab`` with u_y of window w times ``level[w]`` (a mode of the whole flow's speed),
    and its plug (xi > 1.5 DELTA) times ``shape[w]`` beside it (a change of the profile's
    shape)."""
    d = pl.from_arrow(tab)
    w = d["window"].to_numpy()
    f = level[w]
    if shape is not None:
        xi = np.minimum(d["x"].to_numpy(), W - d["x"].to_numpy())
        f = f * np.where(xi > 1.5 * DELTA, shape[w], 1.0)
    return d.with_columns(u_y=pl.col("u_y") * f).to_arrow()


def test_the_shape_has_an_se_on_its_own_correlation_time_where_the_level_wanders():
    # (the flow's speed wanders over the whole record: the run's blocks, chosen on the mean
    # velocity, are too few for any SE; the ratio u_max/u_slip does not see a common factor)
    nw = 400
    level = 1 + 0.05 * np.sin(2 * np.pi * 1.5 * np.arange(nw) / nw)
    # (the truth on the bins: the wall bin's velocity and the central one's, without noise)
    exact = cp.profiles(synthetic_bins(nw=4, noise_u=0.0)[0], start_time=2000.0)
    truth = ch.velocity_scaling(exact)["u_max_over_u_slip"].value
    zs = []
    for seed in range(10):
        tab = _with_level(synthetic_bins(nw=nw, seed=seed)[0], level)
        prof = cp.profiles(tab, start_time=2000.0)
        assert prof.n_blocks < 10
        assert np.isnan(ch.velocity_scaling(prof)["u_max_over_u_slip"].se)
        own = ch.own_blocked(tab, 2000.0)["u_max_over_u_slip"]
        assert own.n_blocks >= 10 and own.tau < 20.0  # (windows of 10: white noise, tau 5)
        assert np.isfinite(own.estimate.se)
        zs.append((own.estimate.value - truth) / own.estimate.se)
    # honest SEs: z over independent runs has unit rms (10 runs: 0.55-1.45 at 95 %)
    assert 0.55 < float(np.sqrt(np.mean(np.square(zs)))) < 1.45


def test_a_drifting_shape_gets_no_se_on_its_own_correlation_time():
    nw = 400
    tab, _ = synthetic_bins(nw=nw, seed=3)
    drift = _with_level(tab, np.ones(nw), shape=1 + 0.02 * np.arange(nw) / nw)
    own = ch.own_blocked(drift, 2000.0)["u_max_over_u_slip"]
    assert own.drift_z > 3.0 and np.isnan(own.estimate.se)
    steady = ch.own_blocked(tab, 2000.0)["u_max_over_u_slip"]
    assert steady.drift_z < 3.0 and np.isfinite(steady.estimate.se)
