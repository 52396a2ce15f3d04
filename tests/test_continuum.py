"""granflow.continuum: 1-D channel solutions of the local mu(I) law and the nonlocal fluidity
model, against closed forms (constant phi, linear mu(I)), limits (A -> 0), balances (B2) and
scalings; bad input; sampling of fitted laws."""

from __future__ import annotations

import math
import warnings
from types import SimpleNamespace

import numpy as np
import pytest
from granflow.continuum import (
    ChannelProblem,
    LocalLaw,
    Profile,
    prediction_band,
    solve_local,
    solve_nonlocal,
)
from granflow.errors import GranflowError, ParameterError
from scipy.integrate import quad
from scipy.special import airy

# a law like paper 002's mu_s = 0.3 fits, calibrated up to I = 1
LAW = LocalLaw(
    mu_s=0.38, A_mu=0.7, a_mu=0.8, phi_0=0.60, A_phi=0.3, a_phi=0.8, I_min=1e-3, I_max=1.0
)


def const_phi_law(**kw: float) -> LocalLaw:
    """phi = phi_0 (A_phi tiny), the case (B2) integrates in closed form."""
    p = dict(mu_s=0.3, A_mu=0.5, a_mu=0.7, phi_0=0.6, A_phi=1e-12, a_phi=0.8, I_min=1e-3, I_max=2.0)
    p.update(kw)
    return LocalLaw(**p)


def local_g_wall(law: LocalLaw, **prob: float) -> ChannelProblem:
    """The problem with g_wall = the local g_loc at x0 (no wall boundary layer)."""
    p0 = ChannelProblem(**prob)  # type: ignore[arg-type]
    g_loc = float(solve_local(law, p0).fluidity[0])
    return ChannelProblem(**prob, g_wall=g_loc)  # type: ignore[arg-type]


# ------------------------------------------------------------------------------------------------
# closed forms of the local model
# ------------------------------------------------------------------------------------------------
def test_constant_phi_stress_is_linear_and_plug_width_exact():
    law = const_phi_law()
    prob = ChannelProblem(W=40.0, sigma_xx=20.0, u_wall=0.5)
    prof = solve_local(law, prob)
    # (B2) with phi = phi_0: sigma_xy = rho_p g phi_0 (W/2 - x)
    expected = 1.0 * 1.0 * 0.6 * (20.0 - prof.x)
    np.testing.assert_allclose(prof.sigma_xy, expected, rtol=1e-8, atol=1e-8 * expected[0])
    np.testing.assert_allclose(prof.mu, expected / 20.0, rtol=1e-8, atol=1e-10)
    # plug (mu <= mu_s) half-width mu_s sigma_xx / (rho_p g phi_0) = 0.3 * 20 / 0.6 = 10
    h = prof.x[1] - prof.x[0]
    assert prof.plug_half_width(I_plug=1e-12) == pytest.approx(10.0, abs=h)
    assert np.all(prof.dudx[prof.x > 10.0 + h] == 0.0)
    assert np.all(prof.dudx[prof.x < 10.0 - h] > 0.0)
    assert np.all(prof.u[prof.x > 10.0] == prof.u_max)
    assert prof.u[0] == prob.u_wall and prof.model == "local"


def test_linear_mu_of_I_gives_quadratic_velocity():
    b, mu_s, phi_0 = 0.8, 0.3, 0.6
    law = const_phi_law(mu_s=mu_s, A_mu=b, a_mu=1.0, phi_0=phi_0)
    prob = ChannelProblem(W=30.0, sigma_xx=12.0, u_wall=2.0, x0=1.5)
    prof = solve_local(law, prob)
    k = phi_0 / prob.sigma_xx  # mu = k (W/2 - x)
    c = math.sqrt(prob.sigma_xx)  # |du/dx| = c I
    xc, x0 = 15.0, 1.5
    x_p = xc - mu_s / k  # yield point, 9.0
    x = prof.x
    xs = np.minimum(x, x_p)
    # u - u_wall = (c/b) int_{x0}^{x} (k (W/2 - s) - mu_s) ds, constant in the plug
    u_exact = (c / b) * ((k * xc - mu_s) * (xs - x0) - k * (xs**2 - x0**2) / 2.0)
    du = prof.u - prob.u_wall
    np.testing.assert_allclose(du, u_exact, rtol=0, atol=1e-6 * np.max(u_exact))
    sheared = x < x_p
    np.testing.assert_allclose(
        prof.dudx[sheared], c * (k * (xc - x[sheared]) - mu_s) / b, rtol=1e-6
    )
    assert np.all(prof.u[x >= x_p] == prof.u_max)


