"""Uncertainty propagation: quantiles of the predicted profiles across sampled laws."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from granflow.errors import GranflowError

from ._checks import bad
from .laws import LocalLaw
from .problem import ChannelProblem, Profile


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
        raise bad("quantiles", quantiles, "a non-empty sequence of numbers in [0, 1]")
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
