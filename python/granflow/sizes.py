"""Particle size distributions (diameters in units of the mean diameter d or a)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from granflow import _core


@dataclass(frozen=True)
class SizeDist:
    """A size distribution: ``kind`` is 'mono', 'discrete' or 'uniform'."""

    kind: str
    params: tuple[float, ...]

    def diameters_for_volume(self, volume: float, seed: int = 0) -> np.ndarray:
        """Diameters whose spheres total (to the nearest whole particle) the solid ``volume``.

        Discrete mixes are filled by exact number fractions (largest remainder)."""
        return np.asarray(
            _core.diameters_for_volume(self.kind, list(self.params), float(volume), int(seed))
        )

    @property
    def max(self) -> float:
        if self.kind == "discrete":
            return max(self.params[0::2])
        return max(self.params)


def mono(d: float = 1.0) -> SizeDist:
    return SizeDist("mono", (float(d),))


def discrete(mix: dict[float, float]) -> SizeDist:
    """A discrete mix by number fraction, e.g. ``discrete({0.9: 0.3, 1.0: 0.4, 1.1: 0.3})``."""
    flat: list[float] = []
    for d, f in mix.items():
        flat += [float(d), float(f)]
    return SizeDist("discrete", tuple(flat))


def uniform(lo: float, hi: float) -> SizeDist:
    """Diameters uniform in [lo, hi] (002: [0.9, 1.1] a)."""
    return SizeDist("uniform", (float(lo), float(hi)))


#: 000's polydisperse mix: 30 % 0.9 d, 40 % 1.0 d, 30 % 1.1 d.
CHANNEL_MIX = discrete({0.9: 0.3, 1.0: 0.4, 1.1: 0.3})
