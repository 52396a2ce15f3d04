"""Particle size distributions (diameters in units of the mean diameter d or a)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from granflow import _core
from granflow.errors import ParameterError

KINDS = ("mono", "discrete", "uniform")


@dataclass(frozen=True)
class SizeDist:
    """A size distribution: ``kind`` is 'mono' (``params = (d,)``), 'discrete' (``params =
    (d1, f1, d2, f2, ...)``, number fractions) or 'uniform' (``params = (lo, hi)``)."""

    kind: str
    params: tuple[float, ...]

    def __post_init__(self) -> None:
        p = self.params
        if self.kind == "mono":
            ok = len(p) == 1 and p[0] > 0
            allowed = "one diameter > 0"
        elif self.kind == "uniform":
            ok = len(p) == 2 and 0 < p[0] <= p[1]
            allowed = "(lo, hi) with 0 < lo <= hi"
        elif self.kind == "discrete":
            ds, fs = p[0::2], p[1::2]
            ok = (len(p) >= 2 and len(p) % 2 == 0 and all(d > 0 for d in ds)
                  and all(f >= 0 for f in fs) and abs(sum(fs) - 1) <= 1e-6)
            allowed = "diameters > 0 with number fractions >= 0 summing to 1"
        else:
            raise ParameterError(f"invalid sizes kind = {self.kind!r}: allowed one of {KINDS}")
        if not (ok and all(np.isfinite(p))):
            raise ParameterError(f"invalid sizes = {self.to_spec()!r}: allowed {allowed}")

    def diameters_for_volume(self, volume: float, seed: int = 0) -> np.ndarray:
        """Diameters whose spheres total (to the nearest whole particle) the solid ``volume``.

        Discrete mixes are filled by exact number fractions (largest remainder)."""
        return np.asarray(
            _core.diameters_for_volume(self.kind, list(self.params), float(volume), int(seed))
        )

    @property
    def max(self) -> float:
        """The largest diameter."""
        if self.kind == "discrete":
            return max(self.params[0::2])
        return max(self.params)

    @property
    def min(self) -> float:
        """The smallest diameter present (a discrete size with fraction 0 is absent)."""
        if self.kind == "discrete":
            return min(d for d, f in zip(self.params[0::2], self.params[1::2], strict=True)
                       if f > 0)
        return min(self.params)

    @property
    def mean_volume(self) -> float:
        """The mean particle volume <pi d^3 / 6> of the distribution."""
        if self.kind == "uniform":
            lo, hi = self.params
            return float(np.pi / 6 * (lo + hi) / 2 * (lo**2 + hi**2) / 2)  # <d^3> = that / (pi/6)
        if self.kind == "discrete":
            mix = zip(self.params[0::2], self.params[1::2], strict=True)
            return float(np.pi / 6 * sum(f * k**3 for k, f in mix))
        return float(np.pi / 6 * self.params[0] ** 3)

    def to_spec(self) -> Any:
        """The TOML/JSON form that :func:`as_size_dist` reads back: a diameter (mono), a
        ``{"d": fraction}`` table (discrete) or ``[lo, hi]`` (uniform)."""
        if self.kind == "mono":
            return self.params[0]
        if self.kind == "uniform":
            return list(self.params)
        return {str(d): f for d, f in zip(self.params[0::2], self.params[1::2], strict=True)}


def solid_volume(diameters: Any) -> float:
    """The total volume of spheres of these ``diameters``, sum pi d^3 / 6."""
    d = np.asarray(diameters, dtype=float)
    return float(np.sum(np.pi * d**3 / 6))


def mono(d: float = 1.0) -> SizeDist:
    """All particles of diameter ``d``."""
    return SizeDist("mono", (float(d),))


def discrete(mix: Mapping[float, float]) -> SizeDist:
    """A discrete mix by number fraction, e.g. ``discrete({0.9: 0.3, 1.0: 0.4, 1.1: 0.3})``."""
    flat: list[float] = []
    for d, f in mix.items():
        flat += [float(d), float(f)]
    return SizeDist("discrete", tuple(flat))


def uniform(lo: float, hi: float) -> SizeDist:
    """Diameters uniform in [lo, hi] (002: [0.9, 1.1] a)."""
    return SizeDist("uniform", (float(lo), float(hi)))


def as_size_dist(value: Any, name: str = "sizes") -> SizeDist:
    """A :class:`SizeDist` from what a scene's ``sizes`` parameter or a TOML spec holds: a
    SizeDist, a ``{diameter: number fraction}`` mapping (discrete), ``[lo, hi]`` (uniform) or
    one diameter (mono)."""
    try:
        if isinstance(value, SizeDist):
            return value
        if isinstance(value, Mapping):
            return discrete({float(k): float(v) for k, v in value.items()})
        if isinstance(value, Sequence) and not isinstance(value, str) and len(value) == 2:
            return uniform(float(value[0]), float(value[1]))
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return mono(float(value))
    except (TypeError, ValueError):
        pass
    raise ParameterError(
        f"invalid {name} = {value!r}: allowed a SizeDist, a mapping diameter -> number fraction "
        "(discrete), [lo, hi] (uniform) or one diameter")


#: 000's polydisperse mix: 30 % 0.9 d, 40 % 1.0 d, 30 % 1.1 d.
CHANNEL_MIX = discrete({0.9: 0.3, 1.0: 0.4, 1.1: 0.3})
