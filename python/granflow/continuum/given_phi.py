"""The channel's models with the packing fraction given, not modelled: phi(x) from a DEM
profile, so that the stress is the DEM's and only the flow rule is tested.

With phi(x) given, (B2) integrates at once: ``sigma_xy(x) = rho_p g int_x^{W/2} phi``, so
``mu(x)`` is known and

* the local model is a quadrature: ``du/dx = I_of_mu(mu) sqrt(sigma_xx/rho_p)/d``;
* the nonlocal model (Henann & Kamrin 2013) is a linear boundary-value problem in the
  fluidity: ``(A d)^2 g'' = |mu - mu_s| (g - g_loc(mu))``, ``g(x0) = g_wall``,
  ``g'(W/2) = 0``, solved by second-order finite differences on a uniform grid; then
  ``du/dx = mu g``.

The models' own phi(I) (:func:`granflow.continuum.solve_local`,
:func:`granflow.continuum.solve_nonlocal`) couples the stress to the flow; given the same
phi(x) as those solutions produce, these solvers return the same profiles (tested).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from scipy.integrate import cumulative_trapezoid
from scipy.linalg import solve_banded

from ._checks import FloatArray, bad, finite
from .laws import LocalLaw
from .local import _g_loc, _stress_ratio_error
from .problem import ChannelProblem, Profile

#: grid points of the given-phi solutions (uniform on [x0, W/2]): the fluidity's decay
#: length A d / sqrt(|mu - mu_s|) is resolved by hundreds of points for any A >= 0.05
N_GRID = 20001


def _phi_on(x: FloatArray, x_phi: npt.ArrayLike, phi: npt.ArrayLike) -> FloatArray:
    """The given ``phi`` (at positions ``x_phi`` from the wall, increasing) interpolated
    linearly at ``x``, held at its end values beyond them."""
    xp = np.asarray(x_phi, dtype=np.float64)
    fp = np.asarray(phi, dtype=np.float64)
    if xp.ndim != 1 or xp.shape != fp.shape or xp.size < 2:
        raise bad("phi", fp.shape, f"one value per position of x_phi {xp.shape}, at least 2")
    if not (np.all(np.isfinite(xp)) and np.all(np.isfinite(fp))):
        raise bad("phi", "non-finite values", "finite positions and packing fractions")
    if np.any(np.diff(xp) <= 0):
        raise bad("x_phi", "not increasing", "positions increasing from the wall")
    if np.any((fp <= 0) | (fp >= 1)):
        raise bad("phi", (float(fp.min()), float(fp.max())), "0 < phi < 1")
    return np.asarray(np.interp(x, xp, fp))


def _stress(prob: ChannelProblem, x: FloatArray, phi: FloatArray) -> FloatArray:
    """``sigma_xy(x) = rho_p g int_x^{W/2} phi`` (trapezoid on the grid; 0 at the centre)."""
    tail = cumulative_trapezoid(phi[::-1], -x[::-1], initial=0.0)[::-1]
    return np.asarray(prob.rho_p * prob.g * tail)


def _profile(model: str, A: float, prob: ChannelProblem, x: FloatArray,
             phi: FloatArray, s: FloatArray, dudx: FloatArray, g: FloatArray,
             info: dict[str, object]) -> Profile:
    u = prob.u_wall + cumulative_trapezoid(dudx, x, initial=0.0)
    mu = s / prob.sigma_xx
    return Profile(x=x, u=np.asarray(u), dudx=dudx, phi=phi, sigma_xy=s, mu=mu,
                   I=dudx / prob.shear_rate_scale, fluidity=g, model=model, A=A, info=info)


def _given(law: LocalLaw, prob: ChannelProblem, x_phi: npt.ArrayLike, phi: npt.ArrayLike,
           n: int) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """The grid (``n`` uniform points on [x0, W/2]), phi on it, the stress and mu; refused
    where the wall stress ratio exceeds ``law.mu_max``."""
    if int(n) != n or n < 3:
        raise bad("n", n, "an integer >= 3")
    x = np.linspace(prob.x0, prob.half_width, int(n))
    ph = _phi_on(x, x_phi, phi)
    s = _stress(prob, x, ph)
    mu = s / prob.sigma_xx
    if mu[0] > law.mu_max:
        raise _stress_ratio_error(law, float(mu[0]), prob)
    return x, ph, s, mu


def solve_local_given_phi(law: LocalLaw, prob: ChannelProblem, x_phi: npt.ArrayLike,
                          phi: npt.ArrayLike, n: int = N_GRID) -> Profile:
    """The local mu(I) model with the packing fraction ``phi`` given at ``x_phi`` (distance
    from the wall) instead of the law's phi(I): the stress from (B2) by quadrature, then
    ``du/dx = I_of_mu(mu) sqrt(sigma_xx/rho_p)/d``. Raises ParameterError where the wall
    stress ratio exceeds ``law.mu_max`` (as :func:`granflow.continuum.solve_local`)."""
    x, ph, s, mu = _given(law, prob, x_phi, phi, n)
    with np.errstate(under="ignore"):
        c = prob.shear_rate_scale
        dudx = c * law.I_of_mu(mu)
        g = _g_loc(law, mu, c)
    return _profile("local", 0.0, prob, x, ph, s, dudx, g, {"mu_wall": float(mu[0]),
                                                               "phi": "given"})


def solve_nonlocal_given_phi(law: LocalLaw, A: float, prob: ChannelProblem,
                             x_phi: npt.ArrayLike, phi: npt.ArrayLike,
                             n: int = N_GRID,
                             layer: tuple[float, float] | None = None) -> Profile:
    """The nonlocal granular fluidity model with the packing fraction ``phi`` given at
    ``x_phi`` instead of the law's phi(I): the stress from (B2) by quadrature, then the
    fluidity from ``(A d)^2 g'' = |mu - mu_s| (g - g_loc(mu))`` with ``g(x0) = g_wall`` and
    ``g'(W/2) = 0`` (second-order finite differences, the centre's condition by a mirror
    node), and ``du/dx = mu g``.

    ``layer = (x_layer, A_layer)``: a wall layer with an amplitude of its own, ``A_layer``
    for ``x < x_layer`` and ``A`` beyond (g and g' continuous across ``x_layer``): the
    fluidity law's amplitude where the DEM's bulk and wall layer differ
    (granflow.continuum.cooperativity). Raises ParameterError for ``A <= 0`` (or
    ``A_layer``), a missing ``g_wall`` or a wall stress ratio above ``law.mu_max``."""
    finite("A", A)
    if A <= 0:
        raise bad("A", A, "> 0")
    if layer is not None:
        finite("x_layer", layer[0])
        finite("A_layer", layer[1])
        if layer[1] <= 0:
            raise bad("A_layer", layer[1], "> 0")
    if prob.g_wall is None:
        raise bad("g_wall", None, "> 0 (the nonlocal model needs the wall fluidity)")
    x, ph, s, mu = _given(law, prob, x_phi, phi, n)
    c = prob.shear_rate_scale
    with np.errstate(under="ignore"):
        gl = _g_loc(law, mu, c)
    m = np.abs(mu - law.mu_s)
    h = float(x[1] - x[0])
    amp = np.full(x.size, float(A))
    if layer is not None:
        amp[x < layer[0]] = layer[1]
    k2 = (amp[1:] * prob.d / h) ** 2  # row i's (A_i d / h)^2, i = 1 .. n-1
    # unknowns g_1 .. g_{n-1} (g_0 = g_wall); row i: k2_i (g_{i-1} - 2 g_i + g_{i+1}) -
    # m_i g_i = -m_i gl_i; the last row has the mirror node g_n = g_{n-2} (g' = 0 at the
    # centre)
    nu = x.size - 1
    ab = np.zeros((3, nu))
    ab[0, 1:] = k2[:-1]             # super-diagonal (row i's g_{i+1})
    ab[1, :] = -2.0 * k2 - m[1:]    # diagonal
    ab[2, :-1] = k2[1:]             # sub-diagonal (row i+1's g_i)
    ab[2, -2] = 2.0 * k2[-1]        # the mirror: g_{n-2} counts twice in the last row
    rhs = -m[1:] * gl[1:]
    rhs[0] -= k2[0] * prob.g_wall
    g = np.empty_like(x)
    g[0] = prob.g_wall
    g[1:] = solve_banded((1, 1), ab, rhs)
    info = {"mu_wall": float(mu[0]), "phi": "given", "nodes": int(x.size), "layer": layer}
    return _profile("nonlocal", float(A), prob, x, ph, s, mu * g, g, info)
