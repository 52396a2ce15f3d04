"""The channel problem (width, normal stress, boundary data) and a half-channel solution."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.integrate import trapezoid

from ._checks import FloatArray, bad, finite

#: Quantities a :class:`Profile` carries on its grid (besides ``x``).
PROFILE_FIELDS: tuple[str, ...] = ("u", "dudx", "phi", "sigma_xy", "mu", "I", "fluidity")


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
            finite(name, getattr(self, name))
        for name in ("W", "sigma_xx", "rho_p", "g", "d"):
            if getattr(self, name) <= 0:
                raise bad(name, getattr(self, name), "> 0")
        if not 0 <= self.x0 < self.W / 2:
            raise bad("x0", self.x0, f"0 <= x0 < W/2 = {self.W / 2!r}")
        if self.g_wall is not None:
            finite("g_wall", self.g_wall)
            if self.g_wall <= 0:
                raise bad("g_wall", self.g_wall, "> 0 (or None for the local model)")

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
            raise bad("xs", (float(np.min(q)), float(np.max(q))), f"within [{lo}, {hi}]")
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
