"""The calibrated local rheology: mu(I) and phi(I) (002 (4.2), (4.7); Jop et al.; each with an
optional fourth constant) with their inverse and the draws that propagate a fit's
uncertainty."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import numpy.typing as npt

from granflow.analysis.laws import jop_law, jop_linear_law, power_law, power_quadratic_law
from granflow.errors import ParameterError

from ._checks import FloatArray, bad, finite


class _HasParams(Protocol):
    """Anything with a ``params`` dict, e.g. ``granflow.analysis.rheology.FitResult``."""

    @property
    def params(self) -> Mapping[str, float]: ...


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

    The fourth constants, 0 by default (the three-constant forms): ``c_mu`` adds ``c_mu I``
    to Jop's form (only there), ``B_phi`` subtracts ``B_phi I^2`` from (4.7); the
    calibration's forms over its whole range (granflow.continuum.calibration). ``mu(I)`` must
    rise over ``[0, I_max]`` (with ``c_mu < 0`` it peaks at ``I = sqrt(A_mu a_mu/|c_mu|) -
    a_mu``), else the inverse is not one; ``phi(I)`` must fall at ``I_max`` (checked there:
    with ``a_phi <= 2`` that makes it fall over the whole range).
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
    c_mu: float = 0.0
    B_phi: float = 0.0

    def __post_init__(self) -> None:
        if self.mu_form not in MU_FORMS:
            raise bad("mu_form", self.mu_form, f"one of {MU_FORMS}")
        for name in ("mu_s", "A_mu", "a_mu", "phi_0", "A_phi", "a_phi", "I_min", "I_max",
                     "c_mu", "B_phi"):
            finite(name, getattr(self, name))
        if self.mu_s < 0:
            raise bad("mu_s", self.mu_s, ">= 0")
        if self.A_mu <= 0:
            raise bad("A_mu", self.A_mu, "> 0")
        if self.a_mu <= 0:
            raise bad("a_mu", self.a_mu, "> 0")
        if not 0 < self.phi_0 < 1:
            raise bad("phi_0", self.phi_0, "0 < phi_0 < 1")
        if self.A_phi < 0:
            raise bad("A_phi", self.A_phi, ">= 0")
        if self.a_phi <= 0:
            raise bad("a_phi", self.a_phi, "> 0")
        if self.I_min <= 0:
            raise bad("I_min", self.I_min, "0 < I_min < I_max")
        if self.I_max <= self.I_min:
            raise bad("I_max", self.I_max, f"> I_min = {self.I_min!r}")
        if self.c_mu != 0 and self.mu_form != "jop":
            raise bad("c_mu", self.c_mu, "0 unless mu_form = 'jop'")
        if self.mu_form == "jop" and self._jop_slope(self.I_max) <= 0:
            least = -self.A_mu * self.a_mu / (self.I_max + self.a_mu) ** 2
            raise bad("c_mu", self.c_mu,
                      f"> {least:.6g} (mu(I) rising up to I_max = {self.I_max:g})")
        if self.B_phi < 0 and self.dphi_dI(self.I_max) >= 0:
            least = -0.5 * self.A_phi * self.a_phi * self.I_max ** (self.a_phi - 2.0)
            raise bad("B_phi", self.B_phi,
                      f"> {least:.6g} (phi(I) falling up to I_max = {self.I_max:g})")

    def _jop_slope(self, i: npt.ArrayLike) -> FloatArray:
        """dmu/dI of Jop's form with its linear term at ``i``."""
        return np.asarray(self.A_mu * self.a_mu / (np.asarray(i) + self.a_mu) ** 2 + self.c_mu)

    def mu(self, I: npt.ArrayLike) -> FloatArray:  # noqa: E741 (the paper's symbol)
        """Stress ratio ``mu_s + A_mu I^a_mu`` (002 (4.2)), or ``mu_s + A_mu I/(I + a_mu) +
        c_mu I`` (Jop et al.), for ``I >= 0``."""
        i = np.maximum(np.asarray(I, dtype=np.float64), 0.0)
        if self.mu_form == "jop" and self.c_mu != 0:
            return np.asarray(jop_linear_law(i, self.mu_s, self.A_mu, self.a_mu, self.c_mu))
        if self.mu_form == "jop":
            return np.asarray(jop_law(i, self.mu_s, self.A_mu, self.a_mu))
        with np.errstate(under="ignore"):
            return np.asarray(power_law(i, self.mu_s, self.A_mu, self.a_mu))

    def phi(self, I: npt.ArrayLike) -> FloatArray:  # noqa: E741
        """Packing fraction ``phi_0 - A_phi I^a_phi - B_phi I^2`` (002 (4.7)).

        ``I`` is clipped to ``[0, I_max]``: the power law is not extrapolated past the calibrated
        range (above ``I_max`` it would soon give unphysical, even negative, ``phi``).
        """
        i = np.clip(np.asarray(I, dtype=np.float64), 0.0, self.I_max)
        with np.errstate(under="ignore"):
            if self.B_phi != 0:
                return np.asarray(power_quadratic_law(i, self.phi_0, self.A_phi, self.a_phi,
                                                      self.B_phi))
            return np.asarray(power_law(i, self.phi_0, self.A_phi, self.a_phi, -1.0))

    def dphi_dI(self, I: npt.ArrayLike) -> FloatArray:  # noqa: E741
        """``dphi/dI`` of :meth:`phi` for ``0 < I < I_max`` (the caller clips: where ``phi``
        is held it is 0, and with ``a_phi < 1`` it diverges at ``I = 0``)."""
        i = np.asarray(I, dtype=np.float64)
        d = -self.A_phi * self.a_phi * i ** (self.a_phi - 1.0)
        return np.asarray(d - 2.0 * self.B_phi * i if self.B_phi != 0 else d)

    def I_of_mu(self, mu: npt.ArrayLike) -> FloatArray:
        """Inverse of :meth:`mu`: 0 where ``mu <= mu_s`` (the plug), else
        ``((mu - mu_s)/A_mu)^(1/a_mu)`` (power) or ``a_mu e/(A_mu - e)``, ``e = mu - mu_s``
        (jop; its asymptote mu_s + A_mu is never reached, the denominator is floored at
        1e-12 A_mu so that a solver's trial state stays finite); not clipped at ``I_max``.
        With ``c_mu``: the root on the rising branch of ``c I^2 + b I - e a_mu = 0``, ``b =
        A_mu + c_mu a_mu - e``, as ``2 e a_mu/(b + sqrt(b^2 + 4 c_mu e a_mu))`` (no
        cancellation); past the peak of ``mu`` (``c_mu < 0``) the discriminant is floored
        at 0, which gives the peak's I, and the denominator as above."""
        excess = np.maximum(np.asarray(mu, dtype=np.float64) - self.mu_s, 0.0)
        if self.mu_form == "jop" and self.c_mu != 0:
            b = self.A_mu + self.c_mu * self.a_mu - excess
            root = np.sqrt(np.maximum(b * b + 4.0 * self.c_mu * excess * self.a_mu, 0.0))
            return np.asarray(2.0 * excess * self.a_mu
                              / np.maximum(b + root, 1e-12 * self.A_mu))
        if self.mu_form == "jop":
            return np.asarray(self.a_mu * excess / np.maximum(self.A_mu - excess,
                                                              1e-12 * self.A_mu))
        with np.errstate(under="ignore"):
            return np.asarray((excess / self.A_mu) ** (1.0 / self.a_mu))

    def excess_dI_dmu(self, mu: npt.ArrayLike) -> FloatArray:
        """``(mu - mu_s) dI/dmu`` of :meth:`I_of_mu` (0 in the plug), written without the
        power form's ``(mu - mu_s)^(1/a_mu - 1)`` singularity: ``I/a_mu`` (power),
        ``I A_mu/(A_mu - e)`` (jop) or ``e/(dmu/dI)`` (jop with ``c_mu``, the slope floored
        at 1e-12 A_mu/a_mu)."""
        i = self.I_of_mu(mu)
        if self.mu_form == "jop" and self.c_mu != 0:
            excess = np.maximum(np.asarray(mu, dtype=np.float64) - self.mu_s, 0.0)
            return np.asarray(excess / np.maximum(self._jop_slope(i),
                                                  1e-12 * self.A_mu / self.a_mu))
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
        ``mu1_0, A1, a1`` or ``mu_s, mu_2, I_0`` (with ``c``, the linear term, if present),
        and ``phi_0, A4, a4`` (with ``B``, the quadratic term, if present))."""
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
                c_mu=float(mp.get("c", 0.0)),
                B_phi=float(pp.get("B", 0.0)),
            )
        except KeyError as e:
            raise ParameterError(
                f"invalid fit params: missing {e.args[0]!r}: allowed the mu(I) fit with "
                "mu1_0, A1, a1 (002 (4.2)) or mu_s, mu_2, I_0 (Jop et al.) and the phi(I) fit "
                "with phi_0, A4, a4 (002 (4.7))"
            ) from None

    @staticmethod
    def mu_covariance(mu_fit_cov: npt.ArrayLike, jop: bool) -> FloatArray:
        """A mu(I) fit's covariance in this class's order (mu_s, A_mu, a_mu[, c_mu]): (4.2)'s
        as it is; Jop's, fitted in (mu_s, mu_2, I_0[, c]), through A_mu = mu_2 - mu_s."""
        c = np.asarray(mu_fit_cov, dtype=np.float64)
        if not jop:
            return c
        t = np.eye(c.shape[0])
        t[1, 0] = -1.0
        return np.asarray(t @ c @ t.T)

    def sample(
        self,
        mu_cov: npt.ArrayLike,
        phi_cov: npt.ArrayLike,
        n: int,
        rng: np.random.Generator | int | None = None,
    ) -> list[LocalLaw]:
        """``n`` laws drawn around this one, to propagate the fit uncertainties.

        ``(mu_s, A_mu, a_mu)``, with ``c_mu`` where ``mu_cov`` is 4x4, is drawn from a normal
        distribution with mean this law's values and covariance ``mu_cov`` (the fit's, in
        this order: :meth:`mu_covariance`), ``(phi_0, A_phi, a_phi)``, with ``B_phi`` where
        ``phi_cov`` is 4x4, independently with ``phi_cov``; a 3x3 covariance holds the fourth
        constant at this law's value.  Draws that are not a valid law (e.g. ``A_mu <= 0``)
        are redrawn, which truncates the distribution: fine while the covariance is small
        against the distances to the bounds, which is when a linearised fit error means
        anything.  ParameterError after ``100 n`` tries.
        """
        if int(n) != n or n < 1:
            raise bad("n", n, "an integer >= 1")
        covs = []
        for name, cov in (("mu_cov", mu_cov), ("phi_cov", phi_cov)):
            c = np.asarray(cov, dtype=np.float64)
            sizes = ((3, 3), (4, 4)) if name == "phi_cov" or self.mu_form == "jop" else ((3, 3),)
            if c.shape not in sizes or not np.all(np.isfinite(c)) or not np.allclose(c, c.T):
                shapes = " or ".join(f"{k}x{k}" for k, _ in sizes)
                raise bad(name, cov, f"a finite symmetric {shapes} covariance matrix")
            if np.min(np.linalg.eigvalsh(c)) < -1e-12 * max(1.0, float(np.max(np.abs(c)))):
                raise bad(name, cov, "a positive semi-definite covariance matrix")
            covs.append(c)
        gen = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        m_mean = np.array([self.mu_s, self.A_mu, self.a_mu, self.c_mu])[: len(covs[0])]
        p_mean = np.array([self.phi_0, self.A_phi, self.a_phi, self.B_phi])[: len(covs[1])]
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
                        float(m[3]) if len(m) > 3 else self.c_mu,
                        float(p[3]) if len(p) > 3 else self.B_phi,
                    )
                )
            except ParameterError:
                continue
        return out