# ------------------------------------------------------------------------------------------------
# the nonlocal model
# ------------------------------------------------------------------------------------------------
def test_nonlocal_tends_to_local_as_A_vanishes():
    prob = local_g_wall(LAW, W=60.0, sigma_xx=25.0, u_wall=1.0)  # wall yields: mu(x0) ~ 0.68
    loc = solve_local(LAW, prob)
    assert loc.mu[0] > LAW.mu_s and 0 < loc.plug_half_width() < 30.0
    diffs = []
    for A in (1e-2, 3e-3, 1e-3):
        nl = solve_nonlocal(LAW, A, prob)
        assert nl.model == "nonlocal" and nl.A == A
        assert nl.fluidity[0] == pytest.approx(prob.g_wall, rel=1e-8)
        away = nl.x >= prob.x0 + 1.0  # many boundary-layer widths A / sqrt(|mu - mu_s|)
        diffs.append(np.max(np.abs((nl.u - loc.u)[away])))
    u_range = loc.u_max - prob.u_wall
    assert diffs[0] > diffs[1] > diffs[2]
    assert diffs[0] / diffs[2] > 5.0  # roughly linear in A
    assert diffs[2] < 2e-5 * u_range


def test_nonlocal_creeps_where_local_plug_is_rigid():
    # wall sheared, central plug: local dudx is exactly 0 in the plug, nonlocal creeps
    prob = local_g_wall(LAW, W=60.0, sigma_xx=25.0, u_wall=1.0)
    loc = solve_local(LAW, prob)
    nl = solve_nonlocal(LAW, 0.5, prob)
    plug = loc.x > 30.0 - loc.plug_half_width(I_plug=1e-300) + 0.1
    assert plug.sum() > 100 and np.all(loc.dudx[plug] == 0.0)
    assert np.all(nl.dudx[:-1] > 0.0)  # mu = 0, hence dudx = 0, only on the centre line
    assert nl.u_max > loc.u_max
    # mu < mu_s everywhere: the local solution does not move, the nonlocal one still does
    still = ChannelProblem(W=60.0, sigma_xx=50.0, u_wall=1.0, g_wall=3.0)
    loc = solve_local(LAW, still)
    assert loc.mu[0] < LAW.mu_s
    assert np.all(loc.u == still.u_wall) and np.all(loc.dudx == 0.0)
    nl = solve_nonlocal(LAW, 0.5, still)
    assert nl.info["form"] == "single"
    assert np.all(nl.dudx[:-1] > 0.0) and np.all(np.diff(nl.u[: len(nl.u) // 2]) > 0.0)
    assert nl.u_max - still.u_wall > 1.0


@pytest.mark.parametrize("A", [0.5, 2.0])
def test_nonlocal_plug_fluidity_is_an_airy_function(A):
    # phi = phi_0 and mu < mu_s everywhere: g_loc = 0, mu_s - mu = beta (x - x_e) with
    # beta = rho_p g phi_0 / sigma_xx, and (A d)^2 g'' = (mu_s - mu) g is Airy's equation in
    # z = lam (x - x_e), lam = (beta / (A d)^2)^(1/3): g = a Ai(z) + b Bi(z), with
    # g(x0) = g_wall and g'(W/2) = 0 fixing a and b
    law = const_phi_law(mu_s=0.38, A_mu=0.7, a_mu=0.8)
    prob = ChannelProblem(W=60.0, sigma_xx=50.0, u_wall=1.0, g_wall=3.0)
    nl = solve_nonlocal(law, A, prob)
    beta = 0.6 / 50.0
    x_e = 30.0 - 0.38 / beta  # where mu would reach mu_s, behind the wall
    lam = (beta / A**2) ** (1.0 / 3.0)
    ai0, _, bi0, _ = airy(lam * (0.0 - x_e))
    _, aipc, _, bipc = airy(lam * (30.0 - x_e))
    a, b = np.linalg.solve([[ai0, bi0], [aipc, bipc]], [3.0, 0.0])

    def g(x):
        ai, _, bi, _ = airy(lam * (x - x_e))
        return a * ai + b * bi

    np.testing.assert_allclose(nl.fluidity, g(nl.x), rtol=1e-6, atol=1e-9 * 3.0)
    # u = u_wall + int mu g dx
    xs = nl.x[::100]
    u = [1.0 + quad(lambda s: beta * (30.0 - s) * g(s), 0.0, x, epsrel=1e-12)[0] for x in xs]
    np.testing.assert_allclose(nl.u[::100], u, rtol=0, atol=1e-8 * (u[-1] - 1.0))


def test_mass_and_momentum_balance():
    prob = local_g_wall(LAW, W=60.0, sigma_xx=30.0, u_wall=0.0, x0=2.0)
    prob = ChannelProblem(
        W=prob.W, sigma_xx=prob.sigma_xx, u_wall=0.0, x0=2.0, g_wall=2.0 * prob.g_wall
    )
    loc = solve_local(LAW, prob)
    nl = solve_nonlocal(LAW, 0.3, prob, n=4001)
    for prof in (loc, nl):
        # (B2) integrated: the wall carries the weight of the half channel
        assert prof.sigma_xy[0] == pytest.approx(prof.mass(), rel=1e-6)
        assert prof.sigma_xy[-1] == pytest.approx(0.0, abs=1e-10 * prof.sigma_xy[0])
    # the nonlocal solution satisfies its ODEs on the returned grid (finite differences)
    s_x = np.gradient(nl.sigma_xy, nl.x, edge_order=2)
    assert np.max(np.abs(s_x + nl.phi)) < 1e-5 * LAW.phi_0
    u_x = np.gradient(nl.u, nl.x, edge_order=2)
    assert np.max(np.abs(u_x - nl.dudx)) < 1e-4 * np.max(nl.dudx)  # O(h^2) in the wall layer
    assert nl.info["max_residual"] <= 1e-8 and nl.info["nodes"] > 0
    # the wall layer is real: g_wall is twice g_loc there
    assert nl.fluidity[0] == pytest.approx(prob.g_wall, rel=1e-8)
    assert np.max(np.abs(nl.phi - loc.at(nl.x)["phi"])) > 1e-3
    # a wall layer ~ A d / sqrt(mu - mu_s) = 0.002 thin: mass() integrates on the solver's
    # mesh as well (a uniform grid of 20001 points gets ~1e-6 here)
    thin = ChannelProblem(W=60.0, sigma_xx=30.0, u_wall=0.0, x0=2.0, g_wall=0.05 * prob.g_wall)
    nl = solve_nonlocal(LAW, 1e-3, thin)
    assert nl.sigma_xy[0] == pytest.approx(nl.mass(), rel=1e-8)


def test_dimensional_scaling_in_rho_p_and_g():
    # rho_p -> 2, g -> 3 and sigma_xx -> 6 sigma_xx keep mu(x), I(x), phi(x); the shear rate
    # scales with sqrt(sigma_xx / rho_p), i.e. by sqrt(3), and so do u - u_wall and g
    base = local_g_wall(LAW, W=50.0, sigma_xx=20.0, u_wall=1.0)
    assert base.g_wall is not None
    scaled = ChannelProblem(
        W=50.0, sigma_xx=120.0, u_wall=1.0, rho_p=2.0, g=3.0, g_wall=math.sqrt(3) * base.g_wall
    )
    for solve in (solve_local, lambda law, p: solve_nonlocal(law, 0.4, p)):
        a, b = solve(LAW, base), solve(LAW, scaled)
        np.testing.assert_allclose(b.sigma_xy, 6.0 * a.sigma_xy, rtol=1e-6, atol=1e-9)
        np.testing.assert_allclose(b.phi, a.phi, rtol=1e-7)
        np.testing.assert_allclose(b.I, a.I, rtol=1e-6, atol=1e-12)
        np.testing.assert_allclose(
            b.u - 1.0, math.sqrt(3.0) * (a.u - 1.0), rtol=1e-6, atol=1e-9 * (a.u_max - 1.0)
        )


# ------------------------------------------------------------------------------------------------
# bad input
# ------------------------------------------------------------------------------------------------
def test_fit_below_wall_stress_ratio_is_refused():
    short = LocalLaw(0.38, 0.7, 0.8, 0.60, 0.3, 0.8, I_min=1e-3, I_max=0.05)  # mu_max ~ 0.44
    prob = ChannelProblem(W=60.0, sigma_xx=25.0, u_wall=1.0, g_wall=1.0)  # mu(x0) ~ 0.68
    with pytest.raises(ParameterError, match=r"mu\(I_max\) = 0\.44.*I_max = 0\.05.*calibrate"):
        solve_local(short, prob)
    with pytest.raises(ParameterError, match=r"mu\(I_max\)"):
        solve_nonlocal(short, 0.5, prob)
    solve_local(LAW, prob)  # the same channel with a law calibrated far enough


@pytest.mark.parametrize(
    ("change", "name"),
    [
        ({"A_mu": 0.0}, "A_mu"),
        ({"A_mu": -0.5}, "A_mu"),
        ({"a_mu": 0.0}, "a_mu"),
        ({"phi_0": 1.0}, "phi_0"),
        ({"phi_0": 0.0}, "phi_0"),
        ({"A_phi": -0.1}, "A_phi"),
        ({"a_phi": -1.0}, "a_phi"),
        ({"I_min": 0.5, "I_max": 0.5}, "I_max"),
        ({"I_min": 0.0}, "I_min"),
        ({"mu_s": math.nan}, "mu_s"),
    ],
)
def test_invalid_law_names_parameter(change, name):
    p = dict(mu_s=0.38, A_mu=0.7, a_mu=0.8, phi_0=0.6, A_phi=0.3, a_phi=0.8, I_min=1e-3, I_max=1.0)
    p.update(change)
    with pytest.raises(ParameterError, match=rf"invalid {name} = .*allowed"):
        LocalLaw(**p)


def test_invalid_problem_and_nonlocal_arguments():
    with pytest.raises(ParameterError, match=r"invalid sigma_xx = 0\.0: allowed > 0"):
        ChannelProblem(W=60.0, sigma_xx=0.0, u_wall=1.0)
    with pytest.raises(ParameterError, match=r"invalid sigma_xx = -1\.0"):
        ChannelProblem(W=60.0, sigma_xx=-1.0, u_wall=1.0)
    with pytest.raises(ParameterError, match=r"invalid x0 = 30\.0: allowed 0 <= x0 < W/2"):
        ChannelProblem(W=60.0, sigma_xx=1.0, u_wall=1.0, x0=30.0)
    with pytest.raises(ParameterError, match=r"invalid g_wall"):
        ChannelProblem(W=60.0, sigma_xx=1.0, u_wall=1.0, g_wall=0.0)
    prob = ChannelProblem(W=60.0, sigma_xx=50.0, u_wall=1.0)
    with pytest.raises(ParameterError, match=r"invalid g_wall = None"):
        solve_nonlocal(LAW, 0.5, prob)
    prob = ChannelProblem(W=60.0, sigma_xx=50.0, u_wall=1.0, g_wall=3.0)
    for A in (0.0, -0.5):
        with pytest.raises(ParameterError, match=r"invalid A = .*allowed > 0"):
            solve_nonlocal(LAW, A, prob)


# ------------------------------------------------------------------------------------------------
# laws from fits, sampling, prediction bands, profile helpers
# ------------------------------------------------------------------------------------------------
def test_from_fits_reads_the_paper_parameter_names():
    mu_fit = SimpleNamespace(params={"mu1_0": 0.33, "A1": 0.6, "a1": 0.7})
    phi_fit = SimpleNamespace(params={"phi_0": 0.59, "A4": 0.25, "a4": 0.92})
    law = LocalLaw.from_fits(mu_fit, phi_fit, I_min=1e-3, I_max=0.3)
    assert law == LocalLaw(0.33, 0.6, 0.7, 0.59, 0.25, 0.92, 1e-3, 0.3)
    assert law.mu_max == pytest.approx(0.33 + 0.6 * 0.3**0.7)
    assert float(law.I_of_mu(law.mu(0.2))) == pytest.approx(0.2)
    assert float(law.I_of_mu(0.2)) == 0.0
    assert float(law.phi(5.0)) == float(law.phi(0.3))  # not extrapolated past I_max
    with pytest.raises(ParameterError, match="A4"):
        LocalLaw.from_fits(mu_fit, SimpleNamespace(params={"phi_0": 0.59}), 1e-3, 0.3)


def test_sample_has_the_requested_covariance():
    mu_cov = np.array([[4e-4, 2e-4, 0.0], [2e-4, 9e-4, -3e-4], [0.0, -3e-4, 1e-3]])
    phi_cov = np.array([[1e-5, 5e-6, 0.0], [5e-6, 4e-4, 0.0], [0.0, 0.0, 2.5e-3]])
    laws = LAW.sample(mu_cov, phi_cov, 4000, np.random.default_rng(7))
    assert len(laws) == 4000
    m = np.array([[w.mu_s, w.A_mu, w.a_mu] for w in laws])
    p = np.array([[w.phi_0, w.A_phi, w.a_phi] for w in laws])
    for draws, cov, mean in ((m, mu_cov, [0.38, 0.7, 0.8]), (p, phi_cov, [0.6, 0.3, 0.8])):
        c = np.cov(draws, rowvar=False)
        sd = np.sqrt(np.diag(cov))
        np.testing.assert_allclose(np.diag(c), np.diag(cov), rtol=0.1)
        np.testing.assert_allclose(c / np.outer(sd, sd), cov / np.outer(sd, sd), atol=0.1)
        assert np.all(np.abs(draws.mean(axis=0) - mean) < 4 * sd / math.sqrt(4000))
    cross = np.corrcoef(m[:, 0], p[:, 0])[0, 1]
    assert abs(cross) < 0.1  # the two fits are drawn independently
    assert all(w.I_max == LAW.I_max and w.I_min == LAW.I_min for w in laws)


def test_sample_redraws_invalid_laws_and_gives_up():
    near = LocalLaw(0.38, 0.05, 0.8, 0.60, 0.3, 0.8, 1e-3, 1.0)
    cov = np.diag([1e-6, 0.05**2, 1e-6])  # half the A_mu draws are <= 0
    laws = near.sample(cov, np.zeros((3, 3)), 300, 1)
    assert len(laws) == 300 and min(w.A_mu for w in laws) > 0
    hopeless = np.diag([1e8, 1e-6, 1e-6])  # phi_0 in (0, 1) once in ~25000 draws
    with pytest.raises(ParameterError, match="covariance"):
        LAW.sample(np.zeros((3, 3)), hopeless, 5, 2)


def test_prediction_band_quantiles_and_failures():
    prob = ChannelProblem(W=40.0, sigma_xx=20.0, u_wall=1.0)
    laws = LAW.sample(np.diag([1e-4, 1e-3, 1e-3]), np.diag([1e-5, 1e-4, 1e-4]), 30, 3)
    bad = LocalLaw(0.38, 0.7, 0.8, 0.60, 0.3, 0.8, 1e-3, 0.02)
    band = prediction_band([*laws, bad], solve_local, prob)
    assert band["failed"] == 1 and band["n_ok"] == 30 and "mu(I_max)" in band["errors"][0]
    nx = len(band["x"])
    for key in ("u", "dudx", "phi"):
        q = band[key]
        assert q.shape == (3, nx)
        assert np.all(q[0] <= q[1]) and np.all(q[1] <= q[2])
    assert band["u"][:, 0] == pytest.approx(0.0, abs=1e-12)  # u - u_wall
    assert band["u"][2, -1] > band["u"][0, -1] > 0
    centre = solve_local(LAW, prob)
    assert band["u"][0, -1] < centre.u_max - 1.0 < band["u"][2, -1]
    with pytest.raises(GranflowError, match="none of 1"):
        prediction_band([bad], solve_local, prob)


def test_profile_helpers():
    law = const_phi_law()
    # whole domain a plug (mu < mu_s everywhere), plug reaching the wall
    rigid = solve_local(law, ChannelProblem(W=10.0, sigma_xx=50.0, u_wall=1.0))
    assert rigid.plug_half_width() == pytest.approx(5.0)
    # a profile sheared up to the centre has no plug
    x = np.linspace(0.0, 1.0, 11)
    ones = np.ones_like(x)
    flowing = Profile(x, x, ones, ones, 1 - x, 1 - x, ones, ones, model="local")
    assert flowing.plug_half_width() == 0.0 and flowing.u_max == 1.0
    assert flowing.mass() == pytest.approx(1.0)
    prof = solve_local(law, ChannelProblem(W=40.0, sigma_xx=20.0, u_wall=0.5))
    vals = prof.at([prof.x[3], 0.5 * (prof.x[3] + prof.x[4])])
    assert vals["u"][0] == prof.u[3]
    assert vals["sigma_xy"][1] == pytest.approx(0.5 * (prof.sigma_xy[3] + prof.sigma_xy[4]))
    assert set(vals) == {"u", "dudx", "phi", "sigma_xy", "mu", "I", "fluidity"}
    with pytest.raises(ParameterError, match="xs"):
        prof.at([25.0])


def test_nonlocal_relaxes_tol_with_a_warning_when_phi_is_clipped():
    # g_wall = 300 puts I(x0) ~ 30 far above I_max = 0.5: phi is clipped there, and the kink
    # keeps solve_bvp from reaching tol = 1e-8 before round-off
    law = LocalLaw(0.38, 0.7, 0.8, 0.60, 0.3, 0.8, 1e-3, 0.5)
    prob = ChannelProblem(W=60.0, sigma_xx=30.0, u_wall=1.0, g_wall=300.0)
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        nl = solve_nonlocal(law, 0.5, prob)
    assert any("not reached" in str(w.message) for w in rec)
    assert nl.info["tol"] > 1e-8 and nl.info["I_max_exceeded"]
    assert nl.sigma_xy[0] == pytest.approx(nl.mass(), rel=1e-6)


# ------------------------------------------------------------------------------------------------
# Jop et al.'s mu(I)
# ------------------------------------------------------------------------------------------------
def test_jop_law_gives_its_closed_form_velocity():
    # mu = mu_s + A I/(I + I_0), phi = phi_0: mu(x) = k (W/2 - x), k = rho_p g phi_0/sigma_xx;
    # with e = mu - mu_s = k (x_p - x): I = I_0 e/(A - e), and
    # u - u_wall = c (I_0/k) [(e - e0) + A ln((A - e)/(A - e0))], c = sqrt(sigma_xx/rho_p)/d
    law = const_phi_law(mu_s=0.36, A_mu=0.47, a_mu=0.56, mu_form="jop")
    prob = ChannelProblem(W=40.0, sigma_xx=20.0, u_wall=0.5, x0=0.75)
    prof = solve_local(law, prob)
    k = 0.6 / 20.0
    xp = 20.0 - 0.36 / k
    e = np.maximum(k * (xp - prof.x), 0.0)
    e0 = k * (xp - 0.75)
    c = math.sqrt(20.0)
    expected = c * (0.56 / k) * ((e - e0) + 0.47 * np.log((0.47 - e) / (0.47 - e0)))
    np.testing.assert_allclose(prof.u - 0.5, expected, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(prof.I, 0.56 * e / (0.47 - e), rtol=1e-8, atol=1e-12)
    assert float(law.I_of_mu(law.mu(0.3))) == pytest.approx(0.3)
    # (mu - mu_s) dI/dmu against a finite difference
    mu, h = 0.5, 1e-6
    fd = (float(law.I_of_mu(mu + h)) - float(law.I_of_mu(mu - h))) / (2 * h)
    assert float(law.excess_dI_dmu(mu)) == pytest.approx((mu - 0.36) * fd, rel=1e-6)


def test_jop_nonlocal_tends_to_local():
    law = LocalLaw(0.36, 0.47, 0.56, 0.59, 0.16, 1.0, 0.03, 0.75, mu_form="jop")
    prob = local_g_wall(law, W=60.0, sigma_xx=35.0, u_wall=1.0)
    loc = solve_local(law, prob)
    diffs = []
    for A in (1e-2, 1e-3):
        nl = solve_nonlocal(law, A, prob)
        keep = loc.x > 1.0
        diffs.append(float(np.max(np.abs(nl.u[keep] - loc.u[keep]))))
    assert diffs[1] < diffs[0] / 3 and diffs[1] < 1e-4 * (loc.u_max - 1.0)


def test_jop_fit_is_read_with_its_covariance():
    class Fit:
        def __init__(self, params: dict[str, float]) -> None:
            self.params = params

    law = LocalLaw.from_fits(Fit({"mu_s": 0.36, "mu_2": 0.83, "I_0": 0.56}),
                             Fit({"phi_0": 0.59, "A4": 0.16, "a4": 1.0}), 0.03, 0.75)
    assert law.mu_form == "jop" and law.A_mu == pytest.approx(0.47) and law.a_mu == 0.56
    assert float(law.mu(1e9)) == pytest.approx(0.83)
    # var(mu_2 - mu_s) = var(mu_2) + var(mu_s) - 2 cov
    c = np.array([[1e-6, 5e-7, 0.0], [5e-7, 4e-6, 1e-6], [0.0, 1e-6, 9e-6]])
    t = LocalLaw.mu_covariance(c, jop=True)
    assert t[1, 1] == pytest.approx(4e-6 + 1e-6 - 1e-6) and t[0, 1] == pytest.approx(5e-7 - 1e-6)
    assert t[2, 2] == 9e-6 and np.allclose(t, t.T)
    assert np.array_equal(LocalLaw.mu_covariance(c, jop=False), c)
    draws = law.sample(t, np.diag([1e-6, 1e-6, 1e-4]), 5, rng=1)
    assert all(d.mu_form == "jop" for d in draws)


def test_law_forms_have_one_home_shared_with_the_fits():
    # the continuum's mu(I), phi(I) and the fits' (4.2), (4.7) and Jop forms: the same bits
    from granflow.analysis import rheology as rh

    inum = np.concatenate([[0.0], np.geomspace(1e-6, 0.5, 200)])
    law = LocalLaw(0.38, 0.55, 0.7, 0.6, 0.3, 0.9, 1e-4, 0.5)
    assert np.array_equal(law.mu(inum), rh.law_value("mu1", inum, 0.38, 0.55, 0.7))
    assert np.array_equal(law.phi(inum), rh.law_value("phi", inum, 0.6, 0.3, 0.9))
    jop = LocalLaw(0.36, 0.9 - 0.36, 0.02, 0.6, 0.3, 0.9, 1e-4, 0.5, mu_form="jop")
    assert np.array_equal(jop.mu(inum), rh.jop_value(inum, 0.36, 0.9, 0.02))


# ------------------------------------------------------------------------------------------------
# the models with phi(x) given (granflow.continuum.given_phi): the DEM's phi, only the flow rule
# ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("A", [0.5, 2.0])
def test_given_constant_phi_is_the_airy_closed_form(A):
    from granflow.continuum.given_phi import solve_nonlocal_given_phi

    law = const_phi_law(mu_s=0.38, A_mu=0.7, a_mu=0.8)
    prob = ChannelProblem(W=60.0, sigma_xx=50.0, u_wall=1.0, g_wall=3.0)
    nl = solve_nonlocal_given_phi(law, A, prob, [0.0, 30.0], [0.6, 0.6])
    beta = 0.6 / 50.0
    x_e = 30.0 - 0.38 / beta
    lam = (beta / A**2) ** (1.0 / 3.0)
    ai0, _, bi0, _ = airy(lam * (0.0 - x_e))
    _, aipc, _, bipc = airy(lam * (30.0 - x_e))
    a, b = np.linalg.solve([[ai0, bi0], [aipc, bipc]], [3.0, 0.0])
    ai, _, bi, _ = airy(lam * (nl.x - x_e))
    # second-order differences on 20,001 points
    np.testing.assert_allclose(nl.fluidity, a * ai + b * bi, rtol=1e-5, atol=1e-8)
    np.testing.assert_allclose(nl.sigma_xy, 0.6 * (30.0 - nl.x), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("model", ["local", "nonlocal"])
def test_given_the_models_own_phi_the_given_phi_solvers_return_the_same_profile(model):
    from granflow.continuum.given_phi import solve_local_given_phi, solve_nonlocal_given_phi

    prob = local_g_wall(LAW, W=60.0, sigma_xx=30.0, u_wall=0.0, x0=2.0)
    prob = ChannelProblem(W=60.0, sigma_xx=30.0, u_wall=0.0, x0=2.0, g_wall=2.0 * prob.g_wall)
    own = (solve_local(LAW, prob) if model == "local"
           else solve_nonlocal(LAW, 0.3, prob, n=4001))
    xs = np.linspace(prob.x0, prob.half_width, 20001)
    phi = own.evaluate(xs)["phi"] if own.evaluate is not None else np.interp(xs, own.x, own.phi)
    given = (solve_local_given_phi(LAW, prob, xs, phi) if model == "local"
             else solve_nonlocal_given_phi(LAW, 0.3, prob, xs, phi))
    ref = own.at(given.x)
    span = own.u_max - prob.u_wall
    assert span > 1.0
    # (measured: 1e-8 in the stress, 1e-6 of the span in u)
    np.testing.assert_allclose(given.sigma_xy, ref["sigma_xy"], rtol=0, atol=1e-7 * 30.0)
    np.testing.assert_allclose(given.u, ref["u"], rtol=0, atol=1e-5 * span)
    assert given.mass() == pytest.approx(own.mass(), rel=1e-8)


def test_given_phi_bad_input_is_refused():
    from granflow.continuum.given_phi import solve_nonlocal_given_phi

    prob = ChannelProblem(W=60.0, sigma_xx=50.0, u_wall=1.0, g_wall=3.0)
    law = const_phi_law()
    for xp, ph, match in (([0.0, 30.0], [0.6], "one value per position"),
                          ([30.0, 0.0], [0.6, 0.6], "increasing"),
                          ([0.0, 30.0], [0.6, 1.2], "0 < phi < 1"),
                          ([0.0, 30.0], [0.6, np.nan], "finite")):
        with pytest.raises(ParameterError, match=match):
            solve_nonlocal_given_phi(law, 0.5, prob, xp, ph)
    with pytest.raises(ParameterError, match="invalid A = 0"):
        solve_nonlocal_given_phi(law, 0.0, prob, [0.0, 30.0], [0.6, 0.6])
    # a stress ratio beyond the calibrated range, as the models' own solvers refuse it
    with pytest.raises(ParameterError, match=r"mu\(I_max\)"):
        solve_nonlocal_given_phi(const_phi_law(I_max=0.01), 0.5, prob, [0.0, 30.0], [0.6, 0.6])


def test_the_fourth_constants_are_refused_where_the_law_would_not_invert():
    jop = dict(mu_s=0.36, A_mu=0.9, a_mu=0.9, phi_0=0.59, A_phi=0.12, a_phi=0.8, I_min=1e-3,
               I_max=0.8, mu_form="jop")
    LocalLaw(**jop, c_mu=-0.2, B_phi=0.05)  # the calibration's: mu still rising at I_max
    # mu(I) would peak inside the calibrated range: no inverse there
    with pytest.raises(ParameterError, match=r"invalid c_mu = -0\.5: allowed > -0\.28.*rising"):
        LocalLaw(**jop, c_mu=-0.5)
    with pytest.raises(ParameterError, match="invalid c_mu = 0.1: allowed 0 unless mu_form"):
        LocalLaw(**{**jop, "mu_form": "power"}, c_mu=0.1)
    # phi(I) would rise at I_max
    with pytest.raises(ParameterError, match=r"invalid B_phi = -1\.0: allowed > .*falling"):
        LocalLaw(**jop, B_phi=-1.0)
    with pytest.raises(ParameterError, match="invalid c_mu = nan"):
        LocalLaw(**jop, c_mu=float("nan"))
    # draws with a 4x4 covariance move the fourth constant, with a 3x3 one hold it
    law = LocalLaw(**jop, c_mu=-0.2, B_phi=0.05)
    four = law.sample(np.eye(4) * 1e-8, np.eye(4) * 1e-10, 5, rng=1)
    three = law.sample(np.eye(3) * 1e-8, np.eye(3) * 1e-10, 5, rng=1)
    assert len({d.c_mu for d in four}) == 5 and {d.c_mu for d in three} == {-0.2}
    with pytest.raises(ParameterError, match=r"(?s)mu_cov.*allowed a finite symmetric 3x3"):
        LocalLaw(**{**jop, "mu_form": "power"}).sample(np.eye(4), np.eye(3), 1)
