"""Argument checks and array types shared by the continuum modules."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from granflow.errors import ParameterError

FloatArray = npt.NDArray[np.float64]


def bad(name: str, value: object, allowed: str) -> ParameterError:
    """The ParameterError for ``name = value``, naming what is allowed."""
    return ParameterError(f"invalid {name} = {value!r}: allowed {allowed}")


def finite(name: str, value: float) -> None:
    """ParameterError unless ``value`` is a finite number."""
    if not (isinstance(value, (int, float, np.floating, np.integer)) and math.isfinite(value)):
        raise bad(name, value, "a finite number")
