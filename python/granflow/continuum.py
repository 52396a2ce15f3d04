"""1-D continuum solutions for fully developed, gravity-driven granular flow in a vertical channel.

The channel has flat walls at ``x = 0`` and ``x = W``, gravity points along the channel and the
flow is symmetric about ``x = W/2``; only the half channel ``x in [x0, W/2]`` is solved, ``x``
measured from the wall.  The purpose is to predict DEM channel profiles (velocity ``u``, shear
rate, packing fraction ``phi``) from a rheology calibrated elsewhere (the stress-controlled cell,
paper 002), so the laws are written in 002's form:

* ``mu(I) = mu_s + A_mu I^a_mu`` (002 (4.2)) and ``phi(I) = phi_0 - A_phi I^a_phi`` (002 (4.7)),
  with the channel's variables ``mu = |sigma_xy| / sigma_xx`` and
  ``I = |du/dx| d / sqrt(sigma_xx / rho_p)``;
* momentum balance (paper 000, appendix B, (B1)-(B2)): ``sigma_xx`` is uniform across the channel
  and ``d sigma_xy / dx = -rho_p phi g`` with ``sigma_xy = 0`` on the centre line;
* two constitutive closures: the local mu(I) law (:func:`solve_local`) and the nonlocal granular
  fluidity model of Henann & Kamrin (PNAS 110, 6730, 2013) (:func:`solve_nonlocal`).

Assumptions, stated once here because every function relies on them:

* ``sigma_xx`` is uniform and is used as the pressure, both in ``I`` and in the local fluidity
  ``g_loc``; the other normal stresses (002's normal-stress differences) do not enter.
* ``phi`` is the local ``phi(I)`` in both models (the nonlocality is in the flow rule only);
  ``phi(I)`` is not extrapolated past the calibrated ``I_max``, and a channel whose stress
  ratio exceeds ``mu(I_max)`` is refused (ParameterError) rather than solved with an
  extrapolated ``mu(I)``.
* Whatever happens in the wall zone (slip, layering) enters only through boundary data at
  ``x0``: the velocity ``u_wall`` and, for the nonlocal model, the fluidity ``g_wall``.

Units: ``rho_p`` (particle density), ``g`` (gravity) and ``d`` (mean diameter) are parameters of
:class:`ChannelProblem`, 1 by default (the DEM units).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt
from scipy.integrate import solve_bvp, solve_ivp, trapezoid

from granflow.errors import GranflowError, ParameterError

__all__ = [
    "LocalLaw",
    "ChannelProblem",
    "Profile",
    "solve_local",
    "solve_nonlocal",
    "prediction_band",
    "plug_half_width",
]

FloatArray = npt.NDArray[np.float64]

#: Quantities a :class:`Profile` carries on its grid (besides ``x``).
PROFILE_FIELDS: tuple[str, ...] = ("u", "dudx", "phi", "sigma_xy", "mu", "I", "fluidity")


class _HasParams(Protocol):
    """Anything with a ``params`` dict, e.g. ``granflow.analysis.rheology.FitResult``."""

    @property
    def params(self) -> Mapping[str, float]: ...


def _bad(name: str, value: object, allowed: str) -> ParameterError:
    return ParameterError(f"invalid {name} = {value!r}: allowed {allowed}")


def _finite(name: str, value: float) -> None:
    if not (isinstance(value, (int, float, np.floating, np.integer)) and math.isfinite(value)):
        raise _bad(name, value, "a finite number")


# ------------------------------------------------------------------------------------------------
# the local law
# ------------------------------------------------------------------------------------------------
#: the forms of mu(I) (:attr:`LocalLaw.mu_form`)
MU_FORMS = ("power", "jop")


@dataclass(frozen=True)
class LocalLaw:
    """Calibrated local rheology: ``mu(I)`` and ``phi(I)`` (002 (4.7)).

    ``mu_form`` "power": ``mu = mu_s + A_mu I^a_mu`` (002 (4.2)); "jop": ``mu = mu_s + A_mu
    I/(I + a_mu)`` (Jop, Forterre & Pouliquen 2006: ``A_mu = mu_2 - mu_s``, ``a_mu = I_0``),
    linear at small I.  ``I_min``/``I_max`` is the range of ``I`` the fit was calibrated on.
    ``phi(I)`` is held at ``phi(I_max)`` above it; ``mu(I)`` is not clipped (its inverse decides
    where the channel needs it, and the solvers refuse a channel whose stress ratio exceeds
    ``mu(I_max)``).
    """

    mu_s: float
    A_mu: float
    a_mu: float
    phi_0: float
    A_phi: float
    a_phi: float
    I_min: float
    I_max: float
    mu_form: str = "power"

    def __post_init__(self) -> None:
        if self.mu_form not in MU_FORMS:
            raise _bad("mu_form", self.mu_form, f"one of {MU_FORMS}")
        for name in ("mu_s", "A_mu", "a_mu", "phi_0", "A_phi", "a_phi", "I_min", "I_max"):
            _finite(name, getattr(self, name))
        if self.mu_s < 0:
            raise _bad("mu_s", self.mu_s, ">= 0")
        if self.A_mu <= 0:
            raise _bad("A_mu", self.A_mu, "> 0")
        if self.a_mu <= 0:
            raise _bad("a_mu", self.a_mu, "> 0")
        if not 0 < self.phi_0 < 1:
            raise _bad("phi_0", self.phi_0, "0 < phi_0 < 1")
        if self.A_phi < 0:
            raise _bad("A_phi", self.A_phi, ">= 0")
        if self.a_phi <= 0:
            raise _bad("a_phi", self.a_phi, "> 0")
        if self.I_min <= 0:
            raise _bad("I_min", self.I_min, "0 < I_min < I_max")
        if self.I_max <= self.I_min:
            raise _bad("I_max", self.I_max, f"> I_min = {self.I_min!r}")

    def mu(self, I: npt.ArrayLike) -> FloatArray:  # noqa: E741 (the paper's symbol)
        """Stress ratio ``mu_s + A_mu I^a_mu`` (002 (4.2)), or ``mu_s + A_mu I/(I + a_mu)``
        (Jop et al.), for ``I >= 0``."""
        i = np.maximum(np.asarray(I, dtype=np.float64), 0.0)
        if self.mu_form == "jop":
            return np.asarray(self.mu_s + self.A_mu * i / (i + self.a_mu))
        with np.errstate(under="ignore"):
            return np.asarray(self.mu_s + self.A_mu * i**self.a_mu)

    def phi(self, I: npt.ArrayLike) -> FloatArray:  # noqa: E741
        """Packing fraction ``phi_0 - A_phi I^a_phi`` (002 (4.7)).

        ``I`` is clipped to ``[0, I_max]``: the power law is not extrapolated past the calibrated
        range (above ``I_max`` it would soon give unphysical, even negative, ``phi``).
        """
        i = np.clip(np.asarray(I, dtype=np.float64), 0.0, self.I_max)
        with np.errstate(under="ignore"):
            return np.asarray(self.phi_0 - self.A_phi * i**self.a_phi)

    def I_of_mu(self, mu: npt.ArrayLike) -> FloatArray:
        """Inverse of :meth:`mu`: 0 where ``mu <= mu_s`` (the plug), else
        ``((mu - mu_s)/A_mu)^(1/a_mu)`` (power) or ``a_mu e/(A_mu - e)``, ``e = mu - mu_s``
        (jop; its asymptote mu_s + A_mu is never reached, the denominator is floored at
        1e-12 A_mu so that a solver's trial state stays finite); not clipped at ``I_max``."""
        excess = np.maximum(np.asarray(mu, dtype=np.float64) - self.mu_s, 0.0)
        if self.mu_form == "jop":
            return np.asarray(self.a_mu * excess / np.maximum(self.A_mu - excess,
                                                              1e-12 * self.A_mu))
        with np.errstate(under="ignore"):
            return np.asarray((excess / self.A_mu) ** (1.0 / self.a_mu))

    def excess_dI_dmu(self, mu: npt.ArrayLike) -> FloatArray:
        """``(mu - mu_s) dI/dmu`` of :meth:`I_of_mu` (0 in the plug), written without the
        power form's ``(mu - mu_s)^(1/a_mu - 1)`` singularity: ``I/a_mu`` (power) or
        ``I A_mu/(A_mu - e)`` (jop)."""
        i = self.I_of_mu(mu)
        if self.mu_form == "jop":
            excess = np.maximum(np.asarray(mu, dtype=np.float64) - self.mu_s, 0.0)
            return np.asarray(i * self.A_mu / np.maximum(self.A_mu - excess, 1e-12 * self.A_mu))
        return np.asarray(i / self.a_mu)

    @property
    def mu_max(self) -> float:
        """``mu(I_max)``: the largest stress ratio the calibration covers."""
        return float(self.mu(self.I_max))

    @classmethod
    def from_fits(
        cls, mu_fit: _HasParams, phi_fit: _HasParams, I_min: float, I_max: float
    ) -> LocalLaw:
        """Build the law from the fits of 002 (4.2) or Jop et al.'s mu(I), and of (4.7)
        (``granflow.analysis.rheology.FitResult``; only ``params`` is read:
        ``mu1_0, A1, a1`` or ``mu_s, mu_2, I_0``, and ``phi_0, A4, a4``)."""
        try:
            mp, pp = mu_fit.params, phi_fit.params
            jop = "mu_2" in mp
            return cls(
                mu_s=float(mp["mu_s"] if jop else mp["mu1_0"]),
                A_mu=float(mp["mu_2"] - mp["mu_s"] if jop else mp["A1"]),
                a_mu=float(mp["I_0"] if jop else mp["a1"]),
                phi_0=float(pp["phi_0"]),
                A_phi=float(pp["A4"]),
                a_phi=float(pp["a4"]),
                I_min=float(I_min),
                I_max=float(I_max),
                mu_form="jop" if jop else "power",
            )
        except KeyError as e:
            raise ParameterError(
                f"invalid fit params: missing {e.args[0]!r}: allowed the mu(I) fit with "
                "mu1_0, A1, a1 (002 (4.2)) or mu_s, mu_2, I_0 (Jop et al.) and the phi(I) fit "
                "with phi_0, A4, a4 (002 (4.7))"
            ) from None

    @staticmethod
    def mu_covariance(mu_fit_cov: npt.ArrayLike, jop: bool) -> FloatArray:
        """A mu(I) fit's covariance in this class's order (mu_s, A_mu, a_mu): (4.2)'s as it
        is; Jop's, fitted in (mu_s, mu_2, I_0), through A_mu = mu_2 - mu_s."""
        c = np.asarray(mu_fit_cov, dtype=np.float64)
        if not jop:
            return c
        t = np.array([[1.0, 0.0, 0.0], [-1.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
        return np.asarray(t @ c @ t.T)

    def sample(
        self,
        mu_cov: npt.ArrayLike,
        phi_cov: npt.ArrayLike,
        n: int,
        rng: np.random.Generator | int | None = None,
    ) -> list[LocalLaw]:
        """``n`` laws drawn around this one, to propagate the fit uncertainties.

        ``(mu_s, A_mu, a_mu)`` is drawn from a normal distribution with mean this law's values
        and covariance ``mu_cov`` (3x3, the (4.2) fit's), ``(phi_0, A_phi, a_phi)``
        independently with ``phi_cov``.  Draws that are not a valid law (e.g. ``A_mu <= 0``)
        are redrawn, which truncates the distribution: fine while the covariance is small
        against the distances to the bounds, which is when a linearised fit error means
        anything.  ParameterError after ``100 n`` tries.
        """
        if int(n) != n or n < 1:
            raise _bad("n", n, "an integer >= 1")
        covs = []
        for name, cov in (("mu_cov", mu_cov), ("phi_cov", phi_cov)):
            c = np.asarray(cov, dtype=np.float64)
            if c.shape != (3, 3) or not np.all(np.isfinite(c)) or not np.allclose(c, c.T):
                raise _bad(name, cov, "a finite symmetric 3x3 covariance matrix")
            if np.min(np.linalg.eigvalsh(c)) < -1e-12 * max(1.0, float(np.max(np.abs(c)))):
                raise _bad(name, cov, "a positive semi-definite 3x3 covariance matrix")
            covs.append(c)
        gen = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        m_mean = np.array([self.mu_s, self.A_mu, self.a_mu])
        p_mean = np.array([self.phi_0, self.A_phi, self.a_phi])
        out: list[LocalLaw] = []
        tries = 0
        while len(out) < n:
            if tries >= 100 * n:
                raise ParameterError(
                    f"invalid covariance: only {len(out)} of {n} laws drawn in {tries} tries "
                    "are valid: allowed covariances small enough that most draws are valid laws"
                )
            tries += 1
            m = gen.multivariate_normal(m_mean, covs[0])
            p = gen.multivariate_normal(p_mean, covs[1])
            try:
                out.append(
                    LocalLaw(
                        float(m[0]),
                        float(m[1]),
                        float(m[2]),
                        float(p[0]),
                        float(p[1]),
                        float(p[2]),
                        self.I_min,
                        self.I_max,
                        self.mu_form,
                    )
                )
            except ParameterError:
                continue
        return out


# ------------------------------------------------------------------------------------------------
# the problem and its solution
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ChannelProblem:
    """The channel: width ``W``, the uniform normal stress ``sigma_xx`` (B1) and the boundary
    data at ``x0`` (the edge of the wall zone): ``u_wall`` and, for the nonlocal model, the
    fluidity ``g_wall = |du/dx| / mu`` there."""

    W: float
    sigma_xx: float
    u_wall: float
    x0: float = 0.0
    g_wall: float | None = None
    rho_p: float = 1.0
    g: float = 1.0
    d: float = 1.0

    def __post_init__(self) -> None:
        for name in ("W", "sigma_xx", "u_wall", "x0", "rho_p", "g", "d"):
            _finite(name, getattr(self, name))
        for name in ("W", "sigma_xx", "rho_p", "g", "d"):
            if getattr(self, name) <= 0:
                raise _bad(name, getattr(self, name), "> 0")
        if not 0 <= self.x0 < self.W / 2:
            raise _bad("x0", self.x0, f"0 <= x0 < W/2 = {self.W / 2!r}")
        if self.g_wall is not None:
            _finite("g_wall", self.g_wall)
            if self.g_wall <= 0:
                raise _bad("g_wall", self.g_wall, "> 0 (or None for the local model)")

    @property
    def half_width(self) -> float:
        """``W/2``, the centre line."""
        return self.W / 2

    @property
    def shear_rate_scale(self) -> float:
        """``sqrt(sigma_xx / rho_p) / d``: ``|du/dx| = I`` times this."""
        return math.sqrt(self.sigma_xx / self.rho_p) / self.d


@dataclass(eq=False)
class Profile:
    """A half-channel solution on the grid ``x`` (``x0`` to ``W/2``).

    ``dudx`` is the shear rate ``|du/dx|`` (``u`` grows towards the centre), ``sigma_xy`` the
    shear stress magnitude (0 at the centre), ``mu = sigma_xy / sigma_xx``, ``fluidity =
    dudx / mu`` (for the local model ``g_loc``).  ``evaluate``, when set, evaluates the solver's
    continuous solution at any positions, and ``mesh`` holds the solver's own nodes (where it
    resolved the solution: boundary layers are finer than a uniform grid); both are used by
    :meth:`mass`.  ``info`` holds solver data.
    """

    x: FloatArray
    u: FloatArray
    dudx: FloatArray
    phi: FloatArray
    sigma_xy: FloatArray
    mu: FloatArray
    I: FloatArray  # noqa: E741
    fluidity: FloatArray
    model: str
    A: float = 0.0
    info: dict[str, Any] = field(default_factory=dict)
    evaluate: Callable[[FloatArray], dict[str, FloatArray]] | None = field(default=None, repr=False)
    mesh: FloatArray | None = field(default=None, repr=False)

    @property
    def u_max(self) -> float:
        """Centre-line velocity ``u(W/2)``."""
        return float(self.u[-1])

    def plug_half_width(self, I_plug: float = 1e-4) -> float:
        """Half-width of the central plug (:func:`plug_half_width` on this profile)."""
        return plug_half_width(self.x, self.I, I_plug)

    def at(self, xs: npt.ArrayLike) -> dict[str, FloatArray]:
        """The quantities of :data:`PROFILE_FIELDS`, interpolated linearly at ``xs`` (which
        must lie in ``[x0, W/2]``)."""
        q = np.asarray(xs, dtype=np.float64)
        lo, hi = float(self.x[0]), float(self.x[-1])
        tol = 1e-12 * max(1.0, abs(hi))
        if q.size and (np.min(q) < lo - tol or np.max(q) > hi + tol):
            raise _bad("xs", (float(np.min(q)), float(np.max(q))), f"within [{lo}, {hi}]")
        return {k: np.interp(q, self.x, getattr(self, k)) for k in PROFILE_FIELDS}

    def mass(self, n_fine: int = 20001) -> float:
        """``int_{x0}^{W/2} phi dx``: trapezoid on a fine grid, ``n_fine`` uniform points plus
        each interval of the solver's mesh cut in four, of the continuous solution (on the
        profile's grid when there is none).  By (B2) it equals ``sigma_xy(x0) / (rho_p g)``."""
        if self.evaluate is None:
            return float(trapezoid(self.phi, self.x))
        lo, hi = float(self.x[0]), float(self.x[-1])
        parts = [np.linspace(lo, hi, max(int(n_fine), len(self.x)))]
        if self.mesh is not None and self.mesh.size > 1:
            m = np.unique(self.mesh)
            parts.append((m[:-1, None] + np.diff(m)[:, None] * np.arange(4) / 4.0).ravel())
        xf = np.unique(np.clip(np.concatenate(parts), lo, hi))
        return float(trapezoid(self.evaluate(xf)["phi"], xf))


def plug_half_width(x: npt.ArrayLike, I: npt.ArrayLike, I_plug: float = 1e-4) -> float:  # noqa: E741
    """Half-width of the central plug of a half profile ``I(x)`` (``x`` from the wall to the
    centre line at ``x[-1]``): ``x[-1]`` minus the largest ``x`` with ``I >= I_plug`` (the
    crossing interpolated linearly between points); ``x[-1] - x[0]`` when ``I < I_plug``
    everywhere, 0 when ``I >= I_plug`` at the centre. Binned DEM profiles take it too, so
    that a model and the DEM are judged alike."""
    xx, i = np.asarray(x, dtype=np.float64), np.asarray(I, dtype=np.float64)
    above = np.nonzero(i >= I_plug)[0]
    if above.size == 0:
        return float(xx[-1] - xx[0])
    k = int(above[-1])
    if k == len(xx) - 1:
        return 0.0
    # I crosses I_plug between x[k] (>=) and x[k+1] (<)
    t = (i[k] - I_plug) / (i[k] - i[k + 1])
    return float(xx[-1] - (xx[k] + t * (xx[k + 1] - xx[k])))


def _g_loc(law: LocalLaw, mu: FloatArray, c: float) -> FloatArray:
    """Henann & Kamrin's local fluidity ``g_loc = I_of_mu(mu) sqrt(P/rho_p)/(d mu)`` (``c =
    sqrt(P/rho_p)/d``): ``|du/dx|/mu`` of the local law, 0 in the plug."""
    i = law.I_of_mu(mu)
    return np.divide(c * i, mu, out=np.zeros_like(i), where=i > 0)


# ------------------------------------------------------------------------------------------------
# the local model
# ------------------------------------------------------------------------------------------------
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
        raise _bad("n", n, "an integer >= 3")
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


# ------------------------------------------------------------------------------------------------
# the nonlocal granular fluidity model (Henann & Kamrin 2013)
# ------------------------------------------------------------------------------------------------
class _Nonlocal:
    """Right-hand side and Jacobian of the nonlocal system in ``y = [S, g, q]`` (in ``x``):

    ``S' = -rho_p g phi(I)``, ``I = mu g d / sqrt(sigma_xx/rho_p)``, ``mu = S/sigma_xx``;
    ``g' = q / (A d)``; ``q' = |mu - mu_s| (g - g_loc(mu)) / (A d)``.  That is Henann &
    Kamrin's ``g = g_loc + xi^2 g''``, ``xi = A d / sqrt(|mu - mu_s|)``, multiplied through by
    ``|mu - mu_s|`` so that ``mu = mu_s`` is not singular, with ``q = A d g'`` in place of
    ``h = g'``: written with ``h``, ``h' = (A d)^-2 ...`` amplifies the collocation error of
    ``g`` by ``(A d)^-2`` in the residual solve_bvp controls, and for small ``A`` it refines
    the mesh far beyond what the solution needs; with ``q`` both equations carry ``(A d)^-1``.
    ``u' = mu g`` does not feed back and is integrated afterwards (:meth:`_Form.solution`).

    Limitation: where ``g`` is close to 0 (deep in a plug at small ``A``, or a tiny
    ``g_wall``) and ``a_phi`` is small (below ~0.6), ``phi(I) ~ I^a_phi`` is so steep at
    ``I = 0`` that the collocation error of ``g`` (~1e-13) shows in the residual of ``S'``;
    solve_bvp then needs many nodes, or the tolerance is relaxed (see :func:`solve_nonlocal`).
    """

    def __init__(self, law: LocalLaw, A: float, prob: ChannelProblem) -> None:
        self.law, self.prob = law, prob
        self.rg = prob.rho_p * prob.g
        self.sxx = prob.sigma_xx
        self.c = prob.shear_rate_scale
        self.k = 1.0 / (A * prob.d)

    def g_loc(self, mu: FloatArray) -> FloatArray:
        return _g_loc(self.law, mu, self.c)

    def f(self, y: FloatArray) -> FloatArray:
        law = self.law
        s, g, q = y[0], y[1], y[2]
        mu = s / self.sxx
        return np.vstack(
            (
                -self.rg * law.phi(mu * g / self.c),
                self.k * q,
                self.k * np.abs(mu - law.mu_s) * (g - self.g_loc(mu)),
            )
        )

    def jac(self, y: FloatArray) -> FloatArray:
        law = self.law
        s, g = y[0], y[1]
        mu = s / self.sxx
        i = mu * g / self.c
        m = mu - law.mu_s
        # dphi/dI, 0 where phi(I) is clipped; I bounded away from 0 where a_phi < 1
        inside = (i > 0) & (i < law.I_max)
        i_safe = np.clip(i, 1e-12 * law.I_max, law.I_max)
        dphi = np.where(inside, -law.A_phi * law.a_phi * i_safe ** (law.a_phi - 1.0), 0.0)
        gl = self.g_loc(mu)
        # |mu - mu_s| d g_loc/dmu, written without the (mu - mu_s)^(1/a_mu - 1) singularity
        i_loc = law.I_of_mu(mu)
        mu_safe = np.where(i_loc > 0, mu, 1.0)
        m_dgl = np.where(
            i_loc > 0,
            self.c * (law.excess_dI_dmu(mu) / mu_safe - m * i_loc / mu_safe**2),
            0.0,
        )
        J = np.zeros((3, 3, y.shape[1]))
        J[0, 0] = -self.rg * dphi * g / (self.c * self.sxx)
        J[0, 1] = -self.rg * dphi * mu / self.c
        J[1, 2] = self.k
        J[2, 0] = self.k * (np.sign(m) * (g - gl) - m_dgl) / self.sxx
        J[2, 1] = self.k * np.abs(m)
        return J


class _RoundOff(Exception):
    """solve_bvp refined the mesh to where round-off dominates the residual."""


_GAUSS_T, _GAUSS_W = np.polynomial.legendre.leggauss(4)


class _Form:
    """The nonlocal BVP in a mapped variable ``t in [0, 1]``, in one of two forms.

    ``single``: ``y = [S, g, q]`` on ``[x0, W/2]``; ``g(x0) = g_wall``, ``S(W/2) = 0``,
    ``q(W/2) = 0``.  ``split`` (used when the wall yields, ``mu(x0) > mu_s``): two copies,
    on ``[x0, x_p]`` and ``[x_p, W/2]``, with the yield point ``x_p`` an unknown parameter
    fixed by ``S(x_p) = mu_s sigma_xx`` and ``S, g, q`` continuous there (7 conditions for
    6 equations and 1 parameter).  ``|mu - mu_s|`` has a kink at ``x_p``; with ``x_p`` inside
    an interval the collocation residual only falls like the spacing times ``(A d)^-1``, and
    for small ``A`` solve_bvp refines into round-off before reaching ``tol``.  The split puts
    the kink on the mesh end points.

    Each region ``[lo, hi]`` is mapped by ``x = lo + (hi - lo) (3 t^2 - 2 t^3)``, which
    compresses the mesh towards both ends, where the right-hand side has power-law
    singularities: ``phi(I)`` goes like ``(W/2 - x)^a_phi`` at the centre (``I ~ mu`` there)
    and like ``(x - x0 + delta)^a_phi`` at a wall with small ``g_wall`` (``I ~ g``),
    ``|mu - mu_s| g_loc`` like ``(x_p - x)^(1 + 1/a_mu)`` at the yield point.  The map turns
    ``|x - end|^q`` into ``t^(2q + 1)``, smooth enough for the collocation.
    """

    def __init__(self, sys: _Nonlocal, split: bool, tol: float, y_scale: float) -> None:
        self.sys, self.split = sys, split
        self.x0, self.xc = sys.prob.x0, sys.prob.half_width
        self.nr = 2 if split else 1
        # below this spacing the residual computed from differences of y is round-off
        self.h_floor = max(1e-13, 0.3 * np.finfo(float).eps * y_scale / tol)

    def bounds(self, p: FloatArray | None) -> list[tuple[float, float]]:
        if self.split:
            assert p is not None
            return [(self.x0, float(p[0])), (float(p[0]), self.xc)]
        return [(self.x0, self.xc)]

    @staticmethod
    def dxdt(lo: float, hi: float, t: FloatArray) -> FloatArray:
        return np.asarray(6.0 * (hi - lo) * t * (1.0 - t))

    @staticmethod
    def x_of_t(lo: float, hi: float, t: FloatArray) -> FloatArray:
        return np.asarray(lo + (hi - lo) * t * t * (3.0 - 2.0 * t))

    @staticmethod
    def t_of_x(lo: float, hi: float, x: FloatArray) -> FloatArray:
        """Inverse of :meth:`x_of_t` (closed form, then one Newton step for the ends)."""
        s = np.clip((x - lo) / (hi - lo), 0.0, 1.0)
        t = 0.5 - np.sin(np.arcsin(1.0 - 2.0 * s) / 3.0)
        ds = 6.0 * t * (1.0 - t)
        step = np.divide(t * t * (3.0 - 2.0 * t) - s, ds, out=np.zeros_like(t), where=ds > 0)
        return np.asarray(np.clip(t - step, 0.0, 1.0))

    def fun(self, t: FloatArray, y: FloatArray, p: FloatArray | None = None) -> FloatArray:
        if t.size > 1:
            dt = np.diff(t)
            k = int(np.argmin(dt))
            if 0 < dt[k] < self.h_floor:
                raise _RoundOff(
                    f"mesh refined to spacing {dt[k]:.2g} (of the unit interval) at "
                    f"t = {t[k]:.8g}, where round-off exceeds the tolerance"
                )
        out = np.empty_like(y)
        for r, (lo, hi) in enumerate(self.bounds(p)):
            out[3 * r : 3 * r + 3] = self.dxdt(lo, hi, t) * self.sys.f(y[3 * r : 3 * r + 3])
        return out

    def jac(
        self, t: FloatArray, y: FloatArray, p: FloatArray | None = None
    ) -> FloatArray | tuple[FloatArray, FloatArray]:
        n = 3 * self.nr
        dfdy = np.zeros((n, n, t.size))
        dfdp = np.zeros((n, 1, t.size))
        for r, (lo, hi) in enumerate(self.bounds(p)):
            sl = slice(3 * r, 3 * r + 3)
            dfdy[sl, sl] = self.dxdt(lo, hi, t) * self.sys.jac(y[sl])
            if self.split:
                # d(dx/dt)/dx_p: +6 t (1 - t) on [x0, x_p], -6 t (1 - t) on [x_p, W/2]
                dfdp[sl, 0] = (6.0 if r == 0 else -6.0) * t * (1.0 - t) * self.sys.f(y[sl])
        return (dfdy, dfdp) if self.split else dfdy

    def bc(self, ya: FloatArray, yb: FloatArray, p: FloatArray | None = None) -> FloatArray:
        gw = self.sys.prob.g_wall
        assert gw is not None
        if not self.split:
            return np.array([ya[1] - gw, yb[0], yb[2]])
        return np.array(
            [
                ya[1] - gw,
                yb[3],
                yb[5],
                yb[0] - ya[3],
                yb[1] - ya[4],
                yb[2] - ya[5],
                yb[0] - self.sys.law.mu_s * self.sys.sxx,
            ]
        )

    def bc_jac(
        self, _ya: FloatArray, _yb: FloatArray, _p: FloatArray | None = None
    ) -> tuple[FloatArray, ...]:
        if not self.split:
            ja, jb = np.zeros((3, 3)), np.zeros((3, 3))
            ja[0, 1] = jb[1, 0] = jb[2, 2] = 1.0
            return ja, jb
        ja, jb = np.zeros((7, 6)), np.zeros((7, 6))
        ja[0, 1] = jb[1, 3] = jb[2, 5] = jb[6, 0] = 1.0
        for r in range(3):
            jb[3 + r, r] = 1.0
            ja[3 + r, 3 + r] = -1.0
        return ja, jb, np.zeros((7, 1))

    def start(
        self, guess: Callable[[FloatArray], FloatArray], mesh: FloatArray, xp: float
    ) -> tuple[FloatArray, FloatArray, FloatArray | None]:
        p = np.array([xp]) if self.split else None
        ys = [guess(self.x_of_t(lo, hi, mesh)) for lo, hi in self.bounds(p)]
        return mesh, np.vstack(ys), p

    def valid(self, res: Any) -> bool:
        return not self.split or bool(self.x0 < float(res.p[0]) < self.xc)

    def solution(self, res: Any) -> Callable[[FloatArray], FloatArray]:
        """``x -> [S, g, q, u]`` from the collocation solution; ``u = u_wall + int mu g dx``
        by 4-point Gauss on each mesh interval, exact for the cubic interpolant."""
        p = res.p if self.split else None
        bounds = self.bounds(p)
        tm = res.x
        sxx, u_wall = self.sys.sxx, self.sys.prob.u_wall

        def du_dt(r: int, t: FloatArray) -> FloatArray:
            lo, hi = bounds[r]
            y = res.sol(t)[3 * r : 3 * r + 3]
            return np.asarray(self.dxdt(lo, hi, t) * (y[0] / sxx) * y[1])

        def gauss(r: int, a: FloatArray, b: FloatArray) -> FloatArray:
            half = 0.5 * (b - a)
            nodes = a[:, None] + half[:, None] * (_GAUSS_T[None, :] + 1.0)
            vals = du_dt(r, nodes.ravel()).reshape(nodes.shape)
            return np.asarray(half * (vals @ _GAUSS_W))

        cum: list[FloatArray] = []
        start = u_wall
        for r in range(self.nr):
            c = start + np.concatenate(([0.0], np.cumsum(gauss(r, tm[:-1], tm[1:]))))
            cum.append(c)
            start = float(c[-1])

        def y_at(x: FloatArray) -> FloatArray:
            x = np.asarray(x, dtype=np.float64)
            out = np.empty((4, x.size))
            region = (x >= bounds[1][0]).astype(int) if self.split else np.zeros(x.size, int)
            for r, (lo, hi) in enumerate(bounds):
                sel = region == r
                if not np.any(sel):
                    continue
                t = self.t_of_x(lo, hi, x[sel])
                out[:3, sel] = res.sol(t)[3 * r : 3 * r + 3]
                i = np.clip(np.searchsorted(tm, t, side="right") - 1, 0, tm.size - 2)
                out[3, sel] = cum[r][i] + gauss(r, tm[i], t)
            return out

        return y_at


def _decay(t: FloatArray) -> FloatArray:
    """``exp(-t)`` for ``t >= 0`` without underflow (0 past ``t = 600``)."""
    return np.asarray(np.where(t < 600.0, np.exp(-np.minimum(t, 600.0)), 0.0))


def _guess(
    A: float, prob: ChannelProblem, local: Profile
) -> tuple[Callable[[FloatArray], FloatArray], float]:
    """Initial guess ``[S, g, q = A d g'](x)`` for the BVP, and its wall-layer length ``l``:
    the local solution with ``g = max(g_loc, small)`` blended into ``g_wall`` over
    ``l = A d / sqrt(0.05)`` (the cooperativity length at ``|mu - mu_s| = 0.05``)."""
    assert prob.g_wall is not None and local.evaluate is not None
    evaluate = local.evaluate
    ell = A * prob.d / math.sqrt(0.05)
    small = 1e-6 * prob.g_wall
    dg = prob.g_wall - max(float(local.fluidity[0]), small)

    def y_of_x(x: FloatArray) -> FloatArray:
        q = evaluate(x)
        b = _decay((x - prob.x0) / ell)
        g = np.maximum(q["fluidity"], small) + dg * b
        return np.vstack((q["sigma_xy"], g, -A * prob.d * dg * b / ell))

    return y_of_x, ell


def _unit_mesh(ell_rel: float) -> FloatArray:
    """401 uniform points on [0, 1] plus points graded geometrically towards 0 over the
    relative wall-layer length ``ell_rel`` (no finer than 1e-5, far above round-off)."""
    lo = max(0.02 * ell_rel, 1e-5)
    graded = np.geomspace(lo, max(20.0 * ell_rel, 10.0 * lo), 60)
    return np.unique(np.concatenate((np.linspace(0.0, 1.0, 401), graded[graded < 1.0])))


def solve_nonlocal(
    law: LocalLaw,
    A: float,
    prob: ChannelProblem,
    n: int = 2001,
    tol: float = 1e-8,
    max_nodes: int = 200_000,
) -> Profile:
    """Nonlocal granular fluidity solution (Henann & Kamrin 2013) on ``n`` uniform points.

    Solves ``S' = -rho_p g phi(I)``, ``(A d)^2 g'' = |mu - mu_s| (g - g_loc(mu))`` (see
    :class:`_Nonlocal`) on ``[x0, W/2]`` with ``g(x0) = g_wall``, ``S(W/2) = 0`` and
    ``g'(W/2) = 0`` (symmetry) by collocation (scipy ``solve_bvp``, relative residual tolerance
    ``tol``, analytic Jacobian), then ``u = u_wall + int_{x0}^x mu g dx`` by quadrature of
    the collocation solution.  When the wall yields (``mu(x0) > mu_s``) the problem is split at
    the yield point (:class:`_Form`); otherwise, or if the split solve fails, it is solved on
    ``[x0, W/2]`` in one piece.  The initial guess is the local solution with ``g`` blended into
    ``g_wall`` near the wall; if a solve fails it is continued from a larger ``A`` (wider,
    smoother boundary layers) down to ``A``.

    ``info`` records ``max_residual`` (solve_bvp's largest relative residual), ``nodes``
    (mesh size; the split form carries both parts on one mesh), ``form`` ("split"/"single"),
    ``x_yield`` (the split point, or None), ``A_path`` (the amplitudes solved at),
    ``failed_forms``, ``tol`` (the tolerance reached), ``mu_wall``, ``I_wall`` and
    ``I_max_exceeded`` (``phi`` is held at ``phi(I_max)`` wherever ``I = mu g d /
    sqrt(sigma_xx/rho_p)`` exceeds ``I_max``, which a large ``g_wall`` can cause).

    The kink that this clipping puts in ``phi``, or ``phi ~ I^a_phi`` with a small ``a_phi``
    where ``g ~ 0`` (see :class:`_Nonlocal`), can keep the residual above a tight ``tol`` until
    the mesh spacing reaches round-off (detected, rather than refined to ``max_nodes``); the
    solve is then repeated at ``100 tol`` and ``10^4 tol`` (not above 1e-4), with a
    RuntimeWarning and ``info["tol"]`` saying so.

    Raises ParameterError for ``A <= 0``, ``g_wall`` missing, or a stress ratio above
    ``law.mu_max`` (``g_loc`` would be needed where the law was not calibrated);
    GranflowError when solve_bvp does not converge.
    """
    _finite("A", A)
    if A <= 0:
        raise _bad("A", A, "> 0")
    if prob.g_wall is None:
        raise _bad("g_wall", None, "> 0 (the nonlocal model needs the wall fluidity)")
    if not (tol > 0 and math.isfinite(tol)):
        raise _bad("tol", tol, "> 0")
    if int(n) != n or n < 3:
        raise _bad("n", n, "an integer >= 3")
    rg = prob.rho_p * prob.g
    x0, xc = prob.x0, prob.half_width
    # phi >= phi(I_max) everywhere, so this is a lower bound on the wall stress ratio
    mu_wall_min = rg * float(law.phi(law.I_max)) * (xc - x0) / prob.sigma_xx
    if mu_wall_min > law.mu_max:
        raise _stress_ratio_error(law, mu_wall_min, prob)

    with np.errstate(under="ignore"):
        local = _local_profile(law, prob, 2001)
        x_edge = float(local.info["x_plug_edge"])
        # phi <= phi_0 = the local plug's phi, so the nonlocal sigma_xy(x0) is at most the local
        # one wherever g >= g_loc: a wall that does not yield in the local solution does not
        # yield here either, and only a yielding wall (mu_s > 0) needs the split form
        splits = [True, False] if (law.mu_s > 0 and x_edge > x0) else [False]
        # a kink or a steep power law in the right-hand side can hold the residual above a
        # tight tol down to round-off: then relax it, twice
        tols = [tol] + [t for t in (1e2 * tol, 1e4 * tol) if t <= 1e-4]
        failures: list[str] = []
        for tol_used in tols:
            for split in splits:
                try:
                    res, path, form = _solve_form(
                        law, A, prob, local, split, x_edge, tol_used, max_nodes
                    )
                    break
                except GranflowError as e:
                    failures.append(f"{'split' if split else 'single'} form, tol {tol_used:g}: {e}")
            else:
                continue
            break
        else:
            raise GranflowError(
                "nonlocal channel solution did not converge: "
                + "; ".join(failures)
                + f" (A = {A:g}, g_wall = {prob.g_wall:g}, W = {prob.W:g}, x0 = {x0:g}, "
                f"sigma_xx = {prob.sigma_xx:g}, {law})"
            )
        if tol_used > tol:
            warnings.warn(
                f"solve_nonlocal: tol = {tol:g} not reached (mesh refinement ran into round-off);"
                f" solved to tol = {tol_used:g}",
                RuntimeWarning,
                stacklevel=2,
            )
        y_at = form.solution(res)
        c = prob.shear_rate_scale

        def evaluate(xs: FloatArray) -> dict[str, FloatArray]:
            with np.errstate(under="ignore"):  # g underflows deep in a plug: harmless
                y = y_at(np.atleast_1d(np.asarray(xs, dtype=np.float64)))
                s, g = y[0], y[1]
                mu = s / prob.sigma_xx
                i = mu * g / c
                return _quantities(law, y[3], s, mu, i, mu * g, g)

        x = np.linspace(x0, xc, int(n))
        q = evaluate(x)

    mu_wall = float(q["mu"][0])
    if mu_wall > law.mu_max:
        raise _stress_ratio_error(law, mu_wall, prob)
    info = {
        "max_residual": float(np.max(res.rms_residuals)),
        "tol": tol_used,
        "nodes": int(res.x.size),
        "niter": int(res.niter),
        "form": "split" if form.split else "single",
        "x_yield": float(res.p[0]) if form.split else None,
        "A_path": path,
        "failed_forms": failures,
        "mu_wall": mu_wall,
        "I_wall": float(q["I"][0]),
        "I_max_exceeded": bool(np.max(q["I"]) > law.I_max),
    }
    bounds = form.bounds(res.p if form.split else None)
    mesh = np.concatenate([form.x_of_t(lo, hi, res.x) for lo, hi in bounds])
    return Profile(x=x, model="nonlocal", A=float(A), info=info, evaluate=evaluate, mesh=mesh, **q)


def _solve_form(
    law: LocalLaw,
    A: float,
    prob: ChannelProblem,
    local: Profile,
    split: bool,
    x_edge: float,
    tol: float,
    max_nodes: int,
) -> tuple[Any, list[float], _Form]:
    """solve_bvp in one form: directly at ``A``, else by continuation from a larger ``A``
    (the first of ``4 A, 16 A, ...`` that converges from the guess), stepping down to ``A``
    from each converged solution and halving the step (in log A) on failure.  A split
    solution whose yield point leaves ``(x0, W/2)`` fails at once: the wall does not yield."""
    span = prob.half_width - prob.x0
    y_scale = max(float(local.sigma_xy[0]), float(prob.g_wall or 0.0), 1e-300)

    def attempt(a: float, t: FloatArray | None, y: FloatArray | None, p: Any) -> Any:
        form = _Form(_Nonlocal(law, a, prob), split, tol, y_scale)
        if t is None or y is None:
            guess, ell = _guess(a, prob, local)
            # x - x0 ~ 3 L t^2 near the wall: the layer ends at t ~ sqrt(l / (3 L))
            ell_rel = math.sqrt(ell / (3.0 * ((x_edge - prob.x0) if split else span)))
            t, y, p = form.start(guess, _unit_mesh(ell_rel), x_edge)
        try:
            # trial Newton iterates may overflow; solve_bvp then reports failure
            with np.errstate(all="ignore"):
                r = solve_bvp(
                    form.fun,
                    form.bc,
                    t,
                    y,
                    p=p,
                    fun_jac=form.jac,
                    bc_jac=form.bc_jac,
                    tol=tol,
                    max_nodes=max_nodes,
                )
        except _RoundOff as e:  # a property of the right-hand side: continuation won't help
            raise _Failed(str(e), final=True) from None
        if not r.success:
            raise _Failed(str(r.message), final=False)
        if not np.all(np.isfinite(r.y)):
            raise _Failed("the solution is not finite", final=False)
        if not form.valid(r):
            raise _Failed(f"the yield point went to x = {float(r.p[0]):g}", final=True)
        return r, form

    path = [A]
    try:
        res, form = attempt(A, None, None, None)
        return res, path, form
    except _Failed as e:
        if e.final:
            raise GranflowError(str(e)) from None
        first = str(e)
    a_hi = A
    for _ in range(5):
        a_hi *= 4.0
        path.append(a_hi)
        try:
            res, form = attempt(a_hi, None, None, None)
            break
        except _Failed as e:
            if e.final:
                raise GranflowError(f"{first}; at A = {a_hi:g}: {e}") from None
    else:
        raise GranflowError(f"{first} (directly and from A up to {a_hi:g})")
    a_cur, step = a_hi, 4.0
    while a_cur > A:
        a_next = max(A, a_cur / step)
        path.append(a_next)
        try:
            # q = A d g' scales with A
            y_next = res.y.copy()
            y_next[2::3] *= a_next / a_cur
            res, form = attempt(a_next, res.x, y_next, res.p)
            a_cur = a_next
            step = min(4.0, step * 2.0)
        except _Failed as e:
            step = math.sqrt(step)
            if e.final or step < 1.05:
                raise GranflowError(
                    f"{first}; continuation in A stalled at A = {a_cur:g}: {e}"
                ) from None
    return res, path, form


class _Failed(Exception):
    """One solve_bvp attempt failed; ``final`` when continuation cannot help."""

    def __init__(self, message: str, final: bool) -> None:
        super().__init__(message)
        self.final = final


# ------------------------------------------------------------------------------------------------
# uncertainty propagation
# ------------------------------------------------------------------------------------------------
def prediction_band(
    laws: Sequence[LocalLaw],
    solve: Callable[[LocalLaw, ChannelProblem], Profile],
    prob: ChannelProblem,
    quantiles: Sequence[float] = (0.16, 0.5, 0.84),
    x: npt.ArrayLike | None = None,
) -> dict[str, Any]:
    """Quantiles across laws (e.g. :meth:`LocalLaw.sample`) of the predicted profiles.

    Runs ``solve(law, prob)`` for each law (for the nonlocal model e.g.
    ``lambda law, p: solve_nonlocal(law, A, p)``) and evaluates, at ``x`` (default: the first
    solved profile's grid), ``"u"`` = ``u - u_wall``, ``"dudx"`` and ``"phi"``; each is returned
    as an array of shape ``(len(quantiles), len(x))``.  Laws whose solve raises ParameterError
    or GranflowError (e.g. ``mu_max`` below the wall stress ratio) are counted in ``"failed"``
    (their messages, first 10, in ``"errors"``): a band over the laws that could be solved is
    biased when that count is not small.  Also returns ``"x"``, ``"quantiles"`` and ``"n_ok"``.
    GranflowError when no law could be solved.
    """
    qs = np.asarray(quantiles, dtype=np.float64)
    if qs.ndim != 1 or qs.size == 0 or np.any(~((qs >= 0) & (qs <= 1))):
        raise _bad("quantiles", quantiles, "a non-empty sequence of numbers in [0, 1]")
    profiles: list[Profile] = []
    errors: list[str] = []
    for law in laws:
        try:
            profiles.append(solve(law, prob))
        except GranflowError as e:  # ParameterError is a GranflowError
            errors.append(str(e))
    if not profiles:
        raise GranflowError(
            f"prediction_band: none of {len(errors)} laws could be solved; first error: "
            f"{errors[0] if errors else 'no laws given'}"
        )
    xs = profiles[0].x if x is None else np.asarray(x, dtype=np.float64)
    out: dict[str, Any] = {"x": xs, "quantiles": qs}
    samples = [p.at(xs) for p in profiles]
    for key in ("u", "dudx", "phi"):
        stack = np.stack([s[key] for s in samples])
        if key == "u":
            stack = stack - prob.u_wall
        out[key] = np.quantile(stack, qs, axis=0)
    out["failed"] = len(errors)
    out["errors"] = errors[:10]
    out["n_ok"] = len(profiles)
    return out
