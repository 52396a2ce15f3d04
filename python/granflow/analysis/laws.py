"""The forms of the flow laws mu(I) and phi(I): the one home of their arithmetic, used by the
fits (:mod:`granflow.analysis.rheology`) and the continuum models (:mod:`granflow.continuum`).

* the power law of paper 002, ``y = c0 + sign A I^a`` ((4.2) ``mu1 = mu1_0 + A1 I^a1``, (4.7)
  ``phi = phi_0 - A4 I^a4``; (4.4) and (4.6) in ``I^2``);
* Jop, Forterre & Pouliquen's (Nature 2006) ``mu = mu_s + A I/(I + I_0)`` (``A = mu_2 - mu_s``),
  linear at small I;
* each with one more constant for the fast points' curvature (the calibration's forms,
  granflow.continuum.calibration): ``jop_law + c I`` and (4.7) ``- B I^2``.
"""

from __future__ import annotations

from .tables import FloatArray

__all__ = ["jop_law", "jop_linear_law", "power_law", "power_quadratic_law"]


def power_law(x: FloatArray, c0: float, A: float, a: float, sign: float = 1.0) -> FloatArray:
    """``c0 + sign * A * x**a`` (``sign`` +1 or -1; ``x`` a float array, ``I`` or, for (4.4)
    and (4.6), ``I^2``)."""
    return c0 + sign * A * x**a


def jop_law(I: FloatArray, mu_s: float, A: float, I_0: float) -> FloatArray:  # noqa: E741
    """``mu_s + A * I / (I + I_0)``: Jop et al.'s mu(I) with ``A = mu_2 - mu_s`` (``I`` a float
    array)."""
    return mu_s + A * I / (I + I_0)


def jop_linear_law(I: FloatArray, mu_s: float, A: float, I_0: float,  # noqa: E741
                   c: float) -> FloatArray:
    """``mu_s + A * I / (I + I_0) + c * I``: Jop et al.'s mu(I) with a linear term."""
    return jop_law(I, mu_s, A, I_0) + c * I


def power_quadratic_law(I: FloatArray, c0: float, A: float, a: float,  # noqa: E741
                        B: float) -> FloatArray:
    """``c0 - A * I**a - B * I**2``: 002's (4.7) with a quadratic term."""
    return power_law(I, c0, A, a, -1.0) - B * I**2
