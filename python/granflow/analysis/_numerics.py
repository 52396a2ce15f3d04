"""Numerical conventions shared by the analysis modules."""

from __future__ import annotations

import functools
import warnings
from collections.abc import Callable
from typing import ParamSpec, TypeVar

import numpy as np

_P = ParamSpec("_P")
_R = TypeVar("_R")


def quiet(fn: Callable[_P, _R]) -> Callable[_P, _R]:
    """Run ``fn`` under ``np.errstate(all="ignore")`` with numpy's RuntimeWarnings (empty
    slices, invalid values) silenced: analysis code lets NaN/inf propagate and must not trip a
    global ``np.seterr(all="raise")`` (e.g. on harmless underflow)."""

    @functools.wraps(fn)
    def wrapper(*args: _P.args, **kwargs: _P.kwargs) -> _R:
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            return fn(*args, **kwargs)

    return wrapper

