"""The local mu(I) model of the channel: an initial-value problem from the centre line."""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.integrate import solve_ivp

from granflow.errors import GranflowError, ParameterError

from ._checks import FloatArray, bad
from .laws import LocalLaw
from .problem import ChannelProblem, Profile


def _g_loc(law: LocalLaw, mu: FloatArray, c: float) -> FloatArray:
    """Henann & Kamrin's local fluidity ``g_loc = I_of_mu(mu) sqrt(P/rho_p)/(d mu)`` (``c =
    sqrt(P/rho_p)/d``): ``|du/dx|/mu`` of the local law, 0 in the plug."""
    i = law.I_of_mu(mu)
    return np.divide(c * i, mu, out=np.zeros_like(i), where=i > 0)


def _quantities(law: LocalLaw, u: FloatArray, s: FloatArray, mu: FloatArray, i: FloatArray,
                dudx: FloatArray, fluidity: FloatArray) -> dict[str, FloatArray]:
    """A profile's quantities (PROFILE_FIELDS) by name, phi from the law at ``i``."""
    return {"u": u, "dudx": dudx, "phi": law.phi(i), "sigma_xy": s, "mu": mu, "I": i,
            "fluidity": fluidity}


def _stress_ratio_error(law: LocalLaw, mu_needed: float, prob: ChannelProblem) -> ParameterError:
    return ParameterError(
        f"invalid law: the mu(I) fit reaches only mu(I_max) = {law.mu_max:.6g} at "
        f"I_max = {law.I_max:.6g}, below the wall stress ratio mu(x0) = {mu_needed:.6g} that "
        f"the channel needs (W = {prob.W:g}, x0 = {prob.x0:g}, sigma_xx = {prob.sigma_xx:g}): "
        "allowed a law calibrated to larger I (mu(I_max) >= the wall stress ratio)"
    )


def _local_profile(law: LocalLaw, prob: ChannelProblem, n: int) -> Profile:
    """The local solution without the ``mu_max`` check (also the nonlocal initial guess)."""
    if int(n) != n or n < 3:
        raise bad("n", n, "an integer >= 3")
    rg = prob.rho_p * prob.g
    sxx, c = prob.sigma_xx, prob.shear_rate_scale
    xc, x0 = prob.half_width, prob.x0
    # In the plug (mu <= mu_s) I = 0 and phi = phi_0, so (B2) integrates exactly: sigma_xy is
    # linear and the plug edge, where sigma_xy = mu_s sigma_xx, is known in closed form.  The
    # ODE starts there, which keeps the kink of phi(I) at I = 0 off the integrator's steps.
    x_edge = xc - law.mu_s * sxx / (rg * law.phi_0)
    s_edge = law.mu_s * sxx

    def plug_s(x: FloatArray) -> FloatArray:
        return np.asarray(rg * law.phi_0 * (xc - x))

    sol: Any = None
    u_edge_rel = 0.0  # u(plug) - u(x0)
    if x_edge > x0:

        def rhs(_x: float, y: FloatArray) -> FloatArray:
            i = law.I_of_mu(y[0] / sxx)
            return np.array([-rg * float(law.phi(i)), c * float(i)])

        u_scale = c * max(law.I_of_mu(rg * law.phi_0 * (xc - x0) / sxx).item(), 1e-300)
        with np.errstate(under="ignore"):
            sol = solve_ivp(
                rhs,
                (x_edge, x0),
                [s_edge, 0.0],
                method="DOP853",
                rtol=1e-10,
                atol=[1e-13 * sxx, 1e-13 * max(u_scale * (xc - x0), 1e-300)],
                dense_output=True,
            )
        if not sol.success:
            raise GranflowError(f"local channel solution failed: {sol.message} ({law}, {prob})")
        u_edge_rel = -float(sol.y[1, -1])

    def evaluate(xs: FloatArray) -> dict[str, FloatArray]:
        with np.errstate(under="ignore"):
            return _evaluate(np.atleast_1d(np.asarray(xs, dtype=np.float64)))

    def _evaluate(xs: FloatArray) -> dict[str, FloatArray]:
        s = plug_s(xs)
        u = np.full(xs.shape, prob.u_wall + u_edge_rel)
        sheared = xs < x_edge
        if sol is not None and np.any(sheared):
            y = sol.sol(xs[sheared])
            s[sheared] = y[0]
            u[sheared] = prob.u_wall + u_edge_rel + y[1]
        mu = s / sxx
        i = law.I_of_mu(mu)
        return _quantities(law, u, s, mu, i, c * i, _g_loc(law, mu, c))

    x = np.linspace(x0, xc, int(n))
    q = evaluate(x)
    q["u"][0] = prob.u_wall  # exact by construction; remove the interpolant's last bit
    info = {"x_plug_edge": x_edge, "mu_wall": float(q["mu"][0])}
    mesh = np.asarray(sol.t, dtype=np.float64) if sol is not None else None
    return Profile(x=x, model="local", A=0.0, info=info, evaluate=evaluate, mesh=mesh, **q)


def solve_local(law: LocalLaw, prob: ChannelProblem, n: int = 2001) -> Profile:
    """Local mu(I) solution on ``n`` uniform points of ``[x0, W/2]``.

    (B2) ``d sigma_xy/dx = -rho_p g phi(I)`` with ``sigma_xy(W/2) = 0`` is integrated as an
    initial-value problem from the centre (DOP853, ``rtol = 1e-10``) together with
    ``du/dx = I sqrt(sigma_xx/rho_p)/d``, ``I = I_of_mu(sigma_xy/sigma_xx)``; ``u`` is then
    shifted so that ``u(x0) = u_wall``.

    Raises ParameterError when the wall stress ratio exceeds ``law.mu_max``: the channel would
    need ``I > I_max``, where the law was never calibrated.
    """
    prof = _local_profile(law, prob, n)
    mu_wall = float(prof.mu[0])
    if mu_wall > law.mu_max:
        raise _stress_ratio_error(law, mu_wall, prob)
    return prof
