"""Scenes: the papers' set-ups with their defaults, built from a few parameters.

- :class:`Channel` (:mod:`granflow.scenes.channel`) — vertical channel of 000 (Debnath,
  Kesava Rao & Kumaran).
- :class:`ShearCell` (:mod:`granflow.scenes.cell`) — stress-controlled triclinic cell of 002
  (Srivastava et al.).
- :class:`PeriodicGas` (:mod:`granflow.scenes.gas`) — a periodic box of spheres (kernel checks,
  benchmarks, quick tests).

Every scene keeps the :class:`Scene` protocol, so the runner, the CLI and the studies treat them
alike; :data:`SCENES` maps the TOML ``scene = ...`` names to the classes.
"""

from granflow.errors import ParameterError

from ._base import SCENES, Scene, check_keys, register, run_with_checkpoints
from .cell import ShearCell
from .channel import Channel
from .gas import PeriodicGas


def get_scene(name: str) -> type[Scene]:
    """The scene class registered under ``name`` ('channel', 'cell', 'gas')."""
    if name not in SCENES:
        raise ParameterError(f"invalid scene = {name!r}: allowed one of {sorted(SCENES)}")
    cls: type[Scene] = SCENES[name]
    return cls


__all__ = [
    "SCENES",
    "Channel",
    "PeriodicGas",
    "Scene",
    "ShearCell",
    "check_keys",
    "get_scene",
    "register",
    "run_with_checkpoints",
]
